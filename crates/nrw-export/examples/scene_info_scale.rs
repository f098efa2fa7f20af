//! How the megadepth layout's N × N files scale with the number of views: D2-Net's
//! `scene_info`, LoFTR's three band files, RoMa's scene info and IMC 2022's pair list, written
//! from synthetic tracks at N views up to the paper's 7,711, with seconds, peak memory and
//! bytes. It answers whether these files need work units: one process writes them, a row at a
//! time, so the question is only time and memory.
//!
//! ```text
//! cargo run --release -p nrw-export --example scene_info_scale [-- N ...] > docs/bench/scene_info_scale.md
//! ```
//!
//! The tracks: every view observes `POINTS_PER_VIEW` points; a point is seen by 2–8 views
//! chosen near one another in view order (a landmark's photos overlap with their neighbours in
//! a crawl, not with all), so each view shares points with a few dozen others. The peer,
//! D2-Net's `preprocess_scene.py`, loops in Python over N² pairs and is measured on the real
//! scenes in docs/bench/exports.md; at these N it is not run.

use std::io::Write;
use std::time::Instant;

use glam::DVec3;
use nrw_export::imc::{self, ImcView};
use nrw_export::megadepth::{SceneInfo, SceneView, LOFTR_BANDS};

/// Points each view observes (MegaDepth's scenes hold a few thousand a view).
const POINTS_PER_VIEW: usize = 2000;
/// How far apart in view order the views of one point may be.
const NEIGHBOURHOOD: usize = 40;
/// The stored views' size.
const SIZE: (u64, u64) = (800, 600);

