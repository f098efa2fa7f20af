//! `demo` and `synth`: the embedded scene through every stage, scene specs, the hard-case scenes and every camera model.

use super::*;

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
    // A 360° panorama it refuses by name: the renderer draws perspective and fisheye views.
    let mut spec = nrw_synth::SceneSpec::demo().shrunk(3, (120, 160), 3000);
    spec.cameras.model = "EQUIRECTANGULAR".into();
    let e = nrw_synth::generate(&spec, &tmp.path().join("pano"), &|| {}).unwrap_err();
    assert!(
        e.to_string().contains("cameras.model") && e.to_string().contains("360°"),
        "{e}"
    );
    for model in nrw_colmap::CameraModel::ALL
        .into_iter()
        .filter(|m| !m.is_spherical())
    {
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
