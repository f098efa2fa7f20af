//! Every camera model COLMAP 4.2 defines against pycolmap 4.2.1's `img_from_cam` on random
//! realistic cameras and points, and against its `cam_from_img` / `cam_ray_from_img` at each
//! camera's centre, corners and edge midpoints (tests/fixtures/camera_models.json, made by
//! tests/fixtures/gen_camera_models.py).

use std::path::Path;

use glam::DVec3;
use nrw_colmap::{Camera, CameraModel};

#[test]
fn every_model_matches_pycolmap_to_1e9_px() {
    let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../tests/fixtures/camera_models.json");
    let v: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(p).unwrap()).unwrap();
    let mut seen = std::collections::BTreeSet::new();
    let (mut compared, mut invisible, mut behind) = (0, 0, 0);
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
                // COLMAP 4.2's division models ignore cheirality and project points on and
                // behind the camera plane; here no perspective model does (no photo shows them).
                (Some(_), None) if p.z < f64::EPSILON && is_division(model) => behind += 1,
                (w, g) => panic!("{name} {p:?}: pycolmap {w:?}, ours {g:?}"),
            }
        }
    }
    assert_eq!(
        seen.len(),
        CameraModel::ALL.len(),
        "fixtures cover every model"
    );
    eprintln!(
        "{compared} points project as pycolmap projects them (within 1e-9 px), {invisible} \
         invisible to both, {behind} behind a division camera"
    );
    assert!(
        compared > 1000 && invisible > 100 && behind > 0,
        "{compared} compared, {invisible} invisible, {behind} behind a division camera"
    );
}

fn is_division(m: CameraModel) -> bool {
    matches!(m, CameraModel::SimpleDivision | CameraModel::Division)
}

fn floats(v: &serde_json::Value) -> Option<Vec<f64>> {
    v.as_array()
        .map(|a| a.iter().map(|x| x.as_f64().unwrap()).collect())
}

/// Each camera's centre, corners and edge midpoints lifted to rays: where pycolmap's
/// `cam_from_img` gives the normalised point (u, v), ours is the same point (the ray over its
/// z) to 1e-9 of its size; for the panorama, `cam_ray_from_img`'s unit ray to 1e-12. Where
/// pycolmap's iterative lift finds no ray, ours finds none either or one that reprojects;
/// where pycolmap's closed-form lift misses its own projection (FOV's small-ω branch, a
/// division lens past its fold), ours reprojects or is none.
#[test]
fn every_model_lifts_corners_and_centre_as_pycolmap_does() {
    let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../tests/fixtures/camera_models.json");
    let v: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(p).unwrap()).unwrap();
    let (mut compared, mut worst, mut inconsistent) = (0, 0.0f64, Vec::new());
    for case in v["cases"].as_array().unwrap() {
        let name = case["model"].as_str().unwrap();
        let model = CameraModel::from_name(name).unwrap();
        let cam = Camera {
            id: 1,
            model,
            width: case["width"].as_u64().unwrap(),
            height: case["height"].as_u64().unwrap(),
            params: floats(&case["params"]).unwrap(),
        };
        for u in case["unprojected"].as_array().unwrap() {
            let px = floats(&u["pixel"]).unwrap();
            let px = glam::DVec2::new(px[0], px[1]);
            let ours = cam.cam_ray_from_img(px);
            if model.is_spherical() {
                let want = floats(&u["ray"]).unwrap();
                let got = ours.unwrap_or_else(|| panic!("{name} {px}: no ray"));
                let d = (got - DVec3::new(want[0], want[1], want[2])).length();
                assert!(d < 1e-12, "{name} {px}: ours {got}, pycolmap {want:?}");
                compared += 1;
                continue;
            }
            match (floats(&u["uv"]), ours) {
                (Some(want), Some(ray)) => {
                    let got = glam::DVec2::new(ray.x / ray.z, ray.y / ray.z);
                    let want = glam::DVec2::new(want[0], want[1]);
                    let d = (got - want).length() / (1.0 + want.length());
                    // Where COLMAP's closed-form lift misses its own projection (FOV's
                    // small-ω Taylor branch), ours, which inverts the projection, must hit it.
                    let theirs_back = cam.img_from_cam(want.extend(1.0));
                    if d >= 1e-9 && theirs_back.is_none_or(|b| (b - px).length() > 1e-6) {
                        let back = cam.img_from_cam(ray).unwrap();
                        assert!((back - px).length() < 1e-6, "{name} {px}: {back}");
                        inconsistent.push(format!("{name} {px}: {theirs_back:?}"));
                        continue;
                    }
                    assert!(d < 1e-9, "{name} {px}: ours {got}, pycolmap {want} ({d:e})");
                    worst = worst.max(d);
                    compared += 1;
                }
                (None, Some(ray)) => {
                    let back = cam.img_from_cam(ray).unwrap();
                    assert!((back - px).length() < 1e-6, "{name} {px}: {back}");
                }
                (Some(want), None) => {
                    // Past the fold of a division lens with k > 0 COLMAP's closed-form lift
                    // gives a point that projects elsewhere: no ray projects there.
                    let theirs_back = cam.img_from_cam(glam::DVec3::new(want[0], want[1], 1.0));
                    assert!(
                        theirs_back.is_none_or(|b| (b - px).length() > 1e-6),
                        "{name} {px}: pycolmap lifts it to {want:?}, ours not"
                    );
                    inconsistent.push(format!("{name} {px}: {theirs_back:?}"));
                }
                (None, None) => {}
            }
        }
    }
    eprintln!(
        "{compared} pixels lifted as pycolmap lifts them; the largest relative difference \
         {worst:.1e}; {} where pycolmap's lift misses its own projection",
        inconsistent.len()
    );
    assert!(compared > 1500, "{compared}");
    assert!(
        inconsistent
            .iter()
            .all(|s| s.starts_with("FOV ") || s.contains("DIVISION ")),
        "{inconsistent:?}"
    );
}
