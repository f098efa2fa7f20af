//! `cargo bench -p nrw-etl --bench pipeline_stages [-- PHOTOS POINTS]`
//!
//! Where the pipeline's time goes: every stage of the paper's pipeline run as its own
//! `nrw-etl` process on a synthetic scene (200 photos and 10⁷ points by default, the
//! paper's settings: 600 px renders, 100 validation photos, VGG16 at 512², k = 20, the
//! official export), each timed whole with its peak memory, so the dominant stage is
//! visible. Needs ../shared/weights/vgg16_imagenet.safetensors. Writes
//! docs/bench/pipeline_stages.md.

#[path = "../../../tests/support/cpu.rs"]
mod cpu;
#[path = "../../../tests/support/timed.rs"]
mod timed;

use std::fmt::Write as _;
use std::path::Path;

fn main() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let (photos, points) = timed::photos_points();
    let weights = root.join("../shared/weights/vgg16_imagenet.safetensors");
    assert!(
        weights.is_file(),
        "{} is needed for the style stage",
        weights.display()
    );
    let work = root.join("target/bench-pipeline-stages");
    let _ = std::fs::remove_dir_all(&work);
    let scene = work.join("scene");
    let spec = nrw_synth::SceneSpec::demo().shrunk(photos, (600, 900), points);
    nrw_synth::generate(&spec, &scene, &|| {}).expect("synthetic scene");
    let ds = work.join("dataset");
    let (s, d) = (scene.to_str().unwrap(), ds.to_str().unwrap());
    let labels = scene.join("ground_truth/semantics");
    let export = work.join("export");
    let val = (photos / 2).min(100).to_string();
    let stages: Vec<(&str, Vec<&str>)> = vec![
        (
            "ingest",
            vec![
                "ingest",
                s,
                "--out",
                d,
                "--semantics",
                labels.to_str().unwrap(),
                "--quiet",
            ],
        ),
        ("split", vec!["split", d, "--val", &val]),
        (
            "style",
            vec![
                "style",
                d,
                "--weights",
                weights.to_str().unwrap(),
                "--quiet",
            ],
        ),
        ("triplets", vec!["triplets", d, "--k", "20"]),
        ("qa", vec!["qa", d]),
        (
            "export",
            vec!["export", d, "--out", export.to_str().unwrap(), "--quiet"],
        ),
    ];
    let mut rows = Vec::new();
    for (name, a) in &stages {
        let (t, m) = timed::timed(env!("CARGO_BIN_EXE_nrw-etl"), a);
        eprintln!("{name}: {t:.1} s, {m:.0} MB");
        rows.push((*name, t, m));
    }
    let total: f64 = rows.iter().map(|r| r.1).sum();
    let mut md = String::from("# Where the pipeline's time goes: one row per stage\n\n");
    let _ = writeln!(
        md,
        "Regenerate: `cargo bench -p nrw-etl --bench pipeline_stages [-- PHOTOS POINTS]` (needs \
         ../shared/weights). Machine: {}.\n\nScene: synthetic (demo façade), {photos} photos of \
         600–900 px, {points} points, its ground-truth ADE20K labels. The paper's settings, each stage \
         its own `nrw-etl` process timed whole by `/usr/bin/time` (wall seconds, peak resident memory): \
         ingest (600 px renders, r = 1), split (`--val {val}`), style (VGG16, 512² centre crop, five \
         Grams), triplets (k = 20), qa, export (the official layout).\n\n\
         | stage | wall s | share | peak MB |\n|---|---|---|---|",
        cpu::describe()
    );
    for (name, t, m) in &rows {
        let _ = writeln!(
            md,
            "| {name} | {t:.1} | {:.1}% | {m:.0} |",
            100.0 * t / total
        );
    }
    let _ = writeln!(md, "| **total** | {total:.1} | 100% | |");
    let (top, t, _) = rows
        .iter()
        .fold(rows[0], |a, b| if b.1 > a.1 { *b } else { a });
    let _ = writeln!(
        md,
        "\nThe dominant stage: **{top}**, {:.0}% of the total ({:.2} s per photo).",
        100.0 * t / total,
        t / photos as f64
    );
    std::fs::create_dir_all(root.join("docs/bench")).unwrap();
    std::fs::write(root.join("docs/bench/pipeline_stages.md"), md).unwrap();
    eprintln!("wrote docs/bench/pipeline_stages.md");
}
