//! End-to-end tests of the `nrw-etl` binary on the real scenes in ../shared/data.

#[path = "architecture.rs"]
mod architecture;
#[path = "bad_inputs.rs"]
mod bad_inputs;
#[path = "clean.rs"]
mod clean;
#[path = "colmap_dense.rs"]
mod colmap_dense;
#[path = "densify.rs"]
mod densify;
#[path = "export_models.rs"]
mod export_models;
#[path = "golden.rs"]
mod golden;
#[path = "gsplat.rs"]
mod gsplat;
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
#[path = "paper_code.rs"]
mod paper_code;
#[path = "support/python.rs"]
mod python;
#[path = "python_pkg.rs"]
mod python_pkg;
#[path = "ray.rs"]
mod ray;
#[path = "s3.rs"]
mod s3;
#[path = "segment.rs"]
mod segment;
#[path = "support/shared.rs"]
mod shared;
#[path = "support/timed.rs"]
mod timed;
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

#[test]
fn inspect_json_equals_pycolmap_on_every_copy_of_every_scene() {
    let Some(_) = shared::shared("data") else {
        return;
    };
    let cases = [
        ("sacre_coeur", "sacre_coeur", "bin"),
        ("sacre_coeur", "sacre_coeur", "txt"),
        ("sacre_coeur", "sacre_coeur/sparse_pycolmap421", "bin"),
        ("sacre_coeur", "sacre_coeur/sparse_pycolmap421", "txt"),
        ("sceaux_castle", "sceaux_castle", "bin"),
        ("sceaux_castle", "sceaux_castle", "txt"),
    ];
    for (oracle, dir, enc) in cases {
        let o: serde_json::Value = serde_json::from_str(
            &std::fs::read_to_string(data().join(format!("{oracle}.oracle.json"))).unwrap(),
        )
        .unwrap();
        let scene = data().join(dir);
        let v: serde_json::Value = serde_json::from_str(&ok(&[
            "inspect",
            scene.to_str().unwrap(),
            "--json",
            "--format",
            enc,
        ]))
        .unwrap();
        for k in [
            "cameras",
            "images",
            "points",
            "observations",
            "camera_models",
        ] {
            assert_eq!(v[k], o[k], "{dir} {enc}: {k}");
        }
        for k in ["mean_reprojection_error_px", "max_reprojection_error_px"] {
            let (a, b) = (v[k].as_f64().unwrap(), o[k].as_f64().unwrap());
            assert!((a - b).abs() / b < 1e-9, "{dir} {enc}: {k} {a} vs {b}");
        }
        assert_eq!(v["encoding"], enc);
        assert_eq!(
            v["layout"],
            if dir.ends_with("421") {
                "colmap4"
            } else {
                "colmap3"
            }
        );
    }
}

#[test]
fn inspect_summary_is_readable() {
    let Some(_) = shared::shared("data") else {
        return;
    };
    let out = ok(&["inspect", data().join("sceaux_castle").to_str().unwrap()]);
    assert!(out.contains("images       11"), "{out}");
    assert!(
        out.contains("reprojection mean 0.4048 px, max 3.8074 px over 35812 observations"),
        "{out}"
    );
}

#[test]
fn ingest_writes_scene_tables_and_a_manifest_that_describes_them() {
    let Some(_) = shared::shared("data") else {
        return;
    };
    use arrow_array::{BooleanArray, StringArray, UInt32Array};
    use parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder;

    let out = tempfile::tempdir().unwrap();
    let scene = data().join("sceaux_castle");
    ok(&[
        "ingest",
        scene.to_str().unwrap(),
        "--out",
        out.path().to_str().unwrap(),
        "--min-dim",
        "200",
    ]);
    let rec = nrw_colmap::read_scene(&scene).unwrap();

    let f = std::fs::File::open(out.path().join("scene/images.parquet")).unwrap();
    let batches: Vec<_> = ParquetRecordBatchReaderBuilder::try_new(f)
        .unwrap()
        .build()
        .unwrap()
        .map(|b| b.unwrap())
        .collect();
    let b = &batches[0];
    assert_eq!(b.num_rows(), rec.images.len());
    let ids = column::<UInt32Array>(b, "image_id");
    let names = column::<StringArray>(b, "name");
    let widths = column::<UInt32Array>(b, "photo_width");
    let matches = column::<BooleanArray>(b, "photo_matches_camera");
    let nobs = column::<UInt32Array>(b, "num_observations");
    for row in 0..b.num_rows() {
        let img = &rec.images[&ids.value(row)];
        assert_eq!(names.value(row), img.name);
        // The photo's real width, read independently of the tool.
        let (w, _) = image_size(&scene.join("images").join(&img.name));
        assert_eq!(widths.value(row), w);
        assert!(matches.value(row));
        assert_eq!(nobs.value(row) as usize, img.num_observations());
    }
    assert_eq!(
        nobs.iter().map(|v| v.unwrap() as usize).sum::<usize>(),
        rec.num_observations()
    );

    let m: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.path().join("manifest.json")).unwrap())
            .unwrap();
    for t in m["tables"].as_array().unwrap() {
        let (bytes, sha) =
            nrw_dataset::manifest::sha256_file(&out.path().join(t["path"].as_str().unwrap()))
                .unwrap();
        assert_eq!(t["sha256"], sha.as_str());
        assert_eq!(t["bytes"], bytes);
    }
    // Model files and the dense cloud.
    assert_eq!(m["inputs"].as_array().unwrap().len(), 4);
    // No temporary file is left behind.
    let leftovers: Vec<_> = walk(out.path())
        .into_iter()
        .filter(|p| p.to_string_lossy().ends_with(".tmp"))
        .collect();
    assert!(leftovers.is_empty(), "{leftovers:?}");
}

/// A column of a batch by name, as its concrete Arrow type.
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

#[test]
fn corrupted_models_fail_with_file_record_and_field() {
    let Some(_) = shared::shared("data") else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    let src = data().join("sacre_coeur/sparse/0");
    for f in ["cameras.bin", "images.bin", "points3D.bin"] {
        std::fs::copy(src.join(f), tmp.path().join(f)).unwrap();
    }
    let images = tmp.path().join("images.bin");
    let full = std::fs::read(&images).unwrap();
    std::fs::write(&images, &full[..full.len() / 2]).unwrap();
    let err = fails(&["inspect", tmp.path().to_str().unwrap()]);
    assert!(
        err.contains("images.bin")
            && err.contains("image #")
            && err.contains("field `")
            && err.contains("truncated"),
        "{err}"
    );
    std::fs::write(&images, &full).unwrap();
    let cams = tmp.path().join("cameras.bin");
    let mut c = std::fs::read(&cams).unwrap();
    c[12..16].copy_from_slice(&42i32.to_le_bytes());
    std::fs::write(&cams, &c).unwrap();
    let err = fails(&["inspect", tmp.path().to_str().unwrap(), "--json"]);
    assert!(
        err.contains("cameras.bin")
            && err.contains("camera #0")
            && err.contains("model_id")
            && err.contains("42"),
        "{err}"
    );
}

