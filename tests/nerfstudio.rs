//! `export --layout nerfstudio` on a real scene: an independent Python projector following
//! nerfstudio's documented conventions (tests/oracles/nerfstudio_projector.py) sends every sparse
//! point of sacre_coeur through transforms.json, and lands exactly where the dataset's own
//! camera puts it, and on its COLMAP observation within the model's reprojection error.
//! Models nerfstudio cannot represent exactly are refused by name.

use std::path::Path;

use nrw_dataset::reader::Dataset;

use super::{data, fails, ok, python_has, shared};

fn dataset(scene: &Path, out: &Path) {
    ok(&[
        "ingest",
        scene.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--max-empty",
        "1",
        "--min-dim",
        "300",
        "--quiet",
    ]);
    ok(&["split", out.to_str().unwrap(), "--val", "3"]);
}

fn export(ds: &Path, out: &Path) -> std::process::Output {
    super::nrw(&[
        "export",
        ds.to_str().unwrap(),
        "--layout",
        "nerfstudio",
        "--out",
        out.to_str().unwrap(),
        "--quiet",
    ])
}

#[test]
fn transforms_json_projects_every_sparse_point_onto_its_observation() {
    let Some(_) = shared::shared("data") else {
        return;
    };
    if !python_has("import pycolmap, numpy") {
        return;
    }
    let scene = data().join("sacre_coeur");
    let tmp = tempfile::tempdir().unwrap();
    let ds_dir = tmp.path().join("ds");
    dataset(&scene, &ds_dir);
    let exp = tmp.path().join("ns");
    let o = export(&ds_dir, &exp);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let meta: serde_json::Value =
        serde_json::from_slice(&std::fs::read(exp.join("transforms.json")).unwrap()).unwrap();
    let frames = meta["frames"].as_array().unwrap();
    assert_eq!(frames.len(), 10);
    assert_eq!(meta["train_filenames"].as_array().unwrap().len(), 7);
    assert_eq!(meta["val_filenames"].as_array().unwrap().len(), 3);
    assert_eq!(meta["test_filenames"], meta["val_filenames"]);
    assert!(exp.join("sparse_pc.ply").is_file());
    // SIMPLE_RADIAL frames carry k1: the PINHOLE-only loaders are warned of, by name.
    let summary: serde_json::Value =
        serde_json::from_slice(&std::fs::read(exp.join("export.json")).unwrap()).unwrap();
    assert!(
        summary["warnings"][0]
            .as_str()
            .unwrap()
            .contains("Splatfacto-W"),
        "{summary}"
    );
    assert_eq!(summary["depth_source"], "the render's z-buffer");
    let ds = Dataset::open(ds_dir.as_path()).unwrap();
    for f in frames {
        assert_eq!(
            f["camera_model"], "OPENCV",
            "SIMPLE_RADIAL is OPENCV with k1"
        );
        for key in ["file_path", "depth_file_path"] {
            assert!(exp.join(f[key].as_str().unwrap()).is_file(), "{f}");
        }
        // Depth: float32 z × 1000 of the stored EXR.
        let v = ds.get(f["colmap_im_id"].as_u64().unwrap() as u32).unwrap();
        let npy = std::fs::read(exp.join(f["depth_file_path"].as_str().unwrap())).unwrap();
        let header_len = u16::from_le_bytes([npy[8], npy[9]]) as usize;
        let header = std::str::from_utf8(&npy[10..10 + header_len]).unwrap();
        assert!(
            header.contains(&format!("'shape': ({}, {})", v.height, v.width)),
            "{header}"
        );
        let depth = v.depth().unwrap();
        let body = &npy[10 + header_len..];
        for (i, z) in depth.data.iter().enumerate() {
            let got = f32::from_le_bytes(body[i * 4..i * 4 + 4].try_into().unwrap());
            assert_eq!(got, z * 1000.0);
            // nerfstudio's conversion (data/utils/data_utils.py `get_depth_image_from_path`:
            // the array × depth_unit_scale_factor, 1e-3 by default, in float32) gives model
            // units back to float32 rounding.
            let back = got * 1e-3f32;
            assert!(
                (back - z).abs() <= 4.0 * f32::EPSILON * z.abs(),
                "{back} vs {z}"
            );
        }
    }
    let o = std::process::Command::new("python3")
        .arg(
            Path::new(env!("CARGO_MANIFEST_DIR"))
                .join("../../tests/oracles/nerfstudio_projector.py"),
        )
        .arg(&exp)
        .arg(scene.join("sparse/0"))
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    // The model's own per-observation errors (our projection, checked against pycolmap's
    // oracle elsewhere), for the bound.
    let rec = nrw_colmap::read_model(&scene.join("sparse/0"), None).unwrap();
    let model_max = nrw_colmap::reprojection_stats(&rec).max_px.unwrap();
    let (mut n, mut worst_exact, mut worst_obs, mut sum_obs) = (0, 0f64, 0f64, 0f64);
    for line in String::from_utf8(o.stdout).unwrap().lines() {
        let r: serde_json::Value = serde_json::from_str(line).unwrap();
        let uv: [f64; 2] = serde_json::from_value(r["uv"].clone()).unwrap();
        let obs: [f64; 2] = serde_json::from_value(r["obs"].clone()).unwrap();
        let ms: [f64; 2] = serde_json::from_value(r["model_size"].clone()).unwrap();
        let fs: [f64; 2] = serde_json::from_value(r["frame_size"].clone()).unwrap();
        // 1. Exactly where the dataset's own camera and pose put the point.
        let v = ds.get(r["image"].as_u64().unwrap() as u32).unwrap();
        let cam = nrw_colmap::Camera {
            id: v.camera_id,
            model: nrw_colmap::CameraModel::from_name(&v.model).unwrap(),
            width: v.width as u64,
            height: v.height as u64,
            params: v.params.clone(),
        };
        let (pose, _) = nrw_colmap::Rigid3::from_colmap(v.qvec, v.tvec).unwrap();
        let xyz = rec.points[&r["point"].as_u64().unwrap()].xyz;
        let ours = cam.img_from_cam(pose.transform(xyz)).unwrap();
        worst_exact = worst_exact.max((ours.x - uv[0]).hypot(ours.y - uv[1]));
        // 2. On the observation, scaled to the frame, within the model's error.
        let (sx, sy) = (fs[0] / ms[0], fs[1] / ms[1]);
        let d = (uv[0] - obs[0] * sx).hypot(uv[1] - obs[1] * sy) / sx.max(sy);
        worst_obs = worst_obs.max(d);
        sum_obs += d;
        n += 1;
    }
    assert_eq!(n, rec.num_observations(), "every observation projected");
    eprintln!(
        "{n} observations: nerfstudio convention vs dataset camera worst {worst_exact:.1e} px; \
         vs COLMAP observations mean {:.3} px, worst {worst_obs:.3} px (model pixels; the \
         model's own max {model_max:.3} px)",
        sum_obs / n as f64
    );
    assert!(worst_exact < 1e-6, "{worst_exact}");
    assert!(
        worst_obs <= model_max * 1.01 + 0.01,
        "{worst_obs} vs {model_max}"
    );
}

