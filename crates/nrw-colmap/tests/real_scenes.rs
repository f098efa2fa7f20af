//! The real scenes in ../shared/data, checked against pycolmap's numbers (the `*.oracle.json`
//! files there were computed with pycolmap 4.2.1: mean and max over every track element).

#[path = "../../../tests/support/shared.rs"]
mod shared;

use std::path::PathBuf;

use nrw_colmap::{read_model, read_ply, reprojection_stats, Format, Reconstruction};

fn data() -> PathBuf {
    shared::shared_path("data")
}

fn oracle(scene: &str) -> serde_json::Value {
    let p = data().join(format!("{scene}.oracle.json"));
    serde_json::from_str(
        &std::fs::read_to_string(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display())),
    )
    .unwrap()
}

fn rel(a: f64, b: f64) -> f64 {
    (a - b).abs() / b.abs().max(f64::MIN_POSITIVE)
}

fn check(rec: &Reconstruction, o: &serde_json::Value, what: &str) {
    assert_eq!(
        rec.cameras.len() as u64,
        o["cameras"].as_u64().unwrap(),
        "{what} cameras"
    );
    assert_eq!(
        rec.images.len() as u64,
        o["images"].as_u64().unwrap(),
        "{what} images"
    );
    assert_eq!(
        rec.points.len() as u64,
        o["points"].as_u64().unwrap(),
        "{what} points"
    );
    assert_eq!(
        rec.num_observations() as u64,
        o["observations"].as_u64().unwrap(),
        "{what} obs"
    );
    let models: Vec<String> = o["camera_models"]
        .as_array()
        .unwrap()
        .iter()
        .map(|m| m.as_str().unwrap().into())
        .collect();
    assert_eq!(rec.camera_model_names(), models, "{what} models");
    let s = reprojection_stats(rec);
    assert_eq!(s.not_visible, 0, "{what}");
    let mean = o["mean_reprojection_error_px"].as_f64().unwrap();
    let max = o["max_reprojection_error_px"].as_f64().unwrap();
    assert!(
        rel(s.mean_px.unwrap(), mean) < 1e-9,
        "{what} mean {} vs {mean}",
        s.mean_px.unwrap()
    );
    assert!(
        rel(s.max_px.unwrap(), max) < 1e-9,
        "{what} max {} vs {max}",
        s.max_px.unwrap()
    );
    let sum: glam::DVec3 = rec.points.values().map(|p| p.xyz).sum();
    let want: Vec<f64> = o["point_xyz_sum"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    for k in 0..3 {
        assert!(rel(sum[k], want[k]) < 1e-9, "{what} xyz sum");
    }
}

#[test]
fn sacre_coeur_matches_pycolmap_in_both_encodings() {
    let Some(_) = shared::shared("data") else {
        return;
    };
    let o = oracle("sacre_coeur");
    for f in [Format::Binary, Format::Text] {
        let rec = read_model(&data().join("sacre_coeur/sparse/0"), Some(f)).unwrap();
        assert!(!rec.is_colmap4());
        check(&rec, &o, &format!("sacre_coeur {f:?}"));
    }
}

#[test]
fn sacre_coeur_colmap4_layout_matches_pycolmap() {
    let Some(_) = shared::shared("data") else {
        return;
    };
    let o = oracle("sacre_coeur");
    for f in [Format::Binary, Format::Text] {
        let rec = read_model(&data().join("sacre_coeur/sparse_pycolmap421"), Some(f)).unwrap();
        assert!(rec.is_colmap4(), "{f:?}: rigs and frames read");
        assert_eq!(rec.rigs.len(), 10);
        assert_eq!(rec.frames.len(), 10);
        assert!(rec.warnings.is_empty(), "{:?}", rec.warnings);
        check(&rec, &o, &format!("sacre_coeur COLMAP 4 {f:?}"));
    }
}

#[test]
fn sceaux_castle_matches_pycolmap_in_both_encodings() {
    let Some(_) = shared::shared("data") else {
        return;
    };
    let o = oracle("sceaux_castle");
    for f in [Format::Binary, Format::Text] {
        let rec = read_model(&data().join("sceaux_castle/sparse/0"), Some(f)).unwrap();
        check(&rec, &o, &format!("sceaux_castle {f:?}"));
    }
}

#[test]
fn binary_and_text_encodings_give_identical_models() {
    let Some(_) = shared::shared("data") else {
        return;
    };
    for scene in ["sacre_coeur", "sceaux_castle"] {
        let dir = data().join(scene).join("sparse/0");
        let b = read_model(&dir, Some(Format::Binary)).unwrap();
        let t = read_model(&dir, Some(Format::Text)).unwrap();
        assert_eq!(b.cameras, t.cameras, "{scene}");
        assert_eq!(b.images, t.images, "{scene}");
        assert_eq!(b.points, t.points, "{scene}");
    }
}

#[test]
fn sceaux_fused_ply_reads_with_normals_and_colors() {
    let Some(_) = shared::shared("data") else {
        return;
    };
    let cloud = read_ply(&data().join("sceaux_castle/dense/fused.ply")).unwrap();
    assert_eq!(cloud.len(), 243_863);
    assert_eq!(cloud.normals.as_ref().unwrap().len(), 243_863);
    assert_eq!(cloud.colors.as_ref().unwrap().len(), 243_863);
    // Normals are unit length as COLMAP writes them.
    let n = cloud.normals.as_ref().unwrap()[1000];
    let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
    assert!((len - 1.0).abs() < 1e-3, "{len}");
}
