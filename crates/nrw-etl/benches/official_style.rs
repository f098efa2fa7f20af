//! `cargo bench -p nrw-etl --bench official_style [-- PHOTOS]`
//!
//! `style --tier official` against the published code (docs/bench/official_style.md): the same
//! photos (a synthetic scene's default official export, PHOTOS photos, all in train), the
//! same `vgg16.npy` (tests/oracles/make_vgg16_npy.py from ../shared/weights), 2 threads on both sides.
//! Ours: `nrw-etl style --tier official` (descriptors of every kept photo) plus `export`, which
//! computes `dist_NAME.pckl` (and writes the PNG folders, so ours is overstated). Theirs:
//! `style_loss.compute_pairwise_style_loss_v2` on the exported references under TensorFlow's
//! CPU build (tests/oracles/paper_oracle.py --only-dist), its graph built once as the published code
//! builds it. Every process timed whole (wall seconds, peak resident memory); the distances of
//! both compared entry by entry and row by row (neighbour order).
//!
//! Needs `pip install tensorflow-cpu opencv-python-headless matplotlib six pillow pyarrow`.

#[path = "../../../tests/support/cpu.rs"]
mod cpu;
#[path = "../../../tests/support/timed.rs"]
mod timed;

use std::fmt::Write as _;
use std::path::Path;
use std::process::Command;
use std::time::Instant;

const EXE: &str = env!("CARGO_BIN_EXE_nrw-etl");

fn ok(args: &[&str]) {
    let o = Command::new(EXE).args(args).output().unwrap();
    assert!(
        o.status.success(),
        "{args:?}: {}",
        String::from_utf8_lossy(&o.stderr)
    );
}

fn main() {
    let photos: usize = std::env::args()
        .skip(1)
        .find_map(|a| a.parse().ok())
        .unwrap_or(32);
    std::env::set_var("RAYON_NUM_THREADS", "2");
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let shared = root.join("../shared");
    let tmp = tempfile::tempdir().unwrap();
    let t = tmp.path();
    let npy = t.join("vgg16.npy");
    let o = Command::new("python3")
        .arg(root.join("tests/oracles/make_vgg16_npy.py"))
        .arg(shared.join("weights/vgg16_imagenet.safetensors"))
        .arg(&npy)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let scene = t.join("scene");
    let mut spec = nrw_synth::SceneSpec::demo().shrunk(photos, (600, 900), 200_000);
    spec.observations.features = 300;
    nrw_synth::generate(&spec, &scene, &|| {}).unwrap();
    let ds = t.join("ds");
    let d = ds.to_str().unwrap();
    let labels = scene.join("ground_truth/semantics");
    ok(&[
        "ingest",
        scene.to_str().unwrap(),
        "--out",
        d,
        "--semantics",
        labels.to_str().unwrap(),
        "--max-empty",
        "1.0",
        "--quiet",
    ]);
    // Every photo in train: both sides describe exactly the same photos.
    ok(&["split", d, "--val", "0"]);
    let off = t.join("official");
    let (style_s, style_mb) = timed::timed(
        EXE,
        &[
            "style",
            d,
            "--tier",
            "official",
            "--weights",
            npy.to_str().unwrap(),
            "--quiet",
        ],
    );
    let (export_s, export_mb) = timed::timed(
        EXE,
        &[
            "export",
            d,
            "--out",
            off.to_str().unwrap(),
            "--name",
            "bench",
            "--quiet",
        ],
    );
    let wall = Instant::now();
    let o = Command::new("python3")
        .arg(root.join("tests/oracles/paper_oracle.py"))
        .args(["--paper", shared.join("paper-code").to_str().unwrap()])
        .args([
            "--official",
            off.to_str().unwrap(),
            "--name",
            "bench",
            "--resolution",
            "512",
        ])
        .args(["--npy", npy.to_str().unwrap(), "--only-dist"])
        .env("TF_CPP_MIN_LOG_LEVEL", "2")
        .env("TF_NUM_INTRAOP_THREADS", "2")
        .env("TF_NUM_INTEROP_THREADS", "2")
        .output()
        .unwrap();
    let process_s = wall.elapsed().as_secs_f64();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let n = v["n"].as_u64().unwrap();
    let theirs = v["seconds"].as_f64().unwrap();
    let ours = style_s + export_s;
    let mut md = String::from("# `style --tier official` against the published code\n\n");
    let _ = writeln!(
        md,
        "Regenerate: `cargo bench -p nrw-etl --bench official_style [-- PHOTOS]` (the peer needs `pip install tensorflow-cpu opencv-python-headless matplotlib six`).\n\nMachine: {}.\n\nA synthetic scene of {photos} photos (demo façade, 600–900 px, stored at shorter side 600), all {} in the train split, so both sides describe the same photos; the same `vgg16.npy` on both sides (tests/oracles/make_vgg16_npy.py: ../shared/weights in tensorflow-vgg's layout); 2 threads on both sides (RAYON_NUM_THREADS, TF_NUM_INTRAOP_THREADS). Ours is `style --tier official` (every kept photo) plus the `export` that computes `dist_bench.pckl` and writes the PNG folders; theirs is `style_loss.compute_pairwise_style_loss_v2` on the exported train references ({}; its Python process took {process_s:.1} s in all with imports).\n",
        cpu::describe(),
        n,
        v["tensorflow"].as_str().map_or("TensorFlow".into(), |t| format!("TensorFlow {t} CPU")),
    );
    let _ = writeln!(
        md,
        "| side | seconds | peak memory (MB) | per train photo (s) |\n|---|---|---|---|"
    );
    let _ = writeln!(md, "| ours: style | {style_s:.1} | {style_mb:.0} | |");
    let _ = writeln!(
        md,
        "| ours: export (pickle + PNGs) | {export_s:.1} | {export_mb:.0} | |"
    );
    let _ = writeln!(
        md,
        "| ours: both | {ours:.1} | {:.0} | {:.3} |",
        style_mb.max(export_mb),
        ours / n as f64
    );
    let _ = writeln!(
        md,
        "| published (TF CPU) | {theirs:.1} | {:.0} | {:.3} |",
        v["peak_mb"].as_f64().unwrap(),
        theirs / n as f64
    );
    let _ = writeln!(
        md,
        "\n**{:.2}×** the published code's speed. Distances: worst relative difference {:.2e}, median {:.2e} over the {} off-diagonal entries; neighbour order {} in every row.",
        theirs / ours,
        v["worst_relative"].as_f64().unwrap(),
        v["median_relative"].as_f64().unwrap(),
        n * (n - 1),
        if v["same_order"] == true { "the same" } else { "NOT the same" }
    );
    let path = root.join("docs/bench/official_style.md");
    std::fs::write(&path, &md).unwrap();
    print!("{md}");
    eprintln!("wrote {}", path.display());
}