#[test]
fn cameras_nerfstudio_cannot_represent_are_refused_by_name() {
    let Some(_) = shared::shared("data") else {
        return;
    };
    // sacre_coeur with its cameras rewritten as FOV (fx, fy, cx, cy, omega).
    let tmp = tempfile::tempdir().unwrap();
    let src = data().join("sacre_coeur");
    let scene = tmp.path().join("scene");
    let mut rec = nrw_colmap::read_model(&src.join("sparse/0"), None).unwrap();
    for c in rec.cameras.values_mut() {
        let (f, cx, cy) = (c.params[0], c.params[1], c.params[2]);
        c.model = nrw_colmap::CameraModel::Fov;
        c.params = vec![f, f, cx, cy, 0.05];
    }
    nrw_colmap::write_model(&rec, &scene.join("sparse/0"), nrw_colmap::Format::Binary).unwrap();
    super::copy_photos(&src.join("images"), &scene.join("images"));
    let ds_dir = tmp.path().join("ds");
    dataset(&scene, &ds_dir);
    let exp = tmp.path().join("ns");
    let err = fails(&[
        "export",
        ds_dir.to_str().unwrap(),
        "--layout",
        "nerfstudio",
        "--out",
        exp.to_str().unwrap(),
    ]);
    assert!(
        err.contains("camera model FOV") && err.contains("--undistort"),
        "{err}"
    );
    assert!(!exp.exists());
}

