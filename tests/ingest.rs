//! `ingest`: the scene tables and manifest, resumption, the filters' verdicts, the shards' payloads read back by other readers, the point source and semantics.

use super::*;

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
    // Ingest writes FilterVerdict::name(); QA, split and the trainer compare with VERDICT_KEPT.
    let kept = nrw_render::FilterVerdict::Kept { empty_ratio: 0.5 };
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

/// `scene` rewritten as two sub-models: `sparse/0` keeps the first `small` images (and the
/// observations among them), `sparse/1` the whole model, as COLMAP's mapper leaves a
/// collection it could not connect.
fn two_sub_models(scene: &Path, small: usize) -> (usize, usize) {
    let full = nrw_colmap::read_scene(scene).unwrap();
    let format = full.format.unwrap();
    let big = scene.join("sparse/1");
    std::fs::create_dir_all(&big).unwrap();
    nrw_colmap::write_model(&full, &big, format).unwrap();
    let mut part = full.clone();
    let keep: Vec<u32> = part.images.keys().copied().take(small).collect();
    part.images.retain(|id, _| keep.contains(id));
    for p in part.points.values_mut() {
        p.track.retain(|t| keep.contains(&t.image_id));
    }
    part.points.retain(|_, p| p.track.len() >= 2);
    let kept: std::collections::BTreeSet<u64> = part.points.keys().copied().collect();
    for img in part.images.values_mut() {
        for kp in &mut img.points2d {
            if kp.has_point3d() && !kept.contains(&kp.point3d_id) {
                kp.point3d_id = nrw_colmap::model::NO_POINT3D;
            }
        }
    }
    nrw_colmap::write_model(&part, &scene.join("sparse/0"), format).unwrap();
    (part.images.len(), full.images.len())
}

#[test]
fn a_scene_with_two_sub_models_gives_the_larger_and_says_so() {
    let tmp = tempfile::tempdir().unwrap();
    let scene = tmp.path().join("scene");
    small_scene(&scene, 5);
    let (small, large) = two_sub_models(&scene, 2);
    assert_eq!((small, large), (2, 5));
    let sc = scene.to_str().unwrap();

    // inspect lists both, side by side, and says which it summarises.
    let listed = ok(&["inspect", sc]);
    eprintln!("{listed}");
    assert!(
        listed.contains("sparse/0") && listed.contains("sparse/1"),
        "{listed}"
    );
    assert!(listed.contains("images       5"), "{listed}");
    let json: serde_json::Value = serde_json::from_str(&ok(&["inspect", sc, "--json"])).unwrap();
    let subs = json["sub_models"].as_array().unwrap();
    let images: Vec<u64> = subs.iter().map(|m| m["images"].as_u64().unwrap()).collect();
    assert_eq!(images, [2, 5]);
    assert!(
        subs.iter().all(|m| m["points"].as_u64().unwrap() > 0),
        "{json}"
    );

    // ingest takes sparse/1 and says which and why.
    let out = tmp.path().join("ds");
    let o = ingest_small(&scene, &out, &["--max-empty", "1.0"]);
    let said = String::from_utf8_lossy(&o.stderr).to_string() + &String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "{said}");
    eprintln!("{said}");
    assert!(
        said.contains("took")
            && said.contains("sparse/1")
            && said.contains("most registered images"),
        "{said}"
    );
    let verdicts = nrw_dataset::scene::read_verdicts(
        &nrw_dataset::Store::open(&nrw_dataset::Location::Local(out.clone())).unwrap(),
    )
    .unwrap();
    assert_eq!(verdicts.len(), 5);

    // --model 0 takes the other; a sub-model the scene does not have is named.
    let out0 = tmp.path().join("ds0");
    let o = ingest_small(&scene, &out0, &["--max-empty", "1.0", "--model", "0"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let verdicts = nrw_dataset::scene::read_verdicts(
        &nrw_dataset::Store::open(&nrw_dataset::Location::Local(out0)).unwrap(),
    )
    .unwrap();
    assert_eq!(verdicts.len(), 2);
    let err = fails(&[
        "ingest",
        sc,
        "--out",
        tmp.path().join("ds7").to_str().unwrap(),
        "--model",
        "7",
    ]);
    assert!(
        err.contains("sparse/7") && err.contains("sparse/0, sparse/1"),
        "{err}"
    );
}

#[test]
fn sub_models_of_equal_size_go_to_the_lowest_number() {
    let tmp = tempfile::tempdir().unwrap();
    let scene = tmp.path().join("scene");
    small_scene(&scene, 3);
    // sparse/0 keeps every image: both sub-models register 3.
    assert_eq!(two_sub_models(&scene, 3), (3, 3));
    let json: serde_json::Value =
        serde_json::from_str(&ok(&["inspect", scene.to_str().unwrap(), "--json"])).unwrap();
    let chosen = json["chosen"].as_str().unwrap();
    assert!(
        json["model_dir"].as_str().unwrap().ends_with("sparse/0"),
        "{json}"
    );
    assert!(
        chosen.contains("sparse/0: 3 images, sparse/1: 3 images"),
        "{chosen}"
    );
}
