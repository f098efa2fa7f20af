//! The camera models' ids, projections and rays, on hand-made cameras.

use super::*;

fn cam(model: CameraModel, params: &[f64]) -> Camera {
    Camera {
        id: 1,
        model,
        width: 100,
        height: 80,
        params: params.to_vec(),
    }
}

#[test]
fn ids_and_names_round_trip() {
    for m in CameraModel::ALL {
        assert_eq!(CameraModel::from_id(m.id()), Some(m));
        assert_eq!(CameraModel::from_name(m.name()), Some(m));
    }
    assert_eq!(CameraModel::from_id(18), None);
    assert_eq!(CameraModel::from_id(-1), None);
}

#[test]
fn behind_on_and_nan_points_are_not_visible() {
    for m in CameraModel::ALL.into_iter().filter(|m| !m.is_spherical()) {
        let mut params = vec![0.0; m.num_params()];
        params[0] = 100.0;
        if !m.single_focal() {
            params[1] = 100.0;
        }
        let c = cam(m, &params);
        assert_eq!(
            c.img_from_cam(DVec3::new(0.1, 0.2, 0.0)),
            None,
            "{m} on plane"
        );
        assert_eq!(
            c.img_from_cam(DVec3::new(0.1, 0.2, -1.0)),
            None,
            "{m} behind"
        );
        assert_eq!(
            c.img_from_cam(DVec3::new(0.1, 0.2, 1e-17)),
            None,
            "{m} below eps"
        );
        assert_eq!(
            c.img_from_cam(DVec3::new(f64::NAN, 0.2, 1.0)),
            None,
            "{m} nan"
        );
        assert!(
            c.img_from_cam(DVec3::new(0.1, 0.2, 1.0)).is_some(),
            "{m} in front"
        );
    }
}

#[test]
fn principal_axis_hits_principal_point() {
    let c = cam(
        CameraModel::OpenCvFisheye,
        &[500.0, 510.0, 320.5, 240.5, 0.1, 0.01, 0.0, 0.0],
    );
    assert_eq!(
        c.img_from_cam(DVec3::new(0.0, 0.0, 3.0)),
        Some(DVec2::new(320.5, 240.5))
    );
}

#[test]
fn fisheye_beyond_90_degrees_is_not_visible() {
    let c = cam(
        CameraModel::OpenCvFisheye,
        &[500.0, 500.0, 320.0, 240.0, 0.0, 0.0, 0.0, 0.0],
    );
    // 89.9° is visible and lands at f·θ from the centre; 90.1° is behind the camera.
    let a = 89.9f64.to_radians();
    let px = c.img_from_cam(DVec3::new(a.sin(), 0.0, a.cos())).unwrap();
    assert!((px.x - (320.0 + 500.0 * a)).abs() < 1e-9);
    let b = 90.1f64.to_radians();
    assert_eq!(c.img_from_cam(DVec3::new(b.sin(), 0.0, b.cos())), None);
}

#[test]
fn rays_from_pixels_reproject_for_every_model() {
    for m in CameraModel::ALL.into_iter().filter(|m| !m.is_spherical()) {
        let mut params = vec![0.0; m.num_params()];
        let k = if m.single_focal() { 1 } else { 2 };
        params[..k].fill(if m.is_fisheye() { 420.0 } else { 700.0 });
        params[k] = 400.0;
        params[k + 1] = 300.0;
        for (i, p) in params.iter_mut().enumerate().skip(k + 2) {
            *p = if m == CameraModel::Fov {
                0.8
            } else {
                0.02 / (i as f64)
            };
        }
        let c = cam(m, &params);
        for y in (0..600).step_by(37) {
            for x in (0..800).step_by(41) {
                let px = DVec2::new(x as f64 + 0.5, y as f64 + 0.5);
                let ray = c.cam_ray_from_img(px).unwrap_or_else(|| panic!("{m} {px}"));
                assert!((ray.length() - 1.0).abs() < 1e-12);
                let back = c.img_from_cam(ray * 7.0).unwrap();
                assert!((back - px).length() < 1e-6, "{m} {px} -> {back}");
            }
        }
    }
}

