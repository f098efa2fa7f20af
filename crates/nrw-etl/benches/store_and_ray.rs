//! `cargo bench -p nrw-etl --bench store_and_ray`
//!
//! What object storage and Ray cost: the same stages with the dataset on local disk and on
//! S3 (moto_server on loopback, started here; `pip install 'moto[server]'`), and the same 8
//! ingest units run by hand (2 at a time) and through the Ray driver's task API on a local
//! 2-CPU Ray (`pip install -r pipelines/ray/requirements.txt`). Writes
//! docs/bench/store_and_ray.md.

#[path = "../../../tests/support/cpu.rs"]
mod cpu;

use std::fmt::Write as _;
use std::io::{Read, Write as _};
use std::net::{TcpListener, TcpStream};
use std::path::Path;
use std::process::{Child, Command};
use std::time::Instant;

const EXE: &str = env!("CARGO_BIN_EXE_nrw-etl");

/// A stage's command line for a dataset location.
type Stage<'a> = (&'a str, Box<dyn Fn(&str) -> Vec<String> + 'a>);

struct Moto(Child, u16);

impl Drop for Moto {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

fn moto() -> Option<Moto> {
    let port = TcpListener::bind("127.0.0.1:0")
        .ok()?
        .local_addr()
        .ok()?
        .port();
    let child = Command::new("moto_server")
        .args(["-H", "127.0.0.1", "-p", &port.to_string()])
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
        .ok()?;
    let m = Moto(child, port);
    let t0 = Instant::now();
    while TcpStream::connect(("127.0.0.1", port)).is_err() {
        if t0.elapsed().as_secs() > 60 {
            return None;
        }
        std::thread::sleep(std::time::Duration::from_millis(100));
    }
    let mut s = TcpStream::connect(("127.0.0.1", port)).ok()?;
    write!(s, "PUT /bench HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nContent-Length: 0\r\nConnection: close\r\n\r\n").ok()?;
    let mut reply = String::new();
    s.read_to_string(&mut reply).ok()?;
    Some(m)
}

/// Seconds of one `nrw-etl` run (with the S3 endpoint's variables when given).
fn run(args: &[&str], s3: Option<u16>) -> f64 {
    let mut c = Command::new(EXE);
    c.args(args);
    if let Some(port) = s3 {
        c.env("AWS_ACCESS_KEY_ID", "bench")
            .env("AWS_SECRET_ACCESS_KEY", "bench")
            .env("AWS_DEFAULT_REGION", "us-east-1")
            .env("AWS_ENDPOINT_URL", format!("http://127.0.0.1:{port}"))
            .env("AWS_ALLOW_HTTP", "true");
    }
    let t = Instant::now();
    let o = c.output().expect("nrw-etl runs");
    assert!(
        o.status.success(),
        "{args:?}: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    t.elapsed().as_secs_f64()
}

fn main() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let work = root.join("target/bench-store-ray");
    let _ = std::fs::remove_dir_all(&work);
    let scene = work.join("scene");
    let (photos, points) = (64usize, 1_000_000usize);
    let spec = nrw_synth::SceneSpec::demo().shrunk(photos, (600, 900), points);
    nrw_synth::generate(&spec, &scene, &|| {}).expect("synthetic scene");
    let s = scene.to_str().unwrap();
    let ingest = ["--quiet", "--rows-per-shard", "8"];
    let mut md = String::new();
    let _ = writeln!(md, "# Object storage and Ray: what they cost\n\nRegenerate: `cargo bench -p nrw-etl --bench store_and_ray` (needs `pip install 'moto[server]'` and `pip install -r pipelines/ray/requirements.txt`).\n\nMachine: {}.\n\nScene: synthetic, {photos} photos of 600–900 px, {points} points, paper render settings, 8 photos per shard (8 shards). Each figure is the whole `nrw-etl` process, best of 2 runs, each into an empty dataset.\n", cpu::describe());

    match moto() {
        None => {
            let _ = writeln!(
                md,
                "## Local disk vs S3\n\nNot measured: moto_server is not installed.\n"
            );
        }
        Some(m) => {
            let port = Some(m.1);
            let _ = writeln!(md, "## Local disk vs S3 (moto on loopback)\n\nmoto is a Python server: its own per-request cost is included, so these ratios bound the store's overhead from above; a real S3 adds network latency and gives more bandwidth.\n\n| stage | local s | S3 s | S3 / local |\n|---|---|---|---|");
            let stages: Vec<Stage> = vec![
                (
                    "one ingest unit (`--unit 0/2`)",
                    Box::new(|d: &str| {
                        [
                            vec![
                                "ingest".into(),
                                s.into(),
                                "--out".into(),
                                d.into(),
                                "--unit".into(),
                                "0/2".into(),
                            ],
                            ingest.iter().map(|x| x.to_string()).collect(),
                        ]
                        .concat()
                    }),
                ),
                (
                    "whole ingest",
                    Box::new(|d: &str| {
                        [
                            vec!["ingest".into(), s.into(), "--out".into(), d.into()],
                            ingest.iter().map(|x| x.to_string()).collect(),
                        ]
                        .concat()
                    }),
                ),
                (
                    "style (color-stats: reads every photo)",
                    Box::new(|d: &str| {
                        [
                            "style",
                            d,
                            "--tier",
                            "color-stats",
                            "--quiet",
                            "--overwrite",
                        ]
                        .map(String::from)
                        .to_vec()
                    }),
                ),
                (
                    "split + triplets (k = 20)",
                    Box::new(|d: &str| ["split", d, "--val", "8"].map(String::from).to_vec()),
                ),
            ];
            let mut best = vec![(f64::MAX, f64::MAX); stages.len()];
            for round in 0..2 {
                let local = work.join(format!("local-{round}"));
                let url = format!("s3://bench/round-{round}");
                for (i, (_, args)) in stages.iter().enumerate() {
                    // The lone unit goes to a dataset of its own (the whole ingest would resume it).
                    let (l, r) = if i == 0 {
                        (format!("{}-unit", local.display()), format!("{url}-unit"))
                    } else {
                        (local.display().to_string(), url.clone())
                    };
                    let l = l.as_str();
                    let a: Vec<String> = args(l);
                    let tl = run(&a.iter().map(String::as_str).collect::<Vec<_>>(), None);
                    let a: Vec<String> = args(&r);
                    let tr = run(&a.iter().map(String::as_str).collect::<Vec<_>>(), port);
                    let (tl, tr) = if i == 3 {
                        (
                            tl + run(&["triplets", l, "--k", "20"], None),
                            tr + run(&["triplets", &url, "--k", "20"], port),
                        )
                    } else {
                        (tl, tr)
                    };
                    best[i] = (best[i].0.min(tl), best[i].1.min(tr));
                }
            }
            for ((name, _), (l, r)) in stages.iter().zip(&best) {
                let _ = writeln!(md, "| {name} | {l:.2} | {r:.2} | {:.2}× |", r / l);
            }
            let _ = writeln!(md);
        }
    }

    let have_ray = Command::new("python3")
        .args(["-c", "import ray"])
        .status()
        .is_ok_and(|s| s.success());
    if !have_ray {
        let _ = writeln!(md, "## Ray\n\nNot measured: ray is not installed.");
    } else {
        let n = 8;
        let mut hand = f64::MAX;
        let mut via_ray = f64::MAX;
        for round in 0..2 {
            let out = work.join(format!("hand-{round}"));
            let t = Instant::now();
            for pair in 0..n / 2 {
                let spawn = |i: usize| {
                    Command::new(EXE)
                        .args([
                            "ingest",
                            s,
                            "--out",
                            out.to_str().unwrap(),
                            "--unit",
                            &format!("{i}/{n}"),
                        ])
                        .args(ingest)
                        .spawn()
                        .unwrap()
                };
                let (mut a, mut b) = (spawn(2 * pair), spawn(2 * pair + 1));
                assert!(a.wait().unwrap().success() && b.wait().unwrap().success());
            }
            hand = hand.min(t.elapsed().as_secs_f64());
            let out = work.join(format!("ray-{round}"));
            let o = Command::new("python3")
                .arg(root.join("pipelines/ray/bench_units.py"))
                .args([s, out.to_str().unwrap(), EXE, &n.to_string(), "2"])
                .args(ingest)
                .output()
                .unwrap();
            assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
            let secs: f64 = String::from_utf8_lossy(&o.stdout)
                .trim()
                .lines()
                .last()
                .unwrap()
                .parse()
                .unwrap();
            via_ray = via_ray.min(secs);
        }
        let _ = writeln!(md, "## Ray's per-task overhead\n\n{n} ingest units of one shard each, 2 at a time: by hand (two processes, then the next two) against the Ray driver's tasks on a local Ray with 2 CPUs (submission to last result; Ray's startup, about a few seconds, excluded).\n\n| path | wall s |\n|---|---|\n| by hand | {hand:.2} |\n| Ray tasks | {via_ray:.2} |\n\nOverhead: {:.3} s per task ({:+.1}%), against units that each load the cloud and render 8 photos.", (via_ray - hand) / n as f64, (via_ray / hand - 1.0) * 100.0);
    }
    std::fs::write(root.join("docs/bench/store_and_ray.md"), &md).unwrap();
    print!("{md}");
}
