//! `ingest --undistort` on ../shared/data/sacre_coeur, whose dense/ folder is COLMAP 3.8's
//! `image_undistorter` output: the dataset's cameras are dense/sparse's PINHOLE cameras, every
//! view is stored with the pinhole camera, and its photo is dense/images at the render size.

use arrow_array::{Array, Float64Array, ListArray, StringArray, UInt32Array};
use nrw_dataset::reader::Dataset;
use parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder;
use std::path::{Path, PathBuf};

use super::{assert_same_files, column, data, fails, files, nrw, ok, shared};

#[test]
fn ingest_undistort_stores_colmaps_pinhole_cameras_and_photos() {
    let Some(_) = shared::shared("data") else {
        return;
    };
    let scene = data().join("sacre_coeur");
    let dense = nrw_colmap::read_model(&scene.join("dense/sparse"), None).unwrap();
    let out = tempfile::tempdir().unwrap();
    // Sparse points leave these renders ~98% empty: keep every view to compare them all.
    ok(&[
        "ingest",
        scene.to_str().unwrap(),
        "--out",
        out.path().to_str().unwrap(),
        "--undistort",
        "--max-empty",
        "1",
        "--quiet",
    ]);
    let f = std::fs::File::open(out.path().join("scene/cameras.parquet")).unwrap();
    let mut cameras = 0;
    for b in ParquetRecordBatchReaderBuilder::try_new(f)
        .unwrap()
        .build()
        .unwrap()
    {
        let b = b.unwrap();
        let ids = column::<UInt32Array>(&b, "camera_id");
        let models = column::<StringArray>(&b, "model");
        let (ws, hs) = (
            column::<UInt32Array>(&b, "width"),
            column::<UInt32Array>(&b, "height"),
        );
        let params = column::<ListArray>(&b, "params");
        for i in 0..b.num_rows() {
            let want = &dense.cameras[&ids.value(i)];
            assert_eq!(models.value(i), "PINHOLE");
            assert_eq!(
                (ws.value(i) as u64, hs.value(i) as u64),
                (want.width, want.height)
            );
            let p = params.value(i);
            let p = p.as_any().downcast_ref::<Float64Array>().unwrap();
            for (k, v) in want.params.iter().enumerate() {
                assert!(
                    (p.value(k) - v).abs() < 1e-6,
                    "camera {}: {} vs {v}",
                    ids.value(i),
                    p.value(k)
                );
            }
            cameras += 1;
        }
    }
    assert_eq!(cameras, 10);
    let ds = Dataset::open(out.path()).unwrap();
    let ids = ds.ids("all").unwrap().to_vec();
    assert_eq!(ids.len(), 10, "every view kept");
    let (mut sum, mut n) = (0u64, 0u64);
    for id in ids {
        let v = ds.get(id).unwrap();
        assert_eq!(v.model, "PINHOLE", "{}", v.name);
        let cam = &dense.cameras[&v.camera_id];
        let (sx, sy) = (v.scale_x, v.scale_y);
        let scaled = [
            cam.params[0] * sx,
            cam.params[1] * sy,
            cam.params[2] * sx,
            cam.params[3] * sy,
        ];
        for (a, b) in v.params.iter().zip(scaled) {
            assert!(
                (a - b).abs() < 1e-6 * b.abs(),
                "{}: {:?} vs {scaled:?}",
                v.name,
                v.params
            );
        }
        let colmap = image::open(scene.join("dense/images").join(&v.name))
            .unwrap()
            .to_rgb8();
        let colmap = nrw_dataset::codec::resize_photo(&colmap, v.width, v.height);
        let ours = v.photo().unwrap();
        for (a, b) in ours.as_raw().iter().zip(colmap.as_raw()) {
            sum += (*a as i32 - *b as i32).unsigned_abs() as u64;
            n += 1;
        }
    }
    let mad = sum as f64 / n as f64;
    eprintln!("stored photos against dense/images at the render size: mean absolute difference {mad:.3} levels");
    assert!(mad < 1.5, "{mad}");
}

#[test]
fn undistorts_options_are_refused_without_it() {
    let Some(_) = shared::shared("data") else {
        return;
    };
    let scene = data().join("sacre_coeur");
    let out = tempfile::tempdir().unwrap();
    // Usage errors (clap's exit status 2), named by flag.
    let usage = |args: &[&str]| {
        let o = nrw(args);
        assert_eq!(o.status.code(), Some(2), "{args:?}");
        String::from_utf8(o.stderr).unwrap()
    };
    let err = usage(&[
        "ingest",
        scene.to_str().unwrap(),
        "--out",
        out.path().to_str().unwrap(),
        "--blank-pixels",
        "0.5",
    ]);
    assert!(err.contains("--undistort"), "{err}");
}

