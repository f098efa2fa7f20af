//! End-to-end tests of the `nrw-etl` binary on the real scenes in ../shared/data.

#[path = "architecture.rs"]
mod architecture;
#[path = "bad_inputs.rs"]
mod bad_inputs;
#[path = "clean.rs"]
mod clean;
#[path = "colmap_dense.rs"]
mod colmap_dense;
#[path = "dataset.rs"]
mod dataset;
#[path = "densify.rs"]
mod densify;
#[path = "docs.rs"]
mod docs;
#[path = "duplicates.rs"]
mod duplicates;
#[path = "export_models.rs"]
mod export_models;
#[path = "golden.rs"]
mod golden;
#[path = "gsplat.rs"]
mod gsplat;
#[path = "ingest.rs"]
mod ingest;
#[path = "inspect.rs"]
mod inspect;
#[path = "jpeg.rs"]
mod jpeg;
#[path = "megadepth.rs"]
mod megadepth;
#[path = "memory.rs"]
mod memory;
#[path = "nerfstudio.rs"]
mod nerfstudio;
#[path = "nerfw.rs"]
mod nerfw;
#[path = "support/npy.rs"]
mod npy;
#[path = "official.rs"]
mod official;
#[path = "paper_code.rs"]
mod paper_code;
#[path = "pipeline.rs"]
mod pipeline;
#[path = "provenance.rs"]
mod provenance;
#[path = "support/python.rs"]
mod python;
#[path = "python_pkg.rs"]
mod python_pkg;
#[path = "qa.rs"]
mod qa;
#[path = "ray.rs"]
mod ray;
#[path = "s3.rs"]
mod s3;
#[path = "segment.rs"]
mod segment;
#[path = "support/shared.rs"]
mod shared;
#[path = "style.rs"]
mod style;
#[path = "synth.rs"]
mod synth;
#[path = "support/timed.rs"]
mod timed;
#[path = "trainer.rs"]
mod trainer;
#[path = "triplets.rs"]
mod triplets;
#[path = "undistort.rs"]
mod undistort;
#[path = "units.rs"]
mod units;
#[path = "untrusted.rs"]
mod untrusted;
#[path = "verify.rs"]
mod verify;

use python::python_has;

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn data() -> PathBuf {
    shared::shared_path("data")
}

fn nrw(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_nrw-etl"))
        .args(args)
        .output()
        .expect("binary runs")
}

/// tests/SCRIPT run by the interpreter `python` with `args`; the one JSON object it prints
/// (its standard error in the failure message).
fn script_json(python: &std::ffi::OsStr, script: &str, args: &[&Path]) -> serde_json::Value {
    let run = std::process::Command::new(python)
        .arg(
            Path::new(env!("CARGO_MANIFEST_DIR"))
                .join("../../tests/oracles")
                .join(script),
        )
        .args(args)
        .output()
        .unwrap();
    assert!(
        run.status.success(),
        "{script}: {}",
        String::from_utf8_lossy(&run.stderr)
    );
    serde_json::from_slice(&run.stdout).unwrap()
}

