//! `cargo bench -p nrw-etl --bench official_export`
//!
//! The measurements behind the paper's official export (docs/bench/official_export.md):
//! 1. Depth levels: how many of the 255 levels the published loaders can read land on the
//!    landmark of a view, and the depth error they leave, for each `--depth` mapping — on the
//!    demo scene (landmark = building, window and column labels) and on ../shared/data's
//!    sceaux_castle (every covered pixel; no labels there).
//! 2. TFRecord throughput: `export --layout tfrecord` against the published Python path
//!    (benches/tfrecord_python.py: cv2 reads of the same official PNGs, Example encoding,
//!    TFRecord framing), same views, same machine, best of 5 alternating rounds.
//!
//! Needs `pip install numpy opencv-python-headless crc32c` for the Python peer.

#[path = "../../../tests/support/cpu.rs"]
mod cpu;

use std::fmt::Write as _;
use std::path::Path;
use std::process::Command;
use std::time::Instant;

use nrw_dataset::reader::Dataset;
use nrw_export::official::{DepthMapping, DepthScale};

fn run(args: &[&str], threads: Option<usize>) -> f64 {
    let mut c = Command::new(env!("CARGO_BIN_EXE_nrw-etl"));
    c.args(args);
    if let Some(t) = threads {
        c.env("RAYON_NUM_THREADS", t.to_string());
    }
    let t = Instant::now();
    let o = c.output().unwrap();
    assert!(
        o.status.success(),
        "{args:?}: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    t.elapsed().as_secs_f64()
}

/// Per view: distinct levels and median relative depth error on `landmark` pixels.
fn levels(
    ds: &Dataset,
    scale: &DepthScale,
    landmark: &dyn Fn(&nrw_dataset::ViewRow) -> Vec<bool>,
) -> (Vec<usize>, Vec<f64>) {
    let (mut counts, mut errs) = (Vec::new(), Vec::new());
    for (split, _) in ds.splits() {
        for v in ds.iter_split(&split).unwrap() {
            let v = v.unwrap();
            let depth = v.depth().unwrap();
            let mask = landmark(&v);
            let mut seen = [false; 256];
            let mut rel = Vec::new();
            for (d, m) in depth.data.iter().zip(&mask) {
                if *m && *d > 0.0 {
                    let l = scale.level(*d);
                    seen[l as usize] = true;
                    rel.push((scale.depth(l).unwrap() - *d as f64).abs() / *d as f64);
                }
            }
            if rel.is_empty() {
                continue;
            }
            rel.sort_by(f64::total_cmp);
            counts.push(seen.iter().filter(|s| **s).count());
            errs.push(rel[rel.len() / 2]);
        }
    }
    (counts, errs)
}

fn median<T: Copy + PartialOrd>(mut v: Vec<T>) -> T {
    v.sort_by(|a, b| a.partial_cmp(b).unwrap());
    v[v.len() / 2]
}

fn depth_table(
    md: &mut String,
    title: &str,
    ds: &Dataset,
    landmark: &dyn Fn(&nrw_dataset::ViewRow) -> Vec<bool>,
) -> String {
    let (near, far) = nrw_dataset::scene::read_depth_range(&ds.store)
        .unwrap()
        .unwrap();
    let _ = writeln!(md, "\n### {title}\n\nDataset depth range {near:.3} … {far:.3} (far / near = {:.1}), {} views.\n", far / near, ds.len());
    let _ = writeln!(md, "| mapping | distinct levels on the landmark, median (min–max over views) | median relative depth error |\n|---|---|---|");
    let mut best = (0, String::new());
    for mapping in [DepthMapping::Linear, DepthMapping::Inverse] {
        let scale = DepthScale { mapping, near, far };
        let (c, e) = levels(ds, &scale, landmark);
        let (lo, hi) = (*c.iter().min().unwrap(), *c.iter().max().unwrap());
        let m = median(c.clone());
        let _ = writeln!(
            md,
            "| {mapping:?} | {m} ({lo}–{hi}) | {:.2}% |",
            100.0 * median(e)
        );
        if m > best.0 {
            best = (
                m,
                format!("{title}: {mapping:?} puts more levels on the landmark (median {m})"),
            );
        }
    }
    best.1
}

fn main() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let tmp = tempfile::tempdir().unwrap();
    let t = tmp.path();
    let mut md = String::from("# The official export: depth levels and TFRecord throughput\n\n");
    let _ = writeln!(md, "Regenerate: `cargo bench -p nrw-etl --bench official_export` (the Python peer needs `pip install numpy opencv-python-headless crc32c`).\n\nMachine: {}.\n\n## Depth levels\n\nThe published loaders read `NNNN_depth.png` as `level * 2/255 - 1`, so depth gets 255 levels (0 = empty). Both mappings span the dataset's nearest to farthest rendered depth, the same for every view (a per-view range would give one level different depths in different views).", cpu::describe());
    run(&["demo", "--out", t.to_str().unwrap()], None);
    let demo = t.join("dataset");
    let ds = Dataset::open(&demo).unwrap();
    let mut winners = vec![depth_table(
        &mut md,
        "Demo scene (synthetic; landmark = building, windowpane, column labels)",
        &ds,
        &|v| {
            v.labels()
                .unwrap()
                .unwrap()
                .as_raw()
                .iter()
                .map(|l| matches!(l, 2 | 9 | 43))
                .collect()
        },
    )];
    let sceaux = root.join("../shared/data/sceaux_castle");
    if sceaux.is_dir() {
        let out = t.join("sceaux");
        run(
            &[
                "ingest",
                sceaux.to_str().unwrap(),
                "--out",
                out.to_str().unwrap(),
                "--quiet",
            ],
            None,
        );
        let ds = Dataset::open(&out).unwrap();
        winners.push(depth_table(
            &mut md,
            "sceaux_castle (real; every covered pixel, 600 px renders)",
            &ds,
            &|v| v.depth().unwrap().data.iter().map(|d| *d > 0.0).collect(),
        ));
    }
    let _ = writeln!(
        md,
        "\nThe export's default is `--depth linear`, chosen from these tables: {}.",
        winners.join("; ")
    );
    // Throughput.
    let d = demo.to_str().unwrap();
    let off = t.join("official");
    run(
        &["export", d, "--out", off.to_str().unwrap(), "--quiet"],
        None,
    );
    let n = ds.len();
    // Each timed run starts from flushed page cache writes and an empty output (so earlier
    // runs' dirty pages do not throttle it), and the three paths alternate round by round.
    let settle = |dir: &Path| {
        let _ = std::fs::remove_dir_all(dir);
        let _ = Command::new("sync").status();
    };
    let tfr = t.join("tfr");
    let ours = |threads: Option<usize>| {
        settle(&tfr);
        run(
            &[
                "export",
                d,
                "--layout",
                "tfrecord",
                "--out",
                tfr.to_str().unwrap(),
                "--quiet",
            ],
            threads,
        )
    };
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("benches/tfrecord_python.py");
    let python = || -> Option<f64> {
        let dir = t.join("py");
        settle(&dir);
        let o = Command::new("python3")
            .arg(&script)
            .arg(&off)
            .arg(&dir)
            .arg("demo")
            .output()
            .ok()?;
        if !o.status.success() {
            eprintln!("python peer failed: {}", String::from_utf8_lossy(&o.stderr));
            return None;
        }
        let v: serde_json::Value = serde_json::from_slice(&o.stdout).ok()?;
        assert_eq!(v["views"].as_u64(), Some(n as u64));
        v["seconds"].as_f64()
    };
    let (mut both, mut one, mut py) = (f64::INFINITY, f64::INFINITY, f64::INFINITY);
    for _ in 0..5 {
        both = both.min(ours(None));
        one = one.min(ours(Some(1)));
        py = py.min(python().unwrap_or(f64::INFINITY));
    }
    let (w, h) = {
        let v = ds.iter_split("train").unwrap().next().unwrap().unwrap();
        (v.width, v.height)
    };
    let _ = writeln!(md, "\n## TFRecord throughput\n\n{n} demo views of about {w}×{h}, best of 5 alternating rounds, each after `sync` into an empty folder. Ours: the whole `nrw-etl export --layout tfrecord` process (opening the dataset, decoding the stored PNGs, mapping depth and colours, encoding, CRC-32C, writing). Published path: `AlignedRenderedDataset` + `_to_example` + `TFRecordWriter`, transcribed (cv2 reads of the same views' official PNGs, hand-encoded Example, crc32c package), one process as published; TensorFlow itself is not installed here.\n\n| path | seconds | views / s | ours vs published |\n|---|---|---|---|");
    let _ = writeln!(
        md,
        "| published (Python, 1 thread) | {py:.2} | {:.1} | 1.0× |",
        n as f64 / py
    );
    let _ = writeln!(
        md,
        "| nrw-etl, 1 thread | {one:.2} | {:.1} | {:.1}× |",
        n as f64 / one,
        py / one
    );
    let _ = writeln!(
        md,
        "| nrw-etl, all cores | {both:.2} | {:.1} | {:.1}× |",
        n as f64 / both,
        py / both
    );
    std::fs::create_dir_all(root.join("docs/bench")).unwrap();
    std::fs::write(root.join("docs/bench/official_export.md"), &md).unwrap();
    eprintln!("{md}\nwrote docs/bench/official_export.md");
}
