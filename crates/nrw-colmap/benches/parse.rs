//! `cargo bench -p nrw-colmap --bench parse [-- SCENE_DIR RUNS]`
//!
//! Parses the real model N times with our reader and, in the same run, with pycolmap, and
//! reports the ratio (pycolmap time / ours: >1 means we are faster). Also measures PLY
//! throughput and what projection costs per model against a hand-inlined pinhole loop.
//! Writes docs/bench/colmap_parse.md. Timings are medians of N runs; ratios, not absolute
//! times, are what to compare across machines.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

use glam::DVec3;
use nrw_colmap::{read_model, read_ply, Camera, CameraModel, Format};

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(|a, b| a.partial_cmp(b).unwrap());
    v[v.len() / 2]
}

fn time<F: FnMut()>(runs: usize, mut f: F) -> f64 {
    f(); // warm the page cache and allocator
    median(
        (0..runs)
            .map(|_| {
                let t = Instant::now();
                f();
                t.elapsed().as_secs_f64()
            })
            .collect(),
    )
}

/// pycolmap's median parse time in seconds, or why it could not be measured.
fn pycolmap(dir: &Path, fmt: Format, runs: usize) -> Result<f64, String> {
    let method = if fmt == Format::Binary {
        "read_binary"
    } else {
        "read_text"
    };
    let script = format!(
        "import pycolmap, time, statistics, sys\n\
         p = sys.argv[1]\n\
         r = pycolmap.Reconstruction(); r.{method}(p)\n\
         ts = []\n\
         for _ in range({runs}):\n\
         \u{20}   t = time.perf_counter(); r = pycolmap.Reconstruction(); r.{method}(p); ts.append(time.perf_counter() - t)\n\
         print(statistics.median(ts))\n"
    );
    let out = Command::new("python3")
        .arg("-c")
        .arg(script)
        .arg(dir)
        .output()
        .map_err(|e| e.to_string())?;
    if !out.status.success() {
        return Err(String::from_utf8_lossy(&out.stderr)
            .lines()
            .last()
            .unwrap_or("")
            .to_string());
    }
    String::from_utf8_lossy(&out.stdout)
        .trim()
        .parse()
        .map_err(|e| format!("{e}"))
}

fn main() {
    let args: Vec<String> = std::env::args().filter(|a| a != "--bench").collect();
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let scene: PathBuf = args
        .get(1)
        .map(PathBuf::from)
        .unwrap_or_else(|| root.join("../shared/data/sceaux_castle"));
    let runs: usize = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(20);
    let dir = nrw_colmap::find_model_dir(&scene).expect("model folder");
    let mut md = String::from("# COLMAP parsing and projection benchmark\n\n");
    md.push_str(&format!(
        "Regenerate: `cargo bench -p nrw-colmap --bench parse` (scene `{}`, median of {runs} runs).\n\n",
        dir.strip_prefix(&root).unwrap_or(&dir).display()
    ));
    md.push_str(
        "| encoding | nrw-colmap | pycolmap | pycolmap / nrw-colmap |\n|---|---|---|---|\n",
    );
    for fmt in [Format::Binary, Format::Text] {
        let ours = time(runs, || {
            std::hint::black_box(read_model(&dir, Some(fmt)).unwrap());
        });
        let row = match pycolmap(&dir, fmt, runs) {
            Ok(py) => format!(
                "| {} | {:.2} ms | {:.2} ms | **{:.2}×** |\n",
                fmt.ext(),
                ours * 1e3,
                py * 1e3,
                py / ours
            ),
            Err(e) => format!(
                "| {} | {:.2} ms | not measured ({e}) | — |\n",
                fmt.ext(),
                ours * 1e3
            ),
        };
        print!("{row}");
        md.push_str(&row);
    }

    let ply = scene.join("dense/fused.ply");
    if ply.is_file() {
        let bytes = std::fs::metadata(&ply).unwrap().len() as f64;
        let t = time(runs.min(10), || {
            std::hint::black_box(read_ply(&ply).unwrap());
        });
        let row = format!(
            "\nPLY `{}`: {:.1} ms for {:.1} MB = **{:.0} MB/s** (serde-ply rows streamed into columns).\n",
            ply.file_name().unwrap().to_string_lossy(), t * 1e3, bytes / 1e6, bytes / 1e6 / t
        );
        print!("{row}");
        md.push_str(&row);
    }

    // Projection cost per point and model, against a hand-written pinhole loop.
    let n = 1_000_000;
    let pts: Vec<DVec3> = (0..n)
        .map(|i| {
            let a = i as f64 * 1e-6;
            DVec3::new((a * 7.0).sin() * 0.5, (a * 3.0).cos() * 0.4, 2.0 + a)
        })
        .collect();
    let naive = time(runs.min(10), || {
        let (f, cx, cy) = (1000.0, 640.0, 480.0);
        let mut out = Vec::with_capacity(n);
        out.extend(pts.iter().map(|p| {
            if p.z >= f64::EPSILON {
                Some(glam::DVec2::new(f * p.x / p.z + cx, f * p.y / p.z + cy))
            } else {
                None
            }
        }));
        std::hint::black_box(out);
    });
    md.push_str("\nProjection of 10⁶ points (`Camera::project_many`), relative to a hand-inlined pinhole loop measured in the same run:\n\n| model | ns / point | × hand-written pinhole |\n|---|---|---|\n");
    md.push_str(&format!(
        "| hand-written pinhole | {:.2} | 1.00 |\n",
        naive / n as f64 * 1e9
    ));
    for model in CameraModel::ALL {
        let mut params = vec![0.0; model.num_params()];
        let k = if model.single_focal() { 1 } else { 2 };
        params[..k].fill(1000.0);
        params[k] = 640.0;
        params[k + 1] = 480.0;
        for p in params.iter_mut().skip(k + 2) {
            *p = 0.01;
        }
        let cam = Camera {
            id: 1,
            model,
            width: 1280,
            height: 960,
            params,
        };
        let mut out = Vec::new();
        let t = time(runs.min(10), || {
            cam.project_many(&pts, &mut out);
            std::hint::black_box(&out);
        });
        let row = format!(
            "| {} | {:.2} | {:.2} |\n",
            model.name(),
            t / n as f64 * 1e9,
            t / naive
        );
        md.push_str(&row);
    }
    print!("{md}");
    let out = root.join("docs/bench/colmap_parse.md");
    std::fs::create_dir_all(out.parent().unwrap()).unwrap();
    std::fs::write(&out, md).unwrap();
    eprintln!("wrote {}", out.display());
}
