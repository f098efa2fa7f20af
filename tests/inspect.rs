//! `inspect` and `--help`: a model's summary and its checks against pycolmap, corrupted models named by file, record and field.

use super::*;

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
fn help_teaches_the_layout_and_examples() {
    let h = ok(&["--help"]);
    assert!(
        h.contains("sparse/0/") && h.contains("Examples:") && h.contains("ingest"),
        "{h}"
    );
    let h = ok(&["ingest", "--help"]);
    assert!(h.contains("--images") && h.contains("--out"), "{h}");
}