/// A small deterministic generator (xorshift64*), so every run sees the same tracks.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_f491_4f6c_dd1d)
    }

    fn below(&mut self, n: usize) -> usize {
        (self.next() % n as u64) as usize
    }

    fn unit(&mut self) -> f64 {
        (self.next() >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// N views with synthetic tracks.
fn scene(n: usize) -> Vec<SceneView> {
    let mut rng = Rng(0x9e37_79b9_7f4a_7c15 ^ n as u64);
    let mut points: Vec<Vec<(u64, [f64; 2], DVec3)>> = vec![Vec::new(); n];
    let total = n * POINTS_PER_VIEW / 5; // a mean track length of 5
    for id in 0..total as u64 {
        let length = 2 + rng.below(7);
        let first = rng.below(n);
        let x = DVec3::new(rng.unit() * 100.0, rng.unit() * 100.0, rng.unit() * 100.0);
        for _ in 0..length {
            let v = (first + rng.below(NEIGHBOURHOOD)) % n;
            if points[v].last().is_some_and(|p| p.0 == id) {
                continue;
            }
            let at = [rng.unit() * SIZE.0 as f64, rng.unit() * SIZE.1 as f64];
            points[v].push((id, at, x));
        }
    }
    points
        .into_iter()
        .enumerate()
        .map(|(i, points)| {
            let a = rng.unit() * std::f64::consts::PI;
            SceneView {
                image_path: format!("Undistorted_SfM/s/images/{i:05}.png"),
                depth_path: format!("phoenix/S6/zl548/MegaDepth_v1/s/dense0/depths/{i:05}.h5"),
                pinhole: [700.0, 700.0, 400.0, 300.0],
                qvec: [(a / 2.0).cos(), 0.0, (a / 2.0).sin(), 0.0],
                tvec: [0.0, 0.0, 150.0],
                points,
            }
        })
        .collect()
}

/// The process's peak resident memory so far, in MB (Linux's VmHWM).
fn peak_mb() -> f64 {
    let status = std::fs::read_to_string("/proc/self/status").unwrap_or_default();
    status
        .lines()
        .find_map(|l| l.strip_prefix("VmHWM:"))
        .and_then(|v| v.trim().trim_end_matches("kB").trim().parse::<f64>().ok())
        .map_or(f64::NAN, |kb| kb / 1024.0)
}

/// One row of the report: N, seconds of each file, bytes written, peak memory.
fn row(n: usize, dir: &std::path::Path, keep: Option<&std::path::Path>) -> String {
    let t = Instant::now();
    let views = scene(n);
    let observations: usize = views.iter().map(|v| v.points.len()).sum();
    let info = SceneInfo::new(views);
    let build = t.elapsed().as_secs_f64();
    let mut bytes = 0u64;
    let mut timed = |name: &str, f: &dyn Fn(&mut std::fs::File) -> std::io::Result<()>| {
        let path = dir.join(name);
        let mut file = std::fs::File::create(&path).unwrap();
        let t = Instant::now();
        f(&mut file).unwrap();
        file.flush().unwrap();
        let s = t.elapsed().as_secs_f64();
        bytes += std::fs::metadata(&path).unwrap().len();
        match keep {
            Some(to) if name == "scene_info.npz" => std::fs::rename(&path, to).unwrap(),
            _ => std::fs::remove_file(&path).unwrap(),
        }
        s
    };
    let npz = timed("scene_info.npz", &|f| info.write_npz(f).map(|_| ()));
    let loftr = timed("loftr.npz", &|f| {
        LOFTR_BANDS
            .iter()
            .try_for_each(|band| info.write_loftr(*band, f))
    });
    let roma = timed("roma.npy", &|f| info.write_roma(f));
    let ids: Vec<String> = (0..n).map(|i| format!("{i:05}")).collect();
    let imc_views: Vec<ImcView> = ids
        .iter()
        .enumerate()
        .map(|(i, id)| info.imc_view(i, id, "", SIZE.0, SIZE.1))
        .collect();
    let pairs_of = |i: usize| info.shared_pairs_of(i);
    let pairs = timed("pair_covisibility.csv", &|f| {
        imc::write_pairs(&imc_views, &pairs_of, f)
    });
    let total = build + npz + loftr + roma + pairs;
    format!(
        "| {n} | {observations} | {build:.1} | {npz:.1} | {loftr:.1} | {roma:.1} | {pairs:.1} | {total:.1} | {:.0} | {:.0} |",
        bytes as f64 / 1e6,
        peak_mb()
    )
}

fn main() {
    // `--keep-npz PATH` keeps the last row's scene_info.npz there (for numpy to read it back).
    let mut args: Vec<String> = std::env::args().skip(1).collect();
    let keep = args.iter().position(|a| a == "--keep-npz").map(|i| {
        let path = std::path::PathBuf::from(args.get(i + 1).expect("--keep-npz PATH"));
        args.drain(i..i + 2);
        path
    });
    let ns: Vec<usize> = args
        .iter()
        .map(|a| a.parse().expect("N: a number of views"))
        .collect();
    let ns = if ns.is_empty() {
        vec![1000, 2000, 4000, 7711, 13500]
    } else {
        ns
    };
    let dir = std::env::temp_dir().join(format!("nrw-scene-info-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let cpuinfo = std::fs::read_to_string("/proc/cpuinfo").unwrap_or_default();
    let present: Vec<&str> = cpuinfo.split_whitespace().collect();
    let flags: Vec<&str> = ["avx512f", "avx2", "fma"]
        .into_iter()
        .filter(|f| present.contains(f))
        .collect();
    println!("# MegaDepth layout's N × N files at scale\n");
    println!(
        "Made by `cargo run --release -p nrw-export --example scene_info_scale`: synthetic tracks, \
         {POINTS_PER_VIEW} points a view, tracks of 2–8 views within {NEIGHBOURHOOD} neighbours in \
         view order. Seconds of one process on {} cores; peak memory is the process's high-water \
         mark after the row (it grows with the largest N run so far); bytes are all four files. \
         CPU flags: {}.\n",
        std::thread::available_parallelism().map_or(0, |n| n.get()),
        flags.join(", ")
    );
    println!(
        "| views N | observations | tracks into SceneInfo s | scene_info.npz s | LoFTR's 3 band files s | \
         RoMa's .npy s | IMC pair_covisibility.csv s | total s | MB written | peak MB |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|");
    for (k, n) in ns.iter().enumerate() {
        let last = k + 1 == ns.len();
        let line = row(*n, &dir, keep.as_deref().filter(|_| last));
        eprintln!("{line}");
        println!("{line}");
    }
    std::fs::remove_dir_all(&dir).ok();
    println!(
        "\nEvery file is streamed (the N × N matrices a row at a time, the pair lists a view's \
         pairs at a time); memory is the tracks' (per-view dicts and each point's views), growing \
         with the observations. Its three matrices alone are 24 N² bytes, which passes 4 GiB near \
         N = 13,000: from there scene_info.npz carries ZIP64 records (numpy's zipfile reads them)."
    );
}