#[test]
fn undistorted_units_and_finalize_write_the_bytes_of_one_process() {
    let Some(_) = shared::shared("data") else {
        return;
    };
    let scene = data().join("sacre_coeur");
    let tmp = tempfile::tempdir().unwrap();
    let run = |out: &std::path::Path, shard: Option<&str>| {
        let mut a = vec![
            "ingest",
            scene.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            "--undistort",
            "--max-empty",
            "1",
            "--min-dim",
            "200",
            "--rows-per-shard",
            "4",
            "--quiet",
        ];
        if let Some(s) = shard {
            a.extend(["--unit", s]);
        }
        ok(&a);
    };
    let whole = tmp.path().join("whole");
    run(&whole, None);
    let units = tmp.path().join("units");
    run(&units, Some("1/2"));
    run(&units, Some("0/2"));
    ok(&["finalize", units.to_str().unwrap()]);
    assert_same_files(
        &files(&whole),
        &files(&units),
        "undistorted: 2 units + finalize",
    );
    // The manifest says how the views were undistorted.
    let m: serde_json::Value =
        serde_json::from_slice(&std::fs::read(whole.join("manifest.json")).unwrap()).unwrap();
    assert_eq!(m["parameters"]["undistort"]["blank_pixels"], 0.0, "{m}");
}

/// Ingest's flags that keep every view of a small synthetic scene, stored at a shorter side
/// of 150 px.
pub(crate) const SMALL_VIEWS: [&str; 6] = [
    "--min-photo-side",
    "100",
    "--min-dim",
    "150",
    "--max-empty",
    "1.0",
];

/// A synthetic scene in DIR/scene of `photos` photos (220–260 px) taken through a `model`
/// lens at `distortion` times its default coefficients, with people where `people`.
pub(crate) fn lens_scene(
    dir: &Path,
    photos: usize,
    model: &str,
    distortion: f64,
    people: bool,
) -> PathBuf {
    let scene = dir.join("scene");
    let mut spec = nrw_synth::SceneSpec::demo().shrunk(photos, (220, 260), 60_000);
    spec.cameras.model = model.into();
    spec.cameras.distortion = distortion;
    if people {
        spec.effects.transients = Some(6.0);
    }
    nrw_synth::generate(&spec, &scene, &|| {}).unwrap();
    scene
}

/// Scenes of each camera model COLMAP 4 added (SIMPLE_DIVISION, DIVISION, EUCM; their
/// projections are pycolmap's, crates/nrw-synth/tests/pycolmap_oracle.rs): `inspect` names
/// the model, `ingest` renders each scene with its own lens and `export --layout files` takes
/// it as it is; `--undistort` stores PINHOLE views that gsplat's layout exports, and without
/// it that export is refused naming the model, its reader and the command that fixes it. A
/// 360° model (EQUIRECTANGULAR) is inspected, and refused by ingest naming the file, camera
/// and model.
#[test]
fn colmap_4_cameras_go_through_ingest_and_export_and_a_panorama_is_refused_by_name() {
    let tmp = tempfile::tempdir().unwrap();
    for model in ["SIMPLE_DIVISION", "DIVISION", "EUCM"] {
        let dir = tmp.path().join(model);
        let scene = lens_scene(&dir, 5, model, 3.0, false);
        let text = ok(&["inspect", scene.to_str().unwrap()]);
        assert!(text.contains(model), "{model}: {text}");
        ingest_and_export_a_lens(&dir, &scene, model);
    }
    let scene = tmp.path().join("SIMPLE_DIVISION/scene");
    let mut rec = nrw_colmap::read_model(&scene.join("sparse/0"), None).unwrap();
    for c in rec.cameras.values_mut() {
        c.model = nrw_colmap::CameraModel::Equirectangular;
        c.params = vec![c.width as f64, c.height as f64];
    }
    let pano = tmp.path().join("pano");
    nrw_colmap::write_model(&rec, &pano.join("sparse/0"), nrw_colmap::Format::Binary).unwrap();
    let p = pano.to_str().unwrap();
    let text = ok(&["inspect", p]);
    assert!(text.contains("EQUIRECTANGULAR"), "{text}");
    let err = fails(&[
        "ingest",
        p,
        "--images",
        scene.join("images").to_str().unwrap(),
        "--out",
        tmp.path().join("no").to_str().unwrap(),
    ]);
    assert!(
        err.contains("cameras.bin")
            && err.contains("camera 1: model EQUIRECTANGULAR is a 360° panorama"),
        "{err}"
    );
}

