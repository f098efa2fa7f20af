//! Undistorted cameras against COLMAP 3.8's own: ../shared/data/sacre_coeur/dense/sparse is
//! `image_undistorter`'s output for sparse/0 (10 SIMPLE_RADIAL cameras, one per photo).

#[path = "../../../tests/support/shared.rs"]
mod shared;

use nrw_colmap::{
    read_model, undistort_camera, Camera, CameraModel, UndistortError, UndistortOptions,
};

#[test]
fn undistorted_cameras_equal_colmap_image_undistorter() {
    let Some(scene) = shared::shared("data/sacre_coeur") else {
        return;
    };
    let sparse = read_model(&scene.join("sparse/0"), None).unwrap();
    let dense = read_model(&scene.join("dense/sparse"), None).unwrap();
    assert_eq!(sparse.cameras.len(), 10);
    let mut worst = 0f64;
    for (id, cam) in &sparse.cameras {
        assert_eq!(cam.model, CameraModel::SimpleRadial);
        let ours = undistort_camera(cam, &UndistortOptions::default()).unwrap();
        let colmap = &dense.cameras[id];
        assert_eq!(colmap.model, CameraModel::Pinhole);
        assert_eq!(ours.model, CameraModel::Pinhole);
        assert_eq!(
            (ours.width, ours.height),
            (colmap.width, colmap.height),
            "camera {id}: size (from {}×{})",
            cam.width,
            cam.height
        );
        for (a, b) in ours.params.iter().zip(&colmap.params) {
            worst = worst.max((a - b).abs());
            assert!(
                (a - b).abs() < 1e-6,
                "camera {id}: {:?} vs {:?}",
                ours.params,
                colmap.params
            );
        }
    }
    eprintln!("10 cameras: sizes equal, worst parameter difference {worst:.1e} px");
}

fn camera(model: CameraModel, width: u64, height: u64, params: Vec<f64>) -> Camera {
    Camera {
        id: 7,
        model,
        width,
        height,
        params,
    }
}

#[test]
fn pinhole_cameras_keep_their_numbers_and_options_shape_the_rest() {
    let o = UndistortOptions::default();
    // A pinhole camera is already undistorted; SIMPLE_PINHOLE becomes PINHOLE (fx = fy).
    let p = camera(
        CameraModel::Pinhole,
        640,
        480,
        vec![500.0, 510.0, 320.5, 240.25],
    );
    assert_eq!(undistort_camera(&p, &o).unwrap(), p);
    let sp = camera(
        CameraModel::SimplePinhole,
        640,
        480,
        vec![500.0, 320.0, 240.0],
    );
    let u = undistort_camera(&sp, &o).unwrap();
    assert_eq!(
        (u.model, u.params.clone()),
        (CameraModel::Pinhole, vec![500.0, 500.0, 320.0, 240.0])
    );
    // Barrel distortion (k < 0) drew the scene's border inward: undistorted, the photo's edge
    // spreads out, so even the no-blank-pixel image is larger than the photo, and keeping
    // every photo pixel (blank_pixels = 1, blank corners) makes it larger still.
    let barrel = camera(
        CameraModel::SimpleRadial,
        1000,
        800,
        vec![700.0, 500.0, 400.0, -0.1],
    );
    let tight = undistort_camera(&barrel, &o).unwrap();
    let loose = undistort_camera(
        &barrel,
        &UndistortOptions {
            blank_pixels: 1.0,
            ..o
        },
    )
    .unwrap();
    assert!(tight.width > 1000 && tight.height > 800, "{tight:?}");
    assert!(
        loose.width > tight.width && loose.height > tight.height,
        "{loose:?}"
    );
    assert_eq!(tight.params[0], 700.0, "focal length is kept");
    // max_image_size scales the whole camera down, COLMAP's Rescale.
    let small = undistort_camera(
        &barrel,
        &UndistortOptions {
            max_image_size: Some(300),
            ..o
        },
    )
    .unwrap();
    assert!(small.width.max(small.height) == 300, "{small:?}");
    let s = small.width as f64 / tight.width as f64;
    assert!((small.params[0] / 700.0 - s).abs() < 1e-12);
}

#[test]
fn strong_and_far_from_origin_lenses_stay_finite_or_are_refused_by_name() {
    let o = UndistortOptions::default();
    // Extreme OPENCV distortion (folds back inside the image): a finite camera or a named
    // refusal, never NaN sizes.
    let strong = camera(
        CameraModel::OpenCv,
        1200,
        900,
        vec![600.0, 600.0, 600.0, 450.0, -0.45, 0.2, 0.001, -0.001],
    );
    let got = undistort_camera(&strong, &o);
    eprintln!("strong OPENCV: {got:?}");
    match got {
        Ok(u) => {
            assert!(
                u.width >= 1 && u.height >= 1 && u.params.iter().all(|v| v.is_finite()),
                "{u:?}"
            );
        }
        Err(e) => assert!(e.to_string().contains("camera 7 (OPENCV)"), "{e}"),
    }
    // A 190° fisheye: border pixels past 90° have no ray in front of the camera.
    let fisheye = camera(
        CameraModel::SimpleRadialFisheye,
        1000,
        1000,
        vec![300.0, 500.0, 500.0, 0.0],
    );
    let got = undistort_camera(&fisheye, &o);
    eprintln!("190° fisheye: {got:?}");
    match got {
        Ok(u) => assert!(u.params.iter().all(|v| v.is_finite()), "{u:?}"),
        Err(e) => assert!(matches!(e, UndistortError::NoRay { camera: 7, .. }), "{e}"),
    }
    // Options outside their meaning are refused by name.
    let bad = UndistortOptions {
        blank_pixels: 2.0,
        ..o
    };
    let p = camera(CameraModel::Pinhole, 10, 10, vec![5.0, 5.0, 5.0, 5.0]);
    assert!(undistort_camera(&p, &bad)
        .unwrap_err()
        .to_string()
        .contains("blank_pixels"));
}