#[test]
fn masks_keep_what_the_transient_mask_does_not_cover() {
    // A synthetic scene with people in front of the façade and its ground-truth labels.
    let tmp = tempfile::tempdir().unwrap();
    let scene = tmp.path().join("scene");
    let mut spec = nrw_synth::SceneSpec::demo().shrunk(4, (120, 150), 60_000);
    spec.effects.transients = Some(6.0);
    nrw_synth::generate(&spec, &scene, &|| {}).unwrap();
    let ds_dir = tmp.path().join("ds");
    let labels = scene.join("ground_truth/semantics");
    ok(&[
        "ingest",
        scene.to_str().unwrap(),
        "--out",
        ds_dir.to_str().unwrap(),
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
    ok(&["split", ds_dir.to_str().unwrap(), "--val", "1"]);
    let exp = tmp.path().join("ns");
    let o = export(&ds_dir, &exp);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let meta: serde_json::Value =
        serde_json::from_slice(&std::fs::read(exp.join("transforms.json")).unwrap()).unwrap();
    let ds = Dataset::open(ds_dir.as_path()).unwrap();
    let mut masked = 0usize;
    for f in meta["frames"].as_array().unwrap() {
        let v = ds.get(f["colmap_im_id"].as_u64().unwrap() as u32).unwrap();
        let transient = v.transient().unwrap().expect("semantics ingested");
        let mask = image::open(exp.join(f["mask_path"].as_str().unwrap()))
            .unwrap()
            .to_luma8();
        assert_eq!(mask.dimensions(), (v.width, v.height));
        for (m, t) in mask.as_raw().iter().zip(transient.as_raw()) {
            assert_eq!(*m, 255 - t, "nerfstudio: 0 = ignore the pixel");
            masked += (*m == 0) as usize;
        }
    }
    assert!(masked > 0, "the people are masked out somewhere");
}

/// nerfstudio itself (1.1.5, which needs torch: never in CI) reads the nerfstudio export through
/// its `NerfstudioDataParser` and `DepthDataset`, and the gsplat export through its
/// `ColmapDataParser` at downscale factors 1, 2 and 4 (tests/oracles/nerfstudio_torch.py). Runs where
/// `NRW_TORCH_PYTHON` names a Python with torch and nerfstudio; skips and says so elsewhere.
#[test]
fn nerfstudio_itself_reads_the_nerfstudio_and_gsplat_exports() {
    // Not in CI: nerfstudio 1.1.5 and its dependencies took 209 s and 7.9 GB to install here.
    let Some(py) = super::python::torch_python("nerfstudio", "nerfstudio 1.1.5", false) else {
        return;
    };
    // The gsplat test's dataset (PINHOLE, people, truth labels) and its gsplat export.
    let tmp = tempfile::tempdir().unwrap();
    let (_, ds, gs) = crate::gsplat::exported(tmp.path());
    let ns = tmp.path().join("ns");
    let o = export(&ds, &ns);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let got = super::script_json(&py, "nerfstudio_torch.py", &[&ns, &gs]);
    let n = &got["nerfstudio"];
    assert_eq!(
        (n["train"].as_u64(), n["val"].as_u64()),
        (Some(4), Some(1)),
        "{n}"
    );
    assert_eq!(
        n["depth_unit_scale_factor"], 0.001,
        "the default the files are written for"
    );
    let mut masked = 0;
    for f in n["frames"].as_array().unwrap() {
        assert_eq!(f["image"][0], f["camera"][0], "{f}");
        assert_eq!(f["image"][1], f["camera"][1], "{f}");
        assert_eq!(f["depth"], f["camera"], "{f}");
        assert_eq!(f["masked"], f["masked_in_png"], "0 = ignore: {f}");
        masked += f["masked"].as_u64().unwrap();
    }
    assert!(masked > 0, "the people are masked out somewhere");
    let median = n["median_relative_depth"].as_f64().unwrap();
    let visible = n["visible_points"].as_u64().unwrap();
    assert!(
        visible > 1000 && median < 1e-4,
        "{visible} points, median {median}"
    );
    for factor in ["1", "2", "4"] {
        let c = &got["colmap"][factor];
        let folder = if factor == "1" {
            "images".to_string()
        } else {
            format!("images_{factor}")
        };
        assert_eq!(c["folders"], serde_json::json!([folder]), "{c}");
        assert_eq!(c["views"], 4, "{c}");
        assert_eq!(c["shape_mismatches"], 0, "{c}");
        assert_eq!(c["fx_worst_relative"], 0.0, "{c}");
    }
    eprintln!(
        "nerfstudio {} (torch {}) read both exports: {visible} sparse points seen through its \
         cameras land on its depth within {:.1e} (median, relative); images_2/4 and masks_2/4 match its \
         rescaled cameras",
        got["nerfstudio_version"].as_str().unwrap(),
        got["torch"].as_str().unwrap(),
        median
    );
}