/// `scene` (cameras of `model`) ingested as it is and undistorted, each split and exported.
fn ingest_and_export_a_lens(tmp: &Path, scene: &Path, model: &str) {
    let s = scene.to_str().unwrap();
    for (name, undistort) in [("pinhole", true), ("lens", false)] {
        let ds = tmp.join(name);
        let d = ds.to_str().unwrap();
        let mut args = vec!["ingest", s, "--out", d];
        args.extend(SMALL_VIEWS);
        if undistort {
            args.push("--undistort");
        }
        let o = nrw(&args);
        let line = String::from_utf8_lossy(&o.stderr);
        assert!(
            o.status.success() && line.contains("5 registered, 5 kept"),
            "{line}"
        );
        ok(&["split", d, "--val", "1"]);
        let files = tmp.join(format!("{name}_files"));
        ok(&[
            "export",
            d,
            "--layout",
            "files",
            "--out",
            files.to_str().unwrap(),
        ]);
        let out = tmp.join(format!("{name}_gsplat"));
        let export = [
            "export",
            d,
            "--layout",
            "gsplat",
            "--out",
            out.to_str().unwrap(),
        ];
        if undistort {
            ok(&export);
            let model = nrw_colmap::read_model(&out.join("sparse/0"), None).unwrap();
            assert!(model.cameras.values().all(|c| c.model.name() == "PINHOLE"));
        } else {
            let err = fails(&export);
            assert!(
                err.contains(model)
                    && err.contains("graphdeco")
                    && err.contains("nrw-etl ingest SCENE --out DATASET --undistort"),
                "{model}: {err}"
            );
        }
    }
}

/// `ingest --undistort --semantics`: each label map is resampled with its photo, nearest class.
/// On a distorted synthetic scene, every stored class id is one the ground-truth map holds (no
/// blend), and at 97% or more of each stored view's pixels the id is the ground truth's at the
/// point where the view's own PINHOLE camera (as stored) sees through the photo's lens (the
/// rest lie on class borders, where the two nearest-pixel steps may pick the other side).
#[test]
fn label_maps_are_undistorted_with_their_photos_nearest_class() {
    let tmp = tempfile::tempdir().unwrap();
    let scene = lens_scene(tmp.path(), 4, "SIMPLE_RADIAL", 5.0, true);
    let (ds, labels) = (tmp.path().join("ds"), scene.join("ground_truth/semantics"));
    let (s, d, l) = (
        scene.to_str().unwrap(),
        ds.to_str().unwrap(),
        labels.to_str().unwrap(),
    );
    let mut args = vec![
        "ingest",
        s,
        "--out",
        d,
        "--undistort",
        "--semantics",
        l,
        "--quiet",
    ];
    args.extend(SMALL_VIEWS);
    ok(&args);
    let rec = nrw_colmap::read_model(&scene.join("sparse/0"), None).unwrap();
    let d = Dataset::open(ds.as_path()).unwrap();
    let (mut agree, mut total) = (0usize, 0usize);
    for id in d.all_ids() {
        let v = d.get(id).unwrap();
        let stored = v.labels().unwrap().expect("labels stored");
        let (w, h) = (v.width, v.height);
        assert_eq!((stored.width(), stored.height()), (w, h));
        assert_eq!(v.model, "PINHOLE");
        let lens = &rec.cameras[&rec.images[&id].camera_id];
        let gt = image::open(labels.join(Path::new(&v.name).with_extension("png")))
            .unwrap()
            .to_luma8();
        let classes: std::collections::BTreeSet<u8> = gt.as_raw().iter().copied().collect();
        let (f, c) = (
            glam::DVec2::new(v.params[0], v.params[1]),
            glam::DVec2::new(v.params[2], v.params[3]),
        );
        for y in 0..h {
            for x in 0..w {
                let got = stored.get_pixel(x, y)[0];
                assert!(classes.contains(&got), "{}: ({x},{y}) id {got}", v.name);
                let n = (glam::DVec2::new(x as f64 + 0.5, y as f64 + 0.5) - c) / f;
                let s = lens.img_from_cam(glam::DVec3::new(n.x, n.y, 1.0)).unwrap();
                let (sx, sy) = (s.x.floor() as u32, s.y.floor() as u32);
                let want = gt.get_pixel(sx.min(gt.width() - 1), sy.min(gt.height() - 1))[0];
                agree += (got == want) as usize;
                total += 1;
            }
        }
    }
    let share = agree as f64 / total as f64;
    eprintln!("undistorted label maps: {agree} of {total} stored pixels ({share:.4}) hold the class the stored pinhole camera sees through the lens");
    assert!(share >= 0.97, "{share}");
}