#[test]
fn injective_radius_finds_the_fold_of_a_negative_radial_term() {
    // x(1 + k x²) peaks at x = 1/√(−3k): 2.887 for k = −0.04.
    let c = cam(CameraModel::SimpleRadial, &[500.0, 320.0, 240.0, -0.04]);
    let r = c.injective_radius();
    assert!((r - 1.0 / (0.12f64).sqrt()).abs() < 0.03, "{r}");
    // Positive k never folds; pinhole never does.
    assert_eq!(
        cam(CameraModel::SimpleRadial, &[500.0, 320.0, 240.0, 0.04]).injective_radius(),
        100.0
    );
    assert_eq!(
        cam(CameraModel::Pinhole, &[500.0, 500.0, 320.0, 240.0]).injective_radius(),
        100.0
    );
}

#[test]
fn overflowing_distortion_is_not_a_pixel() {
    let c = cam(CameraModel::Radial, &[100.0, 50.0, 40.0, 1e300, 1e300]);
    assert_eq!(c.img_from_cam(DVec3::new(1e10, 1e10, 1.0)), None);
}

#[test]
fn scaling_moves_focal_and_principal_point_only() {
    let c = cam(CameraModel::SimpleRadial, &[1000.0, 50.0, 40.0, 0.1]);
    let s = c.scaled(0.5, 0.5, 50, 40);
    assert_eq!(s.params, vec![500.0, 25.0, 20.0, 0.1]);
    let p = DVec3::new(0.01, -0.02, 1.0);
    let a = c.img_from_cam(p).unwrap();
    let b = s.img_from_cam(p).unwrap();
    assert!((a * 0.5 - b).length() < 1e-12);
}

#[test]
fn project_many_equals_one_by_one() {
    let c = cam(
        CameraModel::FullOpenCv,
        &[
            500.0, 510.0, 320.0, 240.0, 0.1, -0.01, 0.001, 0.002, 0.001, 0.01, 0.001, 0.0001,
        ],
    );
    let pts: Vec<DVec3> = (0..50)
        .map(|i| {
            DVec3::new(
                i as f64 * 0.01 - 0.25,
                0.1,
                if i % 7 == 0 { -1.0 } else { 1.0 },
            )
        })
        .collect();
    let mut out = Vec::new();
    c.project_many(&pts, &mut out);
    for (p, o) in pts.iter().zip(&out) {
        assert_eq!(c.img_from_cam(*p), *o);
    }
}

#[test]
fn a_panorama_sees_the_whole_sphere_and_its_rays_reproject() {
    let c = cam(CameraModel::Equirectangular, &[800.0, 400.0]);
    // Forward is the centre, behind the camera the left and right edges, up the top row.
    assert_eq!(
        c.img_from_cam(DVec3::new(0.0, 0.0, 2.0)),
        Some(DVec2::new(400.0, 200.0))
    );
    assert_eq!(
        c.img_from_cam(DVec3::new(1.0, 0.0, 0.0)),
        Some(DVec2::new(600.0, 200.0))
    );
    let behind = c.img_from_cam(DVec3::new(1e-9, 0.0, -1.0)).unwrap();
    assert!((behind.x - 800.0).abs() < 1e-6, "{behind}");
    assert_eq!(
        c.img_from_cam(DVec3::new(0.0, -3.0, 0.0)),
        Some(DVec2::new(400.0, 0.0))
    );
    assert_eq!(c.img_from_cam(DVec3::ZERO), None);
    for y in (5..400).step_by(30) {
        for x in (5..800).step_by(45) {
            let px = DVec2::new(x as f64, y as f64);
            let ray = c.cam_ray_from_img(px).unwrap();
            assert!((ray.length() - 1.0).abs() < 1e-12);
            assert!(
                (c.img_from_cam(ray * 3.0).unwrap() - px).length() < 1e-9,
                "{px}"
            );
        }
    }
    assert_eq!(
        c.focal(),
        DVec2::new(800.0 / std::f64::consts::TAU, 400.0 / std::f64::consts::PI)
    );
    assert_eq!(c.scaled(0.5, 0.5, 400, 200).params, vec![400.0, 200.0]);
}