#[test]
fn ingest_without_photos_says_where_it_looked() {
    let Some(_) = shared::shared("data") else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    let model = tmp.path().join("sparse/0");
    std::fs::create_dir_all(&model).unwrap();
    for f in ["cameras.bin", "images.bin", "points3D.bin"] {
        std::fs::copy(data().join("sacre_coeur/sparse/0").join(f), model.join(f)).unwrap();
    }
    let out = tmp.path().join("out");
    let err = fails(&[
        "ingest",
        tmp.path().to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(
        err.contains("no photo folder found") && err.contains("--images"),
        "{err}"
    );
    std::fs::create_dir_all(tmp.path().join("images")).unwrap();
    let err = fails(&[
        "ingest",
        tmp.path().to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(
        err.contains("10 of 10 registered photos are missing"),
        "{err}"
    );
    assert!(
        !out.join("manifest.json").exists(),
        "nothing written for a failed ingest"
    );
    // Out-of-range render parameters are refused by name before any work.
    for (flag, value, says) in [
        ("--radius", "40", "--radius 40 is outside 0..=32"),
        ("--radius=-1", "", "--radius -1 is outside"),
        ("--max-empty", "1.5", "--max-empty 1.5 is not a fraction"),
    ] {
        let mut args = vec![
            "ingest",
            tmp.path().to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            flag,
        ];
        args.extend([value].iter().filter(|v| !v.is_empty()));
        let err = fails(&args);
        assert!(err.contains(says), "{flag} {value}: {err}");
    }
}

#[test]
fn help_teaches_the_layout_and_examples() {
    let h = ok(&["--help"]);
    assert!(
        h.contains("sparse/0/") && h.contains("Examples:") && h.contains("ingest"),
        "{h}"
    );
    let h = ok(&["ingest", "--help"]);
    assert!(h.contains("--images") && h.contains("--out"), "{h}");
}

#[test]
fn demo_builds_the_embedded_scene_and_runs_every_stage() {
    let out = tempfile::tempdir().unwrap();
    let stdout = ok(&["demo", "--out", out.path().to_str().unwrap()]);
    let scene = out.path().join("scene");
    let dataset = out.path().join("dataset");
    assert!(
        stdout.contains(&format!("scene:   {}", scene.display())),
        "{stdout}"
    );
    assert!(
        stdout.contains(&format!("dataset: {}", dataset.display())),
        "{stdout}"
    );
    // The scene is a COLMAP scene like any other, and the dataset describes all of it.
    let rec = nrw_colmap::read_scene(&scene).unwrap();
    let spec = nrw_synth::SceneSpec::demo();
    assert_eq!(rec.images.len(), spec.cameras.count);
    let m: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dataset.join("manifest.json")).unwrap())
            .unwrap();
    let images = m["tables"]
        .as_array()
        .unwrap()
        .iter()
        .find(|t| t["path"] == "scene/images.parquet")
        .unwrap();
    assert_eq!(images["rows"], spec.cameras.count);
    // Split and export ran too: the official layout holds every kept view.
    let split = nrw_dataset::split::read_splits(&nrw_dataset::Store::from(&dataset)).unwrap();
    let kept = nrw_dataset::scene::read_verdicts(&nrw_dataset::Store::from(&dataset))
        .unwrap()
        .iter()
        .filter(|v| v.2 == "kept")
        .count();
    assert!(kept > 0);
    assert_eq!(split.len(), kept);
    let exported = walk(&out.path().join("export"))
        .iter()
        .filter(|p| p.to_string_lossy().ends_with("_reference.png"))
        .count();
    assert_eq!(exported, kept);
    assert!(stdout.contains("export:  "), "{stdout}");
    // Style descriptors and triplets ran too, on the training photos.
    let (kind, desc) = nrw_dataset::descriptors::read_all(&nrw_dataset::Store::from(&dataset))
        .unwrap()
        .unwrap();
    assert_eq!((kind.tier.as_str(), desc.len()), ("color-stats", kept));
    assert!(dataset.join("triplets.parquet").is_file());
    let report: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(scene.join("ground_truth/report.json")).unwrap(),
    )
    .unwrap();
    let v: serde_json::Value =
        serde_json::from_str(&ok(&["inspect", scene.to_str().unwrap(), "--json"])).unwrap();
    let (a, b) = (
        v["mean_reprojection_error_px"].as_f64().unwrap(),
        report["mean_reprojection_error_px"].as_f64().unwrap(),
    );
    assert!((a - b).abs() < 1e-9, "inspect {a} vs generator {b}");
}

#[test]
fn synth_reads_a_spec_file_and_reports_bad_ones() {
    let out = tempfile::tempdir().unwrap();
    let spec = out.path().join("s.toml");
    std::fs::write(&spec, "name = 'x'\nseed = 5\n[cameras]\ncount = 2\nmin_size = 64\nmax_size = 96\n[geometry]\npoints = 1000\n").unwrap();
    ok(&[
        "synth",
        spec.to_str().unwrap(),
        "--out",
        out.path().join("scene").to_str().unwrap(),
    ]);
    assert_eq!(
        nrw_colmap::read_scene(&out.path().join("scene"))
            .unwrap()
            .images
            .len(),
        2
    );
    std::fs::write(&spec, "name = 'x'\nseed = 5\n[cameras]\nmodel = 'WIDE'\n").unwrap();
    let err = fails(&[
        "synth",
        spec.to_str().unwrap(),
        "--out",
        out.path().join("bad").to_str().unwrap(),
    ]);
    assert!(
        err.contains("s.toml") && err.contains("cameras.model") && err.contains("WIDE"),
        "{err}"
    );
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

#[test]
fn interrupted_ingest_resumes_to_the_same_bytes_on_any_thread_count() {
    let tmp = tempfile::tempdir().unwrap();
    let scene = tmp.path().join("scene");
    small_scene(&scene, 9);
    let run = |out: &Path, threads: &str, extra: &[&str]| -> Output {
        let common = ["--rows-per-shard", "2", "--quiet", "--threads", threads];
        ingest_small(&scene, out, &[&common[..], extra].concat())
    };
    let whole = tmp.path().join("whole");
    let o = run(&whole, "1", &[]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));

    let resumed = tmp.path().join("resumed");
    let o = run(&resumed, "2", &["--stop-after-groups", "2"]);
    assert_eq!(
        o.status.code(),
        Some(130),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    assert!(String::from_utf8_lossy(&o.stderr).contains("run the same command again to resume"));
    assert!(
        !resumed.join("manifest.json").exists(),
        "no manifest for an unfinished dataset"
    );
    let o = run(&resumed, "2", &["--json"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let summary: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(
        summary["resumed_groups"], 2,
        "the two finished groups were not redone"
    );

    let (fa, fb) = (files(&whole), files(&resumed));
    assert_eq!(fa.keys().collect::<Vec<_>>(), fb.keys().collect::<Vec<_>>());
    for (k, v) in &fa {
        assert!(
            v == &fb[k],
            "{} differs between the whole run (1 thread) and the resumed one (2 threads)",
            k.display()
        );
    }
    assert!(fa.keys().filter(|k| k.starts_with("shards")).count() >= 3);
}

#[test]
fn the_renderers_kept_verdict_is_the_word_readers_look_for() {
    // Ingest writes Verdict::name(); QA, split and the trainer compare with VERDICT_KEPT.
    let kept = nrw_render::Verdict::Kept { empty_ratio: 0.5 };
    assert_eq!(kept.name(), nrw_dataset::scene::VERDICT_KEPT);
}

#[test]
fn a_scene_where_every_view_is_dropped_exits_3_with_every_verdict_recorded() {
    let Some(_) = shared::shared("data") else {
        return;
    };
    use arrow_array::{Float64Array, StringArray};
    use parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder;
    let out = tempfile::tempdir().unwrap();
    let o = nrw(&[
        "ingest",
        data().join("sacre_coeur").to_str().unwrap(),
        "--out",
        out.path().to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(3));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("no view survived the filters") && err.contains("10 too sparse"),
        "{err}"
    );
    let f = std::fs::File::open(out.path().join("scene/images.parquet")).unwrap();
    let b = ParquetRecordBatchReaderBuilder::try_new(f)
        .unwrap()
        .build()
        .unwrap()
        .next()
        .unwrap()
        .unwrap();
    let verdicts = column::<StringArray>(&b, "verdict");
    let values = column::<Float64Array>(&b, "verdict_value");
    for i in 0..b.num_rows() {
        assert_eq!(verdicts.value(i), "too_sparse");
        // The data README: sparse points leave 97–99% of pixels empty.
        assert!(
            (0.97..1.0).contains(&values.value(i)),
            "{}",
            values.value(i)
        );
    }
    let m: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.path().join("manifest.json")).unwrap())
            .unwrap();
    assert!(m["tables"]
        .as_array()
        .unwrap()
        .iter()
        .all(|t| !t["path"].as_str().unwrap().starts_with("shards/")));
}

#[test]
fn shard_payloads_decode_and_align() {
    let Some(_) = shared::shared("data") else {
        return;
    };
    use arrow_array::{BinaryArray, UInt32Array};
    use parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder;
    let out = tempfile::tempdir().unwrap();
    ok(&[
        "ingest",
        data().join("sceaux_castle").to_str().unwrap(),
        "--out",
        out.path().to_str().unwrap(),
        "--min-dim",
        "150",
        "--min-photo-side",
        "100",
        "--quiet",
    ]);
    let f = std::fs::File::open(out.path().join("shards/views-00000.parquet")).unwrap();
    let builder = ParquetRecordBatchReaderBuilder::try_new(f).unwrap();
    assert!(
        builder.metadata().num_row_groups() >= 2,
        "small row groups for random access"
    );
    let mut rows = 0;
    for b in builder.build().unwrap() {
        let b = b.unwrap();
        let (w, h) = (
            column::<UInt32Array>(&b, "width"),
            column::<UInt32Array>(&b, "height"),
        );
        for i in 0..b.num_rows() {
            let (w, h) = (w.value(i), h.value(i));
            assert_eq!(w.min(h), 150);
            let name = Path::new("row");
            let (pw, ph, pc, _) = nrw_dataset::codec::decode_png(
                column::<BinaryArray>(&b, "photo_png").value(i),
                name,
            )
            .unwrap();
            assert_eq!((pw, ph, pc), (w, h, 3));
            let (cw, ch, cc, rgba) = nrw_dataset::codec::decode_png(
                column::<BinaryArray>(&b, "color_png").value(i),
                name,
            )
            .unwrap();
            assert_eq!((cw, ch, cc), (w, h, 4));
            let depth = nrw_dataset::depth::decode_exr(
                column::<BinaryArray>(&b, "depth_exr").value(i),
                name,
            )
            .unwrap();
            assert_eq!((depth.width as u32, depth.height as u32), (w, h));
            for (k, d) in depth.data.iter().enumerate() {
                assert_eq!(*d > 0.0, rgba[k * 4 + 3] == 255, "alpha is coverage");
            }
            // fused.ply has normals, so the normal channel is there.
            let normals = column::<BinaryArray>(&b, "normal_png");
            assert!(!arrow_array::Array::is_null(normals, i));
            rows += 1;
        }
    }
    assert_eq!(rows, 11);
}

#[test]
fn shards_read_back_with_pyarrow_duckdb_and_openexr() {
    let Some(_) = shared::shared("data") else {
        return;
    };
    if !python_has("import pyarrow, duckdb, OpenEXR, PIL, numpy") {
        return;
    }
    let out = tempfile::tempdir().unwrap();
    ok(&[
        "ingest",
        data().join("sceaux_castle").to_str().unwrap(),
        "--out",
        out.path().to_str().unwrap(),
        "--min-dim",
        "150",
        "--min-photo-side",
        "100",
        "--quiet",
    ]);
    // Descriptors too, so their CRC-32s are checked from Python as well.
    ok(&[
        "style",
        out.path().to_str().unwrap(),
        "--tier",
        "color-stats",
        "--quiet",
    ]);
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../tests/oracles/read_shards.py");
    let o = Command::new("python3")
        .arg(script)
        .arg(out.path())
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(v["kept"], 11);
    assert_eq!(v["shard_rows"], 11);
    assert_eq!(v["views_checked"], 11);
    assert_eq!(v["descriptors_checked"], 11);
}

#[test]
fn the_sparse_views_scene_is_dropped_whole_with_exit_3() {
    let tmp = tempfile::tempdir().unwrap();
    let scene = tmp.path().join("scene");
    let text = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes/sparse_views.toml"),
    )
    .unwrap();
    let mut spec = nrw_synth::SceneSpec::from_toml(&text, "sparse_views").unwrap();
    spec.cameras.count = 3;
    spec.cameras.min_size = 120;
    spec.cameras.max_size = 150;
    nrw_synth::generate(&spec, &scene, &|| {}).unwrap();
    let out = tmp.path().join("ds");
    let o = nrw(&[
        "ingest",
        scene.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--min-photo-side",
        "100",
        "--json",
        "--quiet",
    ]);
    assert_eq!(
        o.status.code(),
        Some(3),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    let s: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(
        (s["kept"].as_u64(), s["too_sparse"].as_u64()),
        (Some(0), Some(3))
    );
}

#[test]
fn the_point_source_is_fused_ply_then_sparse_points_then_an_error_and_points_overrides() {
    let tmp = tempfile::tempdir().unwrap();
    let scene = tmp.path().join("scene");
    small_scene(&scene, 3);
    let run = |out: &str, extra: &[&str]| -> Output {
        let extra = [&["--json", "--quiet"], extra].concat();
        ingest_small(&scene, &tmp.path().join(out), &extra)
    };
    // Exit 0 or 3 (every view too sparse) both end with the summary.
    let source = |o: Output| -> (String, u64) {
        assert!(
            matches!(o.status.code(), Some(0 | 3)),
            "{}",
            String::from_utf8_lossy(&o.stderr)
        );
        let s: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        (
            s["point_source"].as_str().unwrap().into(),
            s["points"].as_u64().unwrap(),
        )
    };
    let fused = scene.join("dense/fused.ply");
    let dense = nrw_colmap::read_ply(&fused).unwrap();
    assert_eq!(source(run("a", &[])), ("ply".into(), dense.len() as u64));

    // --points wins over dense/fused.ply: a cloud of its first 1,000 points.
    let other = tmp.path().join("other.ply");
    let mut few = dense.clone();
    few.positions.truncate(1000);
    if let Some(c) = few.colors.as_mut() {
        c.truncate(1000);
    }
    if let Some(n) = few.normals.as_mut() {
        n.truncate(1000);
    }
    nrw_colmap::write_ply(&few, &other).unwrap();
    assert_eq!(
        source(run("b", &["--points", other.to_str().unwrap()])),
        ("ply".into(), 1000)
    );
    let missing = tmp.path().join("nowhere.ply");
    let err = fails(&[
        "ingest",
        scene.to_str().unwrap(),
        "--out",
        tmp.path().join("c").to_str().unwrap(),
        "--points",
        missing.to_str().unwrap(),
    ]);
    assert!(err.contains("nowhere.ply"), "{err}");

    // Without dense/fused.ply: the model's sparse points.
    std::fs::remove_file(&fused).unwrap();
    let model = scene.join("sparse/0");
    let mut rec = nrw_colmap::read_scene(&scene).unwrap();
    assert_eq!(
        source(run("d", &[])),
        ("sparse".into(), rec.points.len() as u64)
    );

    // A model without 3D points either: a clear error, nothing written.
    rec.points.clear();
    for img in rec.images.values_mut() {
        img.points2d.clear();
    }
    let format = rec.format.unwrap_or(nrw_colmap::Format::Binary);
    nrw_colmap::write_model(&rec, &model, format).unwrap();
    let out = tmp.path().join("e");
    let err = fails(&[
        "ingest",
        scene.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(
        err.contains("nothing to render") && err.contains("--points"),
        "{err}"
    );
    assert!(!out.join("manifest.json").exists());
}

#[test]
fn semantics_are_stored_colour_coded_with_a_transient_mask() {
    use arrow_array::{BinaryArray, StringArray, UInt32Array};
    use parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder;
    let tmp = tempfile::tempdir().unwrap();
    let scene = tmp.path().join("scene");
    let mut spec = nrw_synth::SceneSpec::demo().shrunk(4, (120, 150), 60_000);
    spec.effects.transients = Some(6.0);
    nrw_synth::generate(&spec, &scene, &|| {}).unwrap();
    let out = tmp.path().join("ds");
    let labels = scene.join("ground_truth/semantics");
    let o = nrw(&[
        "ingest",
        scene.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--semantics",
        labels.to_str().unwrap(),
        "--min-photo-side",
        "100",
        "--min-dim",
        "96",
        "--max-empty",
        "1.0",
        "--quiet",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let f = std::fs::File::open(out.join("shards/views-00000.parquet")).unwrap();
    let (mut people, mut rows) = (0usize, 0usize);
    for b in ParquetRecordBatchReaderBuilder::try_new(f)
        .unwrap()
        .build()
        .unwrap()
    {
        let b = b.unwrap();
        for i in 0..b.num_rows() {
            rows += 1;
            let name = column::<StringArray>(&b, "name").value(i);
            let (w, h) = (
                column::<UInt32Array>(&b, "width").value(i),
                column::<UInt32Array>(&b, "height").value(i),
            );
            let (sw, sh, sc, rgb) = nrw_dataset::codec::decode_png(
                column::<BinaryArray>(&b, "semantics_png").value(i),
                Path::new(name),
            )
            .unwrap();
            let (_, _, mc, mask) = nrw_dataset::codec::decode_png(
                column::<BinaryArray>(&b, "transient_png").value(i),
                Path::new(name),
            )
            .unwrap();
            assert_eq!((sw, sh, sc, mc), (w, h, 3, 1));
            // Independently: nearest-resize the ground-truth ids and compare pixel by pixel.
            let gt = image::open(labels.join(Path::new(name).with_extension("png")))
                .unwrap()
                .to_luma8();
            for y in 0..h {
                for x in 0..w {
                    let sx = ((x as f64 + 0.5) * gt.width() as f64 / w as f64) as u32;
                    let sy = ((y as f64 + 0.5) * gt.height() as f64 / h as f64) as u32;
                    let id = gt.get_pixel(sx.min(gt.width() - 1), sy.min(gt.height() - 1))[0];
                    let k = (y * w + x) as usize;
                    let person = id == 13;
                    assert_eq!(mask[k] == 255, person, "{name} ({x},{y}) id {id}");
                    if person {
                        assert_eq!(&rgb[k * 3..k * 3 + 3], &[150, 5, 61]);
                        people += 1;
                    }
                    if id == 3 {
                        assert_eq!(&rgb[k * 3..k * 3 + 3], &[6, 230, 230], "sky");
                    }
                }
            }
        }
    }
    assert_eq!(rows, 4);
    assert!(
        people > 0,
        "the scene asked for people; some must be labelled"
    );
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

fn split_of(ds: &Path) -> std::collections::BTreeMap<String, String> {
    nrw_dataset::split::read_splits(&nrw_dataset::Store::from(ds))
        .unwrap()
        .into_iter()
        .map(|a| (a.name, a.split))
        .collect()
}

#[test]
fn split_is_reproducible_exact_and_incremental() {
    let tmp = tempfile::tempdir().unwrap();
    let ds = small_dataset(tmp.path(), 9, false);
    let copy = tmp.path().join("copy");
    std::fs::create_dir_all(&copy).unwrap();
    for f in walk(&ds) {
        let rel = f.strip_prefix(&ds).unwrap();
        std::fs::create_dir_all(copy.join(rel).parent().unwrap()).unwrap();
        std::fs::copy(&f, copy.join(rel)).unwrap();
    }
    ok(&["split", ds.to_str().unwrap(), "--val", "3", "--seed", "11"]);
    ok(&[
        "split",
        copy.to_str().unwrap(),
        "--val",
        "3",
        "--seed",
        "11",
    ]);
    assert_eq!(
        std::fs::read(ds.join("splits.parquet")).unwrap(),
        std::fs::read(copy.join("splits.parquet")).unwrap()
    );
    let first = split_of(&ds);
    assert_eq!(first.len(), 9);
    assert_eq!(first.values().filter(|s| *s == "val").count(), 3);
    let v: serde_json::Value =
        serde_json::from_str(&ok(&["inspect", ds.to_str().unwrap(), "--json"])).unwrap();
    assert_eq!(
        (v["splits"]["train"].as_u64(), v["splits"]["val"].as_u64()),
        (Some(6), Some(3))
    );

    // The same scene with three more photos (the generator draws photos in order, so the
    // first nine are identical), ingested into the same dataset, then split again.
    let bigger = small_dataset(tmp.path(), 12, false);
    std::fs::copy(ds.join("splits.parquet"), bigger.join("splits.parquet")).unwrap();
    ok(&[
        "split",
        bigger.to_str().unwrap(),
        "--val",
        "4",
        "--seed",
        "99",
    ]);
    let second = split_of(&bigger);
    assert_eq!(second.len(), 12);
    for (name, s) in &first {
        assert_eq!(&second[name], s, "{name} moved from {s}");
    }
    assert_eq!(second.values().filter(|s| *s == "val").count(), 4);
    let err = fails(&["split", bigger.to_str().unwrap(), "--val", "40"]);
    assert!(
        err.contains("--val 40") && err.contains("only 0 unassigned") && err.contains("12 kept"),
        "{err}"
    );
    let err = fails(&["split", bigger.to_str().unwrap(), "--val", "2"]);
    assert!(
        err.contains("4 validation photos already assigned"),
        "{err}"
    );
}

#[test]
fn reader_streams_a_split_and_crops_every_channel_at_one_place() {
    use nrw_dataset::reader::Dataset;
    let tmp = tempfile::tempdir().unwrap();
    let ds_dir = small_dataset(tmp.path(), 9, true);
    ok(&[
        "split",
        ds_dir.to_str().unwrap(),
        "--val",
        "2",
        "--seed",
        "5",
    ]);
    let ds = Dataset::open(&ds_dir).unwrap();
    let want: Vec<u32> = ds.ids("val").unwrap().to_vec();
    let got: Vec<u32> = ds
        .iter_split("val")
        .unwrap()
        .map(|v| v.unwrap().image_id)
        .collect();
    assert_eq!(got, want);
    let train: Vec<u32> = ds
        .iter_split("train")
        .unwrap()
        .map(|v| v.unwrap().image_id)
        .collect();
    assert_eq!(train.len(), 7);
    assert!(
        train.iter().all(|id| !want.contains(id)),
        "splits are disjoint"
    );
    let v = ds.get(train[3]).unwrap();
    assert_eq!(v.image_id, train[3]);
    let (photo, color, depth) = (v.photo().unwrap(), v.color().unwrap(), v.depth().unwrap());
    let c = v.crop_at(7, 5, 64).unwrap();
    for y in 0..64u32 {
        for x in 0..64u32 {
            assert_eq!(c.photo.get_pixel(x, y), photo.get_pixel(x + 7, y + 5));
            assert_eq!(c.color.get_pixel(x, y), color.get_pixel(x + 7, y + 5));
            let d = c.depth[(y * 64 + x) as usize];
            assert_eq!(d, depth.data[((y + 5) * v.width + x + 7) as usize]);
            assert_eq!(
                d > 0.0,
                c.color.get_pixel(x, y)[3] == 255,
                "alpha is coverage inside the crop"
            );
        }
    }
    assert!(c.semantics.is_some() && c.transient.is_some());
    let too_big = v.crop_at(0, 0, 4096).unwrap_err().to_string();
    assert!(too_big.contains("does not fit"), "{too_big}");
    assert!(ds
        .get(999_999)
        .unwrap_err()
        .to_string()
        .contains("not a kept view"));
    // Another schema version is refused with a clear message.
    let m = ds_dir.join("manifest.json");
    let text = std::fs::read_to_string(&m).unwrap().replace(
        &format!("\"schema_version\": {}", nrw_dataset::SCHEMA_VERSION),
        "\"schema_version\": 7",
    );
    std::fs::write(&m, text).unwrap();
    let e = Dataset::open(&ds_dir).unwrap_err().to_string();
    assert!(
        e.contains("schema version 7") && e.contains("re-run ingest"),
        "{e}"
    );
}

/// Run tests/oracles/paper_oracle.py (the published code itself) in its records mode: the official
/// folders through `AlignedRenderedDataset` → `_generate_tfrecord_dataset` →
/// `_parser_rendered_dataset`, our TFRecords through the same parser, compared. None when
/// TensorFlow is not installed here (a skip that says so; CI requires it).
fn published_records(args: &[&str]) -> Option<serde_json::Value> {
    if !python_has(paper_code::PAPER_DEPS) {
        return None;
    }
    shared::shared("paper-code")?;
    Some(paper_code::paper_oracle(args))
}

/// Files under `dir`, relative, sorted.
fn listing(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = walk(dir)
        .iter()
        .map(|p| p.strip_prefix(dir).unwrap().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}

fn export_json(dir: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(dir.join("export.json")).unwrap()).unwrap()
}

#[test]
fn official_and_tfrecord_exports_are_what_the_published_code_reads() {
    use nrw_dataset::reader::Dataset;
    if !python_has("import numpy, PIL, pyarrow") {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let ds_dir = small_dataset(tmp.path(), 6, true);
    let d = ds_dir.to_str().unwrap();
    let off = tmp.path().join("official");
    let tfr = tmp.path().join("tfr");
    let err = fails(&["export", d, "--out", off.to_str().unwrap()]);
    assert!(
        err.contains("needs a train split") && err.contains("split it first (--val N"),
        "{err}"
    );
    ok(&["split", d, "--val", "2"]);
    let stdout = ok(&[
        "export",
        d,
        "--out",
        off.to_str().unwrap(),
        "--name",
        "tiny",
        "--crop",
        "none",
    ]);
    assert!(
        stdout.contains("exported 6 views (train 4, val 2)"),
        "{stdout}"
    );
    ok(&[
        "export",
        d,
        "--layout",
        "tfrecord",
        "--shards", // the old name of --tfrecord-files, still taken
        "2",
        "--out",
        tfr.to_str().unwrap(),
        "--name",
        "tiny",
        "--crop",
        "none",
        "--quiet",
    ]);
    // The published converter and parser read both exports, to the same tensors.
    if let Some(v) = published_records(&[
        "--official",
        off.to_str().unwrap(),
        "--tfrecord",
        tfr.to_str().unwrap(),
        "--name",
        "tiny",
    ]) {
        eprintln!("paper_oracle.py: {v}");
        for (split, n) in [("train", 4), ("val", 2)] {
            assert_eq!(v["splits"][split]["views"], n, "{v}");
            assert_eq!(v["splits"][split]["records"], n, "{v}");
        }
    }
    // Exactly the paper's files, TFRecords named for the published glob.
    let files = listing(&off);
    assert_eq!(
        files.iter().filter(|f| f.starts_with("train/")).count(),
        16,
        "{files:?}"
    );
    assert_eq!(
        files.iter().filter(|f| f.starts_with("val/")).count(),
        8,
        "{files:?}"
    );
    assert!(!files.iter().any(|f| f.ends_with(".pckl")), "{files:?}");
    assert_eq!(
        listing(&tfr),
        [
            "export.json",
            "tiny-00000-of-00002_train.tfrecord",
            "tiny-00000-of-00002_val.tfrecord",
            "tiny-00001-of-00002_train.tfrecord",
            "tiny-00001-of-00002_val.tfrecord",
        ]
    );
    // Depth: levels 1-255 by the formula export.json records (linear by default), 0 exactly
    // where empty; the recorded inverse gives back the depth within half a level's spacing.
    let ds = Dataset::open(&ds_dir).unwrap();
    let meta = export_json(&off);
    let (near, far) = (
        meta["depth"]["near"].as_f64().unwrap(),
        meta["depth"]["far"].as_f64().unwrap(),
    );
    assert_eq!(meta["depth"]["mapping"], "linear");
    assert_eq!(
        Some((near, far)),
        nrw_dataset::scene::read_depth_range(&nrw_dataset::Store::from(&ds_dir)).unwrap()
    );
    let step = (far - near) / 254.0;
    let mut levels = std::collections::BTreeSet::new();
    for split in ["train", "val"] {
        let ids = meta["splits"]
            .as_array()
            .unwrap()
            .iter()
            .find(|s| s["split"] == split)
            .unwrap()["image_ids"]
            .clone();
        for (k, view) in ds.iter_split(split).unwrap().enumerate() {
            let view = view.unwrap();
            assert_eq!(
                ids[k], view.image_id,
                "export.json maps index {k} to the image id"
            );
            let png = image::open(off.join(split).join(format!("{k:04}_depth.png"))).unwrap();
            assert_eq!(png.color(), image::ColorType::L8);
            let truth = view.depth().unwrap();
            for (p, &t) in png.to_luma8().pixels().zip(&truth.data) {
                let l = p[0];
                assert_eq!(l == 0, t == 0.0, "0 = empty");
                if l > 0 {
                    levels.insert(l);
                    // The recorded formula: d = near + (level - 1) / 254 * (far - near).
                    let back = near + (l - 1) as f64 / 254.0 * (far - near);
                    assert!(
                        (back - t as f64).abs() <= step / 2.0 * (1.0 + 1e-9),
                        "level {l} for depth {t}"
                    );
                }
            }
            // The photo and the render are the stored ones, pixel for pixel.
            let rgb = image::open(off.join(split).join(format!("{k:04}_reference.png"))).unwrap();
            assert_eq!(rgb.to_rgb8(), view.photo().unwrap());
            let rgba = image::open(off.join(split).join(format!("{k:04}_color.png"))).unwrap();
            assert_eq!(rgba.to_rgba8(), view.color().unwrap());
        }
    }
    assert!(
        levels.len() > 20,
        "depth uses more than a few levels: {}",
        levels.len()
    );
    // The files layout keeps ADE20K ids and colour150.
    let files_out = tmp.path().join("files");
    ok(&[
        "export",
        d,
        "--layout",
        "files",
        "--out",
        files_out.to_str().unwrap(),
        "--quiet",
    ]);
    let v = ds.iter_split("val").unwrap().next().unwrap().unwrap();
    let dir = files_out
        .join("val")
        .join(Path::new(&v.name).with_extension(""));
    for f in [
        "photo.png",
        "color.png",
        "depth.exr",
        "normal.png",
        "semantics.png",
        "labels.png",
        "transient.png",
        "meta.json",
    ] {
        assert!(dir.join(f).is_file(), "{f}");
    }
    assert_eq!(
        image::open(dir.join("labels.png")).unwrap().to_luma8(),
        v.labels().unwrap().unwrap()
    );
    assert_eq!(
        image::open(dir.join("semantics.png")).unwrap().to_rgb8(),
        v.semantics().unwrap().unwrap()
    );
    assert_eq!(
        nrw_dataset::depth::read_exr(&dir.join("depth.exr")).unwrap(),
        v.depth().unwrap()
    );
}

#[test]
fn official_export_refuses_bad_requests_and_never_leaves_stale_files() {
    let tmp = tempfile::tempdir().unwrap();
    let plain = small_dataset(tmp.path(), 5, false);
    let p = plain.to_str().unwrap();
    ok(&["split", p, "--val", "0"]);
    let out = tmp.path().join("out");
    let o = out.to_str().unwrap();
    let leftovers = || {
        std::fs::read_dir(tmp.path())
            .unwrap()
            .flatten()
            .filter(|e| e.file_name().to_string_lossy().contains(".export-"))
            .count()
    };
    // No semantics: refused with what to do, nothing written.
    let e = fails(&["export", p, "--out", o]);
    assert!(
        e.contains("--semantics")
            && e.contains("--no-semantics")
            && e.contains("--use_semantic=False"),
        "{e}"
    );
    assert!(!out.exists() && leftovers() == 0);
    // --no-semantics: the loader's files without *_seg_rgb.png; the empty val split is named.
    let run = nrw(&["export", p, "--out", o, "--no-semantics", "--crop", "none"]);
    assert!(run.status.success());
    let err = String::from_utf8_lossy(&run.stderr);
    assert!(err.contains("split val has no view: not written"), "{err}");
    let files = listing(&out);
    assert_eq!(files.len(), 5 * 3 + 1, "{files:?}");
    assert!(files.iter().all(|f| !f.contains("seg_rgb")));
    assert_eq!(export_json(&out)["semantics"], serde_json::Value::Null);
    // No published converter reads a folder without *_seg_rgb.png (AlignedRenderedDataset
    // raises NameError on img_seg); what trains with --use_semantic=False is the TFRecords,
    // which the published parser reads with use_semantics=False.
    let tfr = tmp.path().join("tfr_plain");
    ok(&[
        "export",
        p,
        "--layout",
        "tfrecord",
        "--out",
        tfr.to_str().unwrap(),
        "--name",
        "plain",
        "--no-semantics",
        "--crop",
        "none",
        "--quiet",
    ]);
    if let Some(v) = published_records(&[
        "--tfrecord",
        tfr.to_str().unwrap(),
        "--name",
        "plain",
        "--no-semantics",
    ]) {
        assert_eq!(v["splits"]["train"]["records"], 5, "{v}");
    }
    // A crop larger than every view: refused, naming a view and its size.
    let e = fails(&["export", p, "--out", o, "--no-semantics", "--crop", "4000"]);
    assert!(
        e.contains("no train view is left") && e.contains("photo_") && e.contains('×'),
        "{e}"
    );
    // ... and the earlier export is still there, whole.
    assert_eq!(listing(&out), files);
    // The files layout keeps views whole: a crop is refused, not ignored.
    let e = fails(&["export", p, "--out", o, "--layout", "files", "--crop", "64"]);
    assert!(
        e.contains("--crop applies to the official and tfrecord layouts"),
        "{e}"
    );
    assert_eq!(listing(&out), files);
    // A crop that fits: every channel cropped, export.json says so.
    ok(&[
        "export",
        p,
        "--out",
        o,
        "--no-semantics",
        "--crop",
        "64",
        "--quiet",
    ]);
    assert_eq!(export_json(&out)["crop"], 64);
    // Every channel of every view is the same 64 × 64 window of the uncropped export, at the
    // published start ((side − 64) // 2 in x and y): offsets and alignment, not only sizes.
    let whole = tmp.path().join("whole");
    ok(&[
        "export",
        p,
        "--out",
        whole.to_str().unwrap(),
        "--no-semantics",
        "--crop",
        "none",
        "--quiet",
    ]);
    let mut checked = 0;
    for f in listing(&whole).iter().filter(|f| f.ends_with(".png")) {
        let full = image::open(whole.join(f)).unwrap();
        let cut = image::open(out.join(f)).unwrap();
        assert_eq!((cut.width(), cut.height()), (64, 64), "{f}");
        assert_eq!(cut.color(), full.color(), "{f}");
        let (x, y) = ((full.width() - 64) / 2, (full.height() - 64) / 2);
        assert!(
            cut.as_bytes() == full.crop_imm(x, y, 64, 64).as_bytes(),
            "{f}: not the centre window at ({x}, {y})"
        );
        checked += 1;
    }
    assert_eq!(checked, 5 * 3, "reference, color and depth of 5 views");
    // Replacing an export with a smaller one leaves none of the earlier files.
    let smaller = small_dataset(tmp.path(), 3, false);
    ok(&["split", smaller.to_str().unwrap(), "--val", "1"]);
    ok(&[
        "export",
        smaller.to_str().unwrap(),
        "--out",
        o,
        "--no-semantics",
        "--crop",
        "none",
        "--quiet",
    ]);
    let now = listing(&out);
    assert_eq!(now.len(), 3 * 3 + 1, "{now:?}");
    let json = export_json(&out);
    let listed: usize = json["splits"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| s["files"].as_array().unwrap().len())
        .sum();
    assert_eq!(listed + 1, now.len(), "every file is the new export's");
    assert_eq!(leftovers(), 0, "no staging folder left behind");
    // A folder of someone else's files is not replaced; a file is not a folder.
    let foreign = tmp.path().join("foreign");
    std::fs::create_dir_all(&foreign).unwrap();
    std::fs::write(foreign.join("notes.txt"), "mine").unwrap();
    let e = fails(&[
        "export",
        p,
        "--out",
        foreign.to_str().unwrap(),
        "--no-semantics",
    ]);
    assert!(e.contains("not an nrw-etl export"), "{e}");
    assert_eq!(
        std::fs::read_to_string(foreign.join("notes.txt")).unwrap(),
        "mine"
    );
    let file = tmp.path().join("file");
    std::fs::write(&file, "x").unwrap();
    let e = fails(&[
        "export",
        p,
        "--out",
        file.to_str().unwrap(),
        "--no-semantics",
    ]);
    assert!(e.contains("is a file"), "{e}");
}

#[test]
fn the_twenty_line_python_example_yields_aligned_training_tensors() {
    if !python_has("import pyarrow, OpenEXR, PIL, numpy") {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let ds = small_dataset(tmp.path(), 5, false);
    ok(&["split", ds.to_str().unwrap(), "--val", "1"]);
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../docs/python_reader.py");
    assert!(
        std::fs::read_to_string(&script).unwrap().lines().count() <= 20,
        "the issue asks for a 20-line example"
    );
    let o = Command::new("python3")
        .arg(&script)
        .arg(&ds)
        .arg("64")
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let text = String::from_utf8(o.stdout).unwrap();
    let lines: Vec<&str> = text.lines().collect();
    assert_eq!(lines.len(), 4, "the 4 training views: {text}");
    for l in lines {
        assert!(l.contains("(64, 64, 3) (64, 64, 4) (64, 64, 1)"), "{l}");
    }
}

#[test]
fn style_image_writes_the_five_grams_that_match_pytorch() {
    let Some(_) = shared::shared("fixtures") else {
        return;
    };
    let shared = shared::shared_dir();
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("g.safetensors");
    let png = shared.join("fixtures/vgg16/02928139_3448003521_320x240.png");
    ok(&[
        "style",
        "--image",
        png.to_str().unwrap(),
        "--weights",
        shared
            .join("weights/vgg16_imagenet.safetensors")
            .to_str()
            .unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    let ours = std::fs::read(&out).unwrap();
    let ours = safetensors::SafeTensors::deserialize(&ours).unwrap();
    let fix = std::fs::read(shared.join("fixtures/vgg16/02928139_3448003521_320x240.safetensors"))
        .unwrap();
    let fix = safetensors::SafeTensors::deserialize(&fix).unwrap();
    for layer in ["relu1_2", "relu2_2", "relu3_2", "relu4_2", "relu5_2"] {
        let name = format!("gram_{layer}");
        let a = ours.tensor(&name).unwrap();
        assert_eq!(a.dtype(), safetensors::Dtype::F32);
        let a: Vec<f64> = a
            .data()
            .chunks_exact(4)
            .map(|c| f32::from_le_bytes(c.try_into().unwrap()) as f64)
            .collect();
        let b: Vec<f64> = fix
            .tensor(&name)
            .unwrap()
            .data()
            .chunks_exact(8)
            .map(|c| f64::from_le_bytes(c.try_into().unwrap()))
            .collect();
        let scale = b.iter().fold(0f64, |m, v| m.max(v.abs()));
        let worst = a
            .iter()
            .zip(&b)
            .map(|(x, y)| (x - y).abs())
            .fold(0f64, f64::max)
            / scale;
        assert!(worst < 1e-4, "{layer}: {worst:e}");
    }
    let err = fails(&[
        "style",
        "--image",
        png.to_str().unwrap(),
        "--weights",
        png.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(err.contains("not a safetensors file"), "{err}");
}

#[test]
fn style_describes_a_dataset_resumably_and_never_mixes_kinds() {
    let Some(_) = shared::shared("weights") else {
        return;
    };
    let shared = shared::shared_dir();
    let weights = shared.join("weights/vgg16_imagenet.safetensors");
    let tmp = tempfile::tempdir().unwrap();
    let ds = small_dataset(tmp.path(), 5, false);
    let d = ds.to_str().unwrap();
    // Without weights a VGG tier is refused with the explicit fallback named.
    let err = fails(&["style", d, "--tier", "vgg16-128"]);
    assert!(
        err.contains("--weights") && err.contains("color-stats"),
        "{err}"
    );
    let o = nrw(&["style", d, "--tier", "color-stats"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let (kind, rows) = nrw_dataset::descriptors::read_all(&nrw_dataset::Store::from(&ds))
        .unwrap()
        .unwrap();
    assert_eq!(
        (kind.tier.as_str(), rows.len(), rows[0].descriptor.len()),
        ("color-stats", 5, 9)
    );
    // Rerun: nothing recomputed.
    let o = nrw(&["style", d, "--tier", "color-stats"]);
    assert!(
        String::from_utf8_lossy(&o.stderr).contains("0 parts written, 1 already there"),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    // Another kind is refused unless asked to overwrite.
    let w = weights.to_str().unwrap();
    let err = fails(&["style", d, "--tier", "vgg16-128", "--weights", w]);
    assert!(
        err.contains("--overwrite") && err.contains("color-stats"),
        "{err}"
    );
    ok(&[
        "style",
        d,
        "--tier",
        "vgg16-128",
        "--weights",
        w,
        "--overwrite",
        "--quiet",
    ]);
    let (kind, rows) = nrw_dataset::descriptors::read_all(&nrw_dataset::Store::from(&ds))
        .unwrap()
        .unwrap();
    assert_eq!(kind.tier, "vgg16-128");
    assert_eq!(kind.weights_sha256.len(), 64);
    assert_eq!(
        rows[0].descriptor.len(),
        [64usize, 128, 256, 512, 512]
            .iter()
            .map(|c| c * (c + 1) / 2)
            .sum::<usize>()
    );
    // The squared distance of two descriptors is the style distance Σ‖ΔG‖²_F.
    let net = nrw_style::Vgg::load(&weights).unwrap();
    let reader = nrw_dataset::reader::Dataset::open(&ds).unwrap();
    let g = |id: u32| {
        let img =
            nrw_style::descriptor::prepare(&reader.get(id).unwrap().photo().unwrap(), Some(128));
        nrw_style::grams(
            &net,
            &nrw_style::to_input(&img, nrw_style::Preprocess::Imagenet),
            128,
            128,
            nrw_style::Parallelism::None,
        )
    };
    let (ga, gb) = (g(rows[0].image_id), g(rows[1].image_id));
    let direct: f64 = ga
        .iter()
        .zip(&gb)
        .flat_map(|(a, b)| a.1.iter().zip(&b.1).map(|(x, y)| (x - y).powi(2)))
        .sum();
    let via = nrw_style::distance2(&rows[0].descriptor, &rows[1].descriptor);
    assert!((via - direct).abs() <= 1e-4 * direct, "{via} vs {direct}");
    // The official code's [-1, 1] scaling in dataset mode: recorded, refused as a mix with the
    // ImageNet descriptors, and what the network sees.
    let with = |pre: &'static str, overwrite: bool| {
        let mut a = vec![
            "style",
            d,
            "--tier",
            "vgg16-128",
            "--weights",
            w,
            "--quiet",
            "--preprocess",
            pre,
        ];
        if overwrite {
            a.push("--overwrite");
        }
        a
    };
    let err = fails(&with("minus-one-to-one", false));
    assert!(
        err.contains("MinusOneToOne") && err.contains("--overwrite"),
        "{err}"
    );
    ok(&with("minus-one-to-one", true));
    let (kind, rows) = nrw_dataset::descriptors::read_all(&nrw_dataset::Store::from(&ds))
        .unwrap()
        .unwrap();
    assert_eq!(kind.preprocess, "MinusOneToOne");
    let img = nrw_style::descriptor::prepare(
        &reader.get(rows[0].image_id).unwrap().photo().unwrap(),
        Some(128),
    );
    let g = nrw_style::grams(
        &net,
        &nrw_style::to_input(&img, nrw_style::Preprocess::MinusOneToOne),
        128,
        128,
        nrw_style::Parallelism::None,
    );
    let relu1_2 = &g[0].1;
    let worst = relu1_2.iter().fold(0f64, |m, v| m.max(v.abs()));
    assert!(
        (rows[0].descriptor[0] as f64 - relu1_2[0]).abs() <= 1e-5 * worst,
        "{} vs {}",
        rows[0].descriptor[0],
        relu1_2[0]
    );
}

#[test]
fn the_paper_pipeline_runs_its_stages_and_names_too_few_photos() {
    let Some(_) = shared::shared("data") else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    let pipelines = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../pipelines");
    let paper = pipelines.join("paper.toml");
    let weights = shared::shared_path("weights/vgg16_imagenet.safetensors");
    let weights = weights.to_str().unwrap();
    // The style stage's VGG tier needs weights: refused before any stage runs.
    let out = tmp.path().join("sceaux");
    let err = failed(&run_pipeline(&paper, "sceaux_castle", &out, &[]));
    assert!(
        err.contains("--weights") && err.contains("vgg16-512"),
        "{err}"
    );
    assert!(!out.exists(), "nothing ran");
    // sceaux_castle keeps its 11 views, then split asks for the paper's 100: a clear error.
    let err = failed(&run_pipeline(
        &paper,
        "sceaux_castle",
        &out,
        &["--weights", weights],
    ));
    assert!(err.contains("--val 100") && err.contains("11"), "{err}");
    assert!(
        out.join("shards").is_dir(),
        "ingest ran before split failed"
    );
    // The same stages with a small validation set run through to the export.
    let small = tmp.path().join("small.toml");
    std::fs::write(
        &small,
        std::fs::read_to_string(&paper)
            .unwrap()
            .replace("val = 100", "val = 2")
            .replace("min_dim = 600", "min_dim = 200")
            .replace("semantics = false", "semantics = false\ncrop = 192")
            .replace("\"vgg16-512\"", "\"color-stats\""),
    )
    .unwrap();
    let out = tmp.path().join("sceaux2");
    let o = run_pipeline(&small, "sceaux_castle", &out, &[]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    assert!(
        err.contains("k lowered from 20 to 8"),
        "9 training photos: {err}"
    );
    assert_eq!(
        std::fs::read_dir(out.join("export/val")).unwrap().count(),
        2 * 3
    );
    // Every stage ran: descriptors and triplets are listed, the report exists.
    let m = std::fs::read_to_string(out.join("manifest.json")).unwrap();
    assert!(
        m.contains("descriptors/part-00000.parquet") && m.contains("triplets.parquet"),
        "{m}"
    );
    assert!(out.join("qa/report.html").is_file());
    // sacre_coeur's sparse model keeps nothing: exit 3, later stages skipped. (The paper's
    // [densify] left out: with it, tests/densify.rs shows views kept.)
    let text = std::fs::read_to_string(&paper).unwrap();
    let sparse = tmp.path().join("sparse.toml");
    let (start, end) = (
        text.find("[densify]").unwrap(),
        text.find("[ingest]").unwrap(),
    );
    std::fs::write(&sparse, format!("{}{}", &text[..start], &text[end..])).unwrap();
    let o = run_pipeline(
        &sparse,
        "sacre_coeur",
        &tmp.path().join("sc"),
        &["--weights", weights],
    );
    assert_eq!(o.status.code(), Some(3));
    // A table of one setting runs with the paper's others (once refused with "missing field
    // `min_dim`"): sacre_coeur's sparse renders judged at 99% empty, rendered at the paper's
    // 600 px and filtered at its 450 px, whatever it then keeps (exit 0, or 3 for none).
    let one = tmp.path().join("one.toml");
    std::fs::write(&one, "name = 'one'\n[ingest]\nmax_empty = 0.99\n").unwrap();
    let out_one = tmp.path().join("one");
    let o = run_pipeline(&one, "sacre_coeur", &out_one, &[]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(matches!(o.status.code(), Some(0 | 3)), "{err}");
    let m: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out_one.join("manifest.json")).unwrap())
            .unwrap();
    let p = &m["parameters"];
    assert_eq!(
        (
            p["max_empty"].as_f64(),
            p["min_dim"].as_u64(),
            p["min_photo_side"].as_u64(),
            p["radius"].as_f64()
        ),
        (Some(0.99), Some(600), Some(450), Some(1.0)),
        "{p}"
    );
    // A typo in a pipeline is an error, not a silent default.
    std::fs::write(&small, "name = 'x'\n[ingest]\nmin_dimm = 600\n").unwrap();
    let err = failed(&run_pipeline(&small, "sceaux_castle", &out, &[]));
    assert!(
        err.contains("small.toml") && err.contains("min_dimm"),
        "{err}"
    );
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

/// The stderr of a command that must fail with a clean error exit (as [`fails`] checks).
fn failed(o: &Output) -> String {
    assert_eq!(o.status.code(), Some(1), "a clean error exit, not a crash");
    String::from_utf8_lossy(&o.stderr).into_owned()
}

#[test]
fn triplets_come_from_the_training_split_in_exact_order() {
    use arrow_array::{Array, ListArray, UInt32Array};
    let tmp = tempfile::tempdir().unwrap();
    let ds = small_dataset(tmp.path(), 9, false);
    let d = ds.to_str().unwrap();
    let err = fails(&["triplets", d, "--k", "3"]);
    assert!(err.contains("run `nrw-etl style"), "{err}");
    ok(&["split", d, "--val", "2", "--seed", "4"]);
    ok(&["style", d, "--tier", "color-stats", "--quiet"]);
    let err = fails(&["triplets", d, "--k", "7"]);
    assert!(
        err.contains("--k 7 needs at least 8 photos in scope train, found 7")
            && err.contains("--k 6"),
        "{err}"
    );
    ok(&["triplets", d, "--k", "6"]);
    let val: Vec<u32> = nrw_dataset::split::read_splits(&nrw_dataset::Store::from(&ds))
        .unwrap()
        .iter()
        .filter(|a| a.split == "val")
        .map(|a| a.image_id)
        .collect();
    let (_, desc) = nrw_dataset::descriptors::read_all(&nrw_dataset::Store::from(&ds))
        .unwrap()
        .unwrap();
    let by_id: std::collections::BTreeMap<u32, Vec<f32>> = desc
        .into_iter()
        .map(|r| (r.image_id, r.descriptor))
        .collect();
    let batches = nrw_dataset::parquet_io::read_batches(
        &nrw_dataset::Store::from(&ds),
        "triplets.parquet",
        None,
    )
    .unwrap();
    let mut anchors = 0;
    for b in &batches {
        let a = column::<UInt32Array>(b, "anchor_id");
        let near = column::<ListArray>(b, "nearest_ids");
        let far = column::<ListArray>(b, "furthest_ids");
        for i in 0..b.num_rows() {
            anchors += 1;
            let anchor = a.value(i);
            let ids = |l: &ListArray| {
                l.value(i)
                    .as_any()
                    .downcast_ref::<UInt32Array>()
                    .unwrap()
                    .values()
                    .to_vec()
            };
            let (n, f) = (ids(near), ids(far));
            assert!(
                !val.contains(&anchor)
                    && n.iter().chain(&f).all(|x| !val.contains(x) && *x != anchor),
                "validation photos never appear"
            );
            // Independent check: a naive f64 sort of the training photos by distance.
            let mut all: Vec<(f64, u32)> = by_id
                .iter()
                .filter(|(id, _)| **id != anchor && !val.contains(id))
                .map(|(id, v)| {
                    let d: f64 = by_id[&anchor]
                        .iter()
                        .zip(v)
                        .map(|(x, y)| (*x as f64 - *y as f64).powi(2))
                        .sum();
                    (d, *id)
                })
                .collect();
            all.sort_by(|x, y| x.0.total_cmp(&y.0).then(x.1.cmp(&y.1)));
            assert_eq!(n, all.iter().take(6).map(|p| p.1).collect::<Vec<_>>());
            all.sort_by(|x, y| y.0.total_cmp(&x.0).then(x.1.cmp(&y.1)));
            assert_eq!(f, all.iter().take(6).map(|p| p.1).collect::<Vec<_>>());
        }
    }
    assert_eq!(anchors, 7);
    // And numpy's own all-pairs distances over the Parquet files, none of our code.
    if python::python_has("import numpy, pyarrow") {
        let oracle =
            Path::new(env!("CARGO_MANIFEST_DIR")).join("../../tests/oracles/triplets_oracle.py");
        let o = Command::new("python3")
            .args([oracle.to_str().unwrap(), d, "6"])
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    }
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(ds.join("manifest.json")).unwrap()).unwrap();
    assert!(v["tables"]
        .as_array()
        .unwrap()
        .iter()
        .any(|t| t["path"] == "triplets.parquet"));
}

#[test]
fn approximate_triplets_store_their_measured_recall() {
    use arrow_array::{Float64Array, StringArray};
    let tmp = tempfile::tempdir().unwrap();
    let ds = small_dataset(tmp.path(), 8, false);
    let d = ds.to_str().unwrap();
    ok(&["split", d, "--val", "0"]);
    ok(&["style", d, "--tier", "color-stats", "--quiet"]);
    ok(&["triplets", d, "--k", "3", "--pca", "9"]);
    let b = &nrw_dataset::parquet_io::read_batches(
        &nrw_dataset::Store::from(&ds),
        "triplets.parquet",
        None,
    )
    .unwrap()[0];
    assert_eq!(column::<StringArray>(b, "method").value(0), "pca-9");
    // PCA to the full 9 dimensions loses nothing: recall is exactly 1 and was stored.
    assert_eq!(column::<Float64Array>(b, "recall_nearest").value(0), 1.0);
    assert_eq!(column::<Float64Array>(b, "recall_furthest").value(0), 1.0);
    ok(&["triplets", d, "--k", "3"]);
    let b = &nrw_dataset::parquet_io::read_batches(
        &nrw_dataset::Store::from(&ds),
        "triplets.parquet",
        None,
    )
    .unwrap()[0];
    assert_eq!(column::<StringArray>(b, "method").value(0), "exact");
    assert!(arrow_array::Array::is_null(
        column::<Float64Array>(b, "recall_nearest"),
        0
    ));
}

/// A hard-case scene from scenes/, at test size.
fn hard_case(tmp: &Path, name: &str) -> PathBuf {
    let text = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join(format!("../../scenes/{name}.toml")),
    )
    .unwrap();
    let spec = nrw_synth::SceneSpec::from_toml(&text, name).unwrap();
    let photos = spec.cameras.count.min(5);
    let points = spec.geometry.points.min(60_000);
    let mut spec = spec.shrunk(photos, (120, 150), points);
    spec.observations.features = 300;
    let scene = tmp.join(name);
    nrw_synth::generate(&spec, &scene, &|| {}).unwrap();
    scene
}

#[test]
fn hard_case_scenes_go_through_every_later_stage() {
    let tmp = tempfile::tempdir().unwrap();
    for name in ["utm", "fisheye", "one_photo", "sparse_views"] {
        let scene = hard_case(tmp.path(), name);
        let ds = tmp.path().join(format!("{name}_ds"));
        let d = ds.to_str().unwrap();
        let o = nrw(&[
            "ingest",
            scene.to_str().unwrap(),
            "--out",
            d,
            "--min-photo-side",
            "100",
            "--min-dim",
            "96",
            "--quiet",
            "--json",
        ]);
        let kept = serde_json::from_slice::<serde_json::Value>(&o.stdout).unwrap()["kept"]
            .as_u64()
            .unwrap() as usize;
        match name {
            // Every view far more than 85% empty: exit 3, and the later stages say why they stop.
            "sparse_views" => {
                assert_eq!((o.status.code(), kept), (Some(3), 0));
                ok(&["split", d, "--val", "0"]);
                for args in [
                    vec!["triplets", d, "--k", "1"],
                    vec!["export", d, "--out", tmp.path().join("x").to_str().unwrap()],
                ] {
                    let err = fails(&args);
                    assert!(
                        err.contains("no kept view") && err.contains("dropped all"),
                        "{err}"
                    );
                }
                continue;
            }
            _ => assert!(
                o.status.success() && kept >= 1,
                "{name}: {}",
                String::from_utf8_lossy(&o.stderr)
            ),
        }
        ok(&["split", d, "--val", if kept > 2 { "1" } else { "0" }]);
        ok(&["style", d, "--tier", "color-stats", "--quiet"]);
        let train = nrw_dataset::split::read_splits(&nrw_dataset::Store::from(&ds))
            .unwrap()
            .iter()
            .filter(|a| a.split == "train")
            .count();
        if train >= 2 {
            ok(&["triplets", d, "--k", "1"]);
        } else {
            // One photo: no neighbour exists; the error says how many are needed.
            let err = fails(&["triplets", d, "--k", "1"]);
            assert!(
                err.contains("needs at least 2 photos") && err.contains("found 1"),
                "{name}: {err}"
            );
        }
        let out = tmp.path().join(format!("{name}_export"));
        ok(&[
            "export",
            d,
            "--out",
            out.to_str().unwrap(),
            "--no-semantics",
            "--crop",
            "none",
        ]);
        let exported = walk(&out)
            .iter()
            .filter(|p| p.to_string_lossy().ends_with("_reference.png"))
            .count();
        assert_eq!(exported, kept, "{name}");
        // The georeferenced scene's shards carry its far-away poses in full precision.
        if name == "utm" {
            let v = nrw_dataset::reader::Dataset::open(&ds).unwrap();
            let first = v.iter_split("train").unwrap().next().unwrap().unwrap();
            let c = nrw_colmap::Rigid3::from_colmap(first.qvec, first.tvec)
                .unwrap()
                .0
                .centre();
            assert!(c.x > 4.9e6 && c.y > 4.9e6, "{c:?}");
        }
    }
}

#[test]
fn the_generator_works_with_every_camera_model() {
    let tmp = tempfile::tempdir().unwrap();
    for model in nrw_colmap::CameraModel::ALL {
        let mut spec = nrw_synth::SceneSpec::demo().shrunk(3, (120, 160), 3000);
        spec.cameras.model = model.name().into();
        spec.observations.features = 1500;
        spec.effects = Default::default();
        let scene = tmp.path().join(model.name());
        let report = nrw_synth::generate(&spec, &scene, &|| {}).unwrap();
        let v: serde_json::Value =
            serde_json::from_str(&ok(&["inspect", scene.to_str().unwrap(), "--json"])).unwrap();
        assert_eq!(v["camera_models"][0], model.name());
        let mean = report
            .mean_reprojection_error_px
            .unwrap_or_else(|| panic!("{}: no 3D point to compare", model.name()));
        assert!(
            report.sparse_points > 20,
            "{}: {} points",
            model.name(),
            report.sparse_points
        );
        let got = v["mean_reprojection_error_px"].as_f64().unwrap();
        assert!(
            (got - mean).abs() < 1e-9,
            "{}: inspect {got} vs generator {mean}",
            model.name()
        );
    }
}

/// qa.json's counts, recomputed from the tables with the Arrow reader (not polars).
fn independent_counts(ds: &Path) -> (usize, usize, usize, usize, usize, usize) {
    let v = nrw_dataset::scene::read_verdicts(&nrw_dataset::Store::from(ds)).unwrap();
    let kept = v.iter().filter(|r| r.2 == "kept").count();
    let small = v.iter().filter(|r| r.2 == "too_small").count();
    let sparse = v.iter().filter(|r| r.2 == "too_sparse").count();
    let splits = if ds.join("splits.parquet").is_file() {
        nrw_dataset::split::read_splits(&nrw_dataset::Store::from(ds)).unwrap()
    } else {
        Vec::new()
    };
    let train = splits.iter().filter(|a| a.split == "train").count();
    let val = splits.iter().filter(|a| a.split == "val").count();
    (v.len(), kept, small, sparse, train, val)
}

fn qa_json(ds: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(ds.join("qa/qa.json")).unwrap()).unwrap()
}

#[test]
fn qa_report_figures_equal_the_tables_at_every_stage() {
    let tmp = tempfile::tempdir().unwrap();
    let scene = tmp.path().join("scene");
    let spec = nrw_synth::SceneSpec::demo().shrunk(14, (120, 150), 60_000);
    nrw_synth::generate(&spec, &scene, &|| {}).unwrap();
    let ds = tmp.path().join("ds");
    let d = ds.to_str().unwrap();
    // A size filter inside the drawn range drops some photos as too small.
    ok(&[
        "ingest",
        scene.to_str().unwrap(),
        "--out",
        d,
        "--min-photo-side",
        "125",
        "--min-dim",
        "96",
        "--quiet",
    ]);
    let check = |stage: &str| {
        let out = ok(&["qa", d]);
        assert_eq!(out.trim(), ds.join("qa/report.html").to_str().unwrap());
        let q = qa_json(&ds);
        let (n, kept, small, sparse, train, val) = independent_counts(&ds);
        let c = &q["counts"];
        assert_eq!(c["registered"], n, "{stage}");
        assert_eq!(c["kept"], kept, "{stage}");
        assert_eq!(c["rendered"], n - small, "{stage}");
        assert_eq!(c["shard_rows"], kept, "{stage}");
        assert_eq!(c["train"], train, "{stage}");
        assert_eq!(c["val"], val, "{stage}");
        assert_eq!(
            q["drops"]["too_small"].as_u64().unwrap_or(0) as usize,
            small
        );
        assert_eq!(
            q["drops"]["too_sparse"].as_u64().unwrap_or(0) as usize,
            sparse
        );
        assert!(
            small > 0 && kept > 5,
            "the scene exercises drops: {small} small, {kept} kept"
        );
        let html = std::fs::read_to_string(ds.join("qa/report.html")).unwrap();
        // Self-contained: every image is a data URI, charts are inline SVG.
        let imgs = html.matches("<img ").count();
        assert_eq!(
            imgs,
            html.matches("<img src=\"data:image/jpeg;base64,").count()
        );
        assert!(html.matches("<svg").count() >= 4, "{stage}: charts");
        (q, html, imgs)
    };
    // Right after ingest: no split, no triplets yet.
    let (q, html, imgs) = check("ingest");
    assert!(q["triplets"].is_null());
    assert!(html.contains("No triplets yet") && html.contains("Not split yet"));
    // Contact sheet: 4 images per sampled kept view, dropped-photo thumbnails from the scene.
    assert!(imgs >= 4 * 6, "{imgs} images");
    assert!(q["timings"]["ingest"].as_f64().unwrap() > 0.0);
    ok(&["split", d, "--val", "3", "--seed", "5"]);
    ok(&["style", d, "--tier", "color-stats", "--quiet"]);
    ok(&["triplets", d, "--k", "3"]);
    let (q, html, _) = check("triplets");
    assert_eq!(q["counts"]["val"], 3);
    assert_eq!(q["triplets"]["k"], 3);
    assert_eq!(q["counts"]["descriptors"], q["counts"]["kept"]);
    // 3 val photos: the report says the validation set is small.
    let kinds: Vec<&str> = q["warnings"]
        .as_array()
        .unwrap()
        .iter()
        .map(|w| w["kind"].as_str().unwrap())
        .collect();
    assert!(kinds.contains(&"small_validation_set"), "{kinds:?}");
    // The synthetic scene's true appearances colour the descriptor map.
    assert!(html.contains("by true appearance") && html.contains("anchor "));
}

#[test]
fn qa_report_of_a_dataset_where_every_view_was_dropped() {
    let Some(_) = shared::shared("data") else {
        return;
    };
    let out = tempfile::tempdir().unwrap();
    let d = out.path().to_str().unwrap();
    let o = nrw(&[
        "ingest",
        data().join("sacre_coeur").to_str().unwrap(),
        "--out",
        d,
    ]);
    assert_eq!(o.status.code(), Some(3));
    ok(&["qa", d]);
    let q = qa_json(out.path());
    assert_eq!(q["counts"]["registered"], 10);
    assert_eq!(q["counts"]["kept"], 0);
    assert_eq!(q["drops"]["too_sparse"], 10);
    assert!(q["warnings"]
        .as_array()
        .unwrap()
        .iter()
        .any(|w| w["kind"] == "nothing_kept"));
    let html = std::fs::read_to_string(out.path().join("qa/report.html")).unwrap();
    // The dropped photos are shown with the value that dropped them.
    assert!(
        html.contains("% empty)") && html.contains("No kept views to show"),
        "report"
    );
}

/// Headless Chromium renders the report with no console error and every image decoded. Needs
/// Debian's `chromium` (installed by .ci/run); skipped elsewhere unless NRW_REQUIRE_CHROMIUM=1.
/// NRW_QA_SCREENSHOT=FILE keeps a screenshot to look at.
#[test]
fn qa_report_renders_in_headless_chromium() {
    let chromium = Path::new("/usr/bin/chromium");
    if !chromium.exists() {
        assert!(
            std::env::var("NRW_REQUIRE_CHROMIUM").map_or(true, |v| v != "1"),
            "NRW_REQUIRE_CHROMIUM=1 but /usr/bin/chromium is missing"
        );
        eprintln!("skipped: no /usr/bin/chromium");
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let demo = tmp.path().join("demo");
    let out = ok(&["demo", "--out", demo.to_str().unwrap()]);
    let report = demo.join("dataset/qa/report.html");
    assert!(
        out.contains(report.to_str().unwrap()),
        "demo prints the report: {out}"
    );
    let shot = std::env::var("NRW_QA_SCREENSHOT")
        .map(PathBuf::from)
        .unwrap_or_else(|_| tmp.path().join("shot.png"));
    let profile = tmp.path().join("profile");
    let run = |extra: &[&str]| {
        let o = std::process::Command::new(chromium)
            .args([
                "--headless",
                "--no-sandbox",
                "--disable-gpu",
                "--disable-quic",
                "--no-first-run",
                "--disable-background-networking",
                "--disable-component-update",
                "--disable-sync",
                "--enable-logging=stderr",
                "--v=0",
                "--virtual-time-budget=5000",
                "--window-size=1200,5000",
            ])
            .arg(format!("--user-data-dir={}", profile.display()))
            .args(extra)
            .arg(format!("file://{}", report.display()))
            .output()
            .unwrap();
        (
            String::from_utf8_lossy(&o.stdout).to_string(),
            String::from_utf8_lossy(&o.stderr).to_string(),
        )
    };
    let (dom, log) = run(&["--dump-dom"]);
    assert!(
        dom.contains("data-qa-images=\"ok\""),
        "images failed to load:\n{log}"
    );
    let count: usize = dom
        .split("data-qa-image-count=\"")
        .nth(1)
        .and_then(|s| s.split('"').next())
        .and_then(|s| s.parse().ok())
        .unwrap_or(0);
    assert!(count >= 24, "{count} images in the page");
    let console: Vec<&str> = log
        .lines()
        .filter(|l| l.contains("CONSOLE") || l.contains("Uncaught"))
        .collect();
    assert!(console.is_empty(), "console messages: {console:?}");
    let (_, log) = run(&[&format!("--screenshot={}", shot.display())]);
    let png = std::fs::read(&shot).unwrap_or_else(|e| panic!("no screenshot ({e}):\n{log}"));
    assert!(
        png.starts_with(b"\x89PNG") && png.len() > 50_000,
        "screenshot"
    );
}

/// A synthetic dataset ready for training: ingested, split, described (colour statistics) and
/// with triplets of `k` neighbours.
fn trainable_dataset(tmp: &Path, photos: usize, k: usize) -> PathBuf {
    let ds = small_dataset(tmp, photos, true);
    let d = ds.to_str().unwrap();
    ok(&["split", d, "--val", "2", "--seed", "3"]);
    ok(&["style", d, "--tier", "color-stats", "--quiet"]);
    ok(&["triplets", d, "--k", &k.to_string()]);
    ds
}

#[test]
fn trainer_loader_crops_align_cover_every_row_once_repeat_under_a_seed_and_stay_bounded() {
    use nrw_trainer::{Loader, LoaderConfig};
    let tmp = tempfile::tempdir().unwrap();
    let ds_dir = small_dataset(tmp.path(), 9, true);
    ok(&["split", ds_dir.to_str().unwrap(), "--val", "2"]);
    let ds = nrw_dataset::reader::Dataset::open(&ds_dir).unwrap();
    let cfg = LoaderConfig {
        crop: 48,
        batch: 3,
        seed: 7,
        semantics: true,
    };
    let loader = Loader::new(&ds, "train", cfg.clone()).unwrap();
    let batches: Vec<_> = loader.epoch(0).map(|b| b.unwrap()).collect();
    // The epoch covers each row of the split exactly once.
    let mut seen: Vec<u32> = batches.iter().flat_map(|b| b.ids.clone()).collect();
    seen.sort_unstable();
    assert_eq!(seen, ds.ids("train").unwrap());
    // Every channel of a crop is the same window of its view (photo, render, depth, semantics).
    let scale = nrw_dataset::scene::read_depth_max(&nrw_dataset::Store::from(&ds_dir))
        .unwrap()
        .unwrap() as f32;
    let s = 48usize;
    for b in &batches {
        for (k, (&id, &(x, y))) in b.ids.iter().zip(&b.offsets).enumerate() {
            let v = ds.get(id).unwrap();
            let (photo, color, depth) =
                (v.photo().unwrap(), v.color().unwrap(), v.depth().unwrap());
            let sem = v.semantics().unwrap().unwrap();
            for j in 0..s {
                for i in 0..s {
                    let (px, py) = (x + i as u32, y + j as u32);
                    let at = |c: usize| b.photo[((k * 3 + c) * s + j) * s + i];
                    let p = photo.get_pixel(px, py);
                    assert_eq!(at(0), p[0] as f32 / 127.5 - 1.0);
                    assert_eq!(at(2), p[2] as f32 / 127.5 - 1.0);
                    let c = color.get_pixel(px, py);
                    let r = b.color[((k * 3 + 1) * s + j) * s + i];
                    let z = b.depth[(k * s + j) * s + i];
                    let dz = depth.data[py as usize * depth.width + px as usize];
                    assert_eq!(z, if dz > 0.0 { (dz / scale).min(1.0) } else { 0.0 });
                    // Known alignment of synthetic renders: drawn colour ⇔ depth, same pixel.
                    assert_eq!(c[3] > 0, z > 0.0, "view {id} at ({px}, {py})");
                    assert_eq!(
                        r,
                        if c[3] > 0 {
                            c[1] as f32 / 127.5 - 1.0
                        } else {
                            -1.0
                        }
                    );
                    let m = b.semantics.as_ref().unwrap()[((k * 3) * s + j) * s + i];
                    assert_eq!(m, sem.get_pixel(px, py)[0] as f32 / 127.5 - 1.0);
                }
            }
        }
    }
    // Deterministic under a seed; another seed draws other crops.
    let again: Vec<_> = Loader::new(&ds, "train", cfg.clone())
        .unwrap()
        .epoch(0)
        .map(|b| b.unwrap())
        .collect();
    for (a, b) in batches.iter().zip(&again) {
        assert_eq!(
            (&a.ids, &a.offsets, &a.photo),
            (&b.ids, &b.offsets, &b.photo)
        );
    }
    let other: Vec<_> = Loader::new(&ds, "train", LoaderConfig { seed: 8, ..cfg })
        .unwrap()
        .epoch(0)
        .map(|b| b.unwrap())
        .collect();
    assert!(batches
        .iter()
        .zip(&other)
        .any(|(a, b)| a.ids != b.ids || a.offsets != b.offsets));
    // Bounded memory: never more decoded views alive than one batch.
    assert!(loader.peak_in_flight() <= 3, "{}", loader.peak_in_flight());
    // A crop larger than the views is a clear error naming the view.
    let big = Loader::new(
        &ds,
        "train",
        LoaderConfig {
            crop: 4000,
            batch: 2,
            seed: 0,
            semantics: false,
        },
    )
    .unwrap();
    let err = big.epoch(0).next().unwrap().unwrap_err().to_string();
    assert!(err.contains("does not fit"), "{err}");
}

#[test]
fn trainer_lowers_the_loss_beats_chance_on_held_out_triplets_and_resumes_exactly() {
    use nrw_trainer::{train, TrainConfig};
    let tmp = tempfile::tempdir().unwrap();
    let ds_dir = trainable_dataset(tmp.path(), 26, 8);
    let ds = nrw_dataset::reader::Dataset::open(&ds_dir).unwrap();
    let cfg = TrainConfig {
        steps: 60,
        batch: 8,
        crop: 32,
        lr: 3e-3,
        pos_k: 3,
        neg_k: 5,
        checkpoint_every: 20,
        // At the default 0.1 most of these triplets start inside the margin (per-step loss
        // mostly 0, a few spikes), so "the loss falls" would be decided by where the spikes
        // land; at 1.0 the first steps' loss is substantial and its fall is the property.
        margin: 1.0,
        ..TrainConfig::default()
    };
    let whole = tmp.path().join("whole");
    let r = train(&ds, "train", &cfg, &whole, &mut |_, _| {}).unwrap();
    let mean = |v: &[(u64, f64)]| v.iter().map(|p| p.1).sum::<f64>() / v.len() as f64;
    let (first, last) = (mean(&r.losses[..15]), mean(&r.losses[45..]));
    eprintln!(
        "accuracy {} → {}, class {:?}",
        r.accuracy_before, r.accuracy_after, r.class_agreement
    );
    assert!(last < first * 0.8, "loss {first} → {last}");
    assert!(r.held_out_triplets > 0);
    assert!(
        r.accuracy_after > 0.5 && r.accuracy_after >= r.accuracy_before,
        "held-out accuracy {} → {}",
        r.accuracy_before,
        r.accuracy_after
    );
    // Interrupted after 20 steps, then resumed: the same losses as the uninterrupted run.
    let part = tmp.path().join("part");
    train(
        &ds,
        "train",
        &TrainConfig {
            steps: 20,
            ..cfg.clone()
        },
        &part,
        &mut |_, _| {},
    )
    .unwrap();
    let resumed = train(&ds, "train", &cfg, &part, &mut |_, _| {}).unwrap();
    assert_eq!(resumed.resumed_from, Some(20));
    for (a, b) in r.losses.iter().zip(&resumed.losses) {
        assert_eq!(a.0, b.0);
        assert!(
            (a.1 - b.1).abs() <= 1e-5 * a.1.abs().max(1e-6),
            "step {}: {} vs {}",
            a.0,
            a.1,
            b.1
        );
    }
    // A setting out of range is named as its config field (nrw-train maps it to --pos-k).
    for (pos_k, neg_k, setting) in [(0, 1, "pos_k"), (1, 1_000, "neg_k")] {
        let e = train(
            &ds,
            "train",
            &TrainConfig {
                pos_k,
                neg_k,
                ..cfg.clone()
            },
            &tmp.path().join("bad-k"),
            &mut |_, _| {},
        )
        .unwrap_err();
        assert!(
            matches!(&e, nrw_trainer::TrainError::Setting { setting: s, .. } if *s == setting),
            "{e}"
        );
        assert!(e.to_string().contains("per anchor"), "{e}");
    }
    // Other settings in the same folder are refused, not mixed.
    let err = train(
        &ds,
        "train",
        &TrainConfig { lr: 1e-2, ..cfg },
        &part,
        &mut |_, _| {},
    )
    .unwrap_err()
    .to_string();
    assert!(err.contains("other settings"), "{err}");
}