fn ok(args: &[&str]) -> String {
    let o = nrw(args);
    assert!(
        o.status.success(),
        "{args:?} failed: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    String::from_utf8(o.stdout).unwrap()
}

fn fails(args: &[&str]) -> String {
    let o = nrw(args);
    assert!(!o.status.success(), "{args:?} should fail");
    assert_eq!(o.status.code(), Some(1), "a clean error exit, not a crash");
    String::from_utf8(o.stderr).unwrap()
}

/// A column of a batch by name, as its concrete Arrow type.
/// The number that follows `before` in `text` (up to the next space or quote), if any.
fn number_after<T: std::str::FromStr>(text: &str, before: &str) -> Option<T> {
    text.split(before)
        .nth(1)?
        .split([' ', '"'])
        .next()?
        .parse()
        .ok()
}

fn column<'a, T: 'static>(b: &'a arrow_array::RecordBatch, name: &str) -> &'a T {
    b.column_by_name(name)
        .unwrap_or_else(|| panic!("no column {name}"))
        .as_any()
        .downcast_ref::<T>()
        .unwrap_or_else(|| panic!("column {name} has another type"))
}

/// Width and height from a JPEG's SOF marker, read without the tool's code.
fn image_size(p: &Path) -> (u32, u32) {
    let b = std::fs::read(p).unwrap();
    let mut i = 2;
    while i + 9 < b.len() {
        assert_eq!(b[i], 0xFF);
        let marker = b[i + 1];
        let len = u16::from_be_bytes([b[i + 2], b[i + 3]]) as usize;
        if (0xC0..=0xCF).contains(&marker) && ![0xC4, 0xC8, 0xCC].contains(&marker) {
            let h = u16::from_be_bytes([b[i + 5], b[i + 6]]) as u32;
            let w = u16::from_be_bytes([b[i + 7], b[i + 8]]) as u32;
            return (w, h);
        }
        i += 2 + len;
    }
    panic!("no SOF in {}", p.display());
}

fn walk(d: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    for e in std::fs::read_dir(d).unwrap() {
        let p = e.unwrap().path();
        if p.is_dir() {
            out.extend(walk(&p));
        } else {
            out.push(p);
        }
    }
    out
}

/// Every file of a dataset with its bytes, but timings.json: how long stages took differs
/// between runs by nature and is kept out of the dataset's reproducible contents.
fn files(dir: &Path) -> std::collections::BTreeMap<PathBuf, Vec<u8>> {
    walk(dir)
        .into_iter()
        .filter(|p| p.file_name().is_none_or(|n| n != "timings.json"))
        .map(|p| {
            (
                p.strip_prefix(dir).unwrap().to_path_buf(),
                std::fs::read(&p).unwrap(),
            )
        })
        .collect()
}

/// Two file maps hold the same paths with the same bytes (`what` names the comparison).
fn assert_same_files(
    a: &std::collections::BTreeMap<PathBuf, Vec<u8>>,
    b: &std::collections::BTreeMap<PathBuf, Vec<u8>>,
    what: &str,
) {
    assert_eq!(
        a.keys().collect::<Vec<_>>(),
        b.keys().collect::<Vec<_>>(),
        "{what}: other files"
    );
    for (k, v) in a {
        assert!(v == &b[k], "{what}: {} differs", k.display());
    }
}

/// `ingest` of a small synthetic scene, render size and photo-size filter lowered to fit it.
fn ingest_small(scene: &Path, out: &Path, extra: &[&str]) -> Output {
    nrw(&strs(&ingest_small_args(scene, out, extra)))
}

/// Owned arguments as the `&str`s [`nrw`] takes.
fn strs(args: &[String]) -> Vec<&str> {
    args.iter().map(String::as_str).collect()
}

/// The arguments of [`ingest_small`].
fn ingest_small_args(scene: &Path, out: &Path, extra: &[&str]) -> Vec<String> {
    let mut args = vec![
        "ingest",
        scene.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--min-dim",
        "96",
        "--min-photo-side",
        "100",
    ];
    args.extend(extra);
    args.into_iter().map(String::from).collect()
}

/// Copy a scene's photo folder (flat) into `dst`, for tests that rewrite a real scene's model.
fn copy_photos(src: &Path, dst: &Path) {
    std::fs::create_dir_all(dst).unwrap();
    for e in std::fs::read_dir(src).unwrap().flatten() {
        std::fs::copy(e.path(), dst.join(e.file_name())).unwrap();
    }
}

/// A small synthetic scene whose photos pass a lowered size filter.
fn small_scene(dir: &Path, photos: usize) {
    let mut spec = nrw_synth::SceneSpec::demo().shrunk(photos, (120, 160), 60_000);
    spec.observations.features = 300;
    nrw_synth::generate(&spec, dir, &|| {}).unwrap();
}

/// A dataset of a small synthetic scene (photos pass lowered filters), with `n` photos.
fn small_dataset(tmp: &Path, n: usize, semantics: bool) -> PathBuf {
    let scene = tmp.join(format!("scene{n}"));
    let mut spec = nrw_synth::SceneSpec::demo().shrunk(n, (120, 150), 60_000);
    spec.observations.features = 300;
    nrw_synth::generate(&spec, &scene, &|| {}).unwrap();
    let out = tmp.join(format!("ds{n}"));
    let labels = scene.join("ground_truth/semantics");
    let mut extra = vec!["--max-empty", "1.0", "--quiet"];
    if semantics {
        extra.extend(["--semantics", labels.to_str().unwrap()]);
    }
    let o = ingest_small(&scene, &out, &extra);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    out
}

/// `nrw-etl run FILE SCENE --out OUT EXTRA…` on a scene of ../shared/data.
fn run_pipeline(file: &Path, scene: &str, out: &Path, extra: &[&str]) -> Output {
    let (f, sc) = (file.to_str().unwrap(), data().join(scene));
    let mut args = vec![
        "run",
        f,
        sc.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ];
    args.extend(extra);
    nrw(&args)
}
