//! Every camera model against pycolmap's `img_from_cam` on random realistic cameras and
//! points (tests/fixtures/camera_models.json, made by tests/fixtures/gen_camera_models.py).

use std::path::Path;

use glam::DVec3;
use nrw_colmap::{Camera, CameraModel};

#[test]
fn every_model_matches_pycolmap_to_1e9_px() {
    let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../tests/fixtures/camera_models.json");
    let v: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(p).unwrap()).unwrap();
    let mut seen = std::collections::BTreeSet::new();
    let (mut compared, mut invisible) = (0, 0);
    for case in v["cases"].as_array().unwrap() {
        let name = case["model"].as_str().unwrap();
        let model = CameraModel::from_name(name).unwrap();
        seen.insert(model);
        let params: Vec<f64> = case["params"]
            .as_array()
            .unwrap()
            .iter()
            .map(|x| x.as_f64().unwrap())
            .collect();
        assert_eq!(params.len(), model.num_params(), "{name}");
        let cam = Camera {
            id: 1,
            model,
            width: case["width"].as_u64().unwrap(),
            height: case["height"].as_u64().unwrap(),
            params,
        };
        let pts: Vec<DVec3> = case["points"]
            .as_array()
            .unwrap()
            .iter()
            .map(|p| {
                let a: Vec<f64> = p
                    .as_array()
                    .unwrap()
                    .iter()
                    .map(|x| x.as_f64().unwrap())
                    .collect();
                DVec3::new(a[0], a[1], a[2])
            })
            .collect();
        let mut ours = Vec::new();
        cam.project_many(&pts, &mut ours);
        for ((p, want), got) in pts
            .iter()
            .zip(case["pixels"].as_array().unwrap())
            .zip(&ours)
        {
            match (want.as_array(), got) {
                (None, None) => invisible += 1,
                (Some(w), Some(g)) => {
                    let (wx, wy) = (w[0].as_f64().unwrap(), w[1].as_f64().unwrap());
                    let d = ((g.x - wx).powi(2) + (g.y - wy).powi(2)).sqrt();
                    assert!(
                        d < 1e-9,
                        "{name} {p:?}: ours {g:?}, pycolmap ({wx}, {wy}), |d| = {d:e}"
                    );
                    compared += 1;
                }
                (w, g) => panic!("{name} {p:?}: pycolmap {w:?}, ours {g:?}"),
            }
        }
    }
    assert_eq!(
        seen.len(),
        CameraModel::ALL.len(),
        "fixtures cover every model"
    );
    assert!(
        compared > 1000 && invisible > 100,
        "{compared} compared, {invisible} invisible"
    );
}
