//! Numerically hard but valid models: georeferenced coordinates, degenerate sizes, points
//! on and behind the camera plane, unnormalised quaternions.

#[path = "../../../tests/support/shared.rs"]
mod shared;

use std::path::PathBuf;

use glam::{DVec2, DVec3};
use nrw_colmap::pose::dot3_plus;
use nrw_colmap::{
    observation_errors, read_model, reprojection_stats, write_model, Camera, CameraModel, Format,
    Image, Point2D, Point3D, Reconstruction, Rigid3, TrackElement,
};

fn sacre_coeur() -> Reconstruction {
    let dir = shared::shared_path("data/sacre_coeur/sparse/0");
    read_model(&dir, Some(Format::Binary)).unwrap()
}

/// Every point and camera centre moved by `d`, with t' = t − R·d summed exactly enough that
/// the shifted model is the original to within f64 rounding of its own coordinates.
fn shifted(rec: &Reconstruction, d: DVec3) -> Reconstruction {
    let mut out = rec.clone();
    for img in out.images.values_mut() {
        let rows = img.cam_from_world.matrix().transpose();
        let t = img.cam_from_world.translation;
        img.cam_from_world.translation = DVec3::new(
            dot3_plus(rows.x_axis, -d, t.x),
            dot3_plus(rows.y_axis, -d, t.y),
            dot3_plus(rows.z_axis, -d, t.z),
        );
    }
    for p in out.points.values_mut() {
        p.xyz += d;
    }
    out
}

fn roundtrip(rec: &Reconstruction, f: Format) -> (tempfile::TempDir, Reconstruction) {
    let dir = tempfile::tempdir().unwrap();
    write_model(rec, dir.path(), f).unwrap();
    let back = read_model(dir.path(), Some(f)).unwrap();
    (dir, back)
}

#[test]
fn utm_like_coordinates_give_the_same_reprojection_errors() {
    let Some(_) = shared::shared("data") else {
        return;
    };
    let rec = sacre_coeur();
    let base = reprojection_stats(&rec);
    let d = DVec3::new(5.0e6, 5.0e6, 5.0e6);
    for f in [Format::Binary, Format::Text] {
        // Through the file encodings too: the shifted numbers must survive writing and reading.
        let (_tmp, far) = roundtrip(&shifted(&rec, d), f);
        let worst = observation_errors(&rec)
            .iter()
            .zip(observation_errors(&far))
            .map(|(a, b)| (a.unwrap() - b.unwrap()).abs())
            .fold(0.0f64, f64::max);
        eprintln!("{f:?}: worst per-observation difference {worst:e} px");
        assert!(
            worst < 1e-6,
            "{f:?}: an observation's error moved by {worst:e} px"
        );
        let s = reprojection_stats(&far);
        assert_eq!(s.observations, base.observations);
        let dm = (s.mean_px.unwrap() - base.mean_px.unwrap()).abs();
        let dx = (s.max_px.unwrap() - base.max_px.unwrap()).abs();
        assert!(
            dm < 1e-6 && dx < 1e-6,
            "{f:?}: mean differs by {dm:e}, max by {dx:e}"
        );
        for (id, a) in &base.per_image {
            let b = &s.per_image[id];
            let di = (a.mean_px.unwrap() - b.mean_px.unwrap()).abs();
            assert!(
                di < 1e-6,
                "{f:?} image {id}: per-image mean differs by {di:e}"
            );
        }
    }
}

#[test]
fn points_on_and_behind_the_camera_plane_are_counted_not_averaged() {
    let cam = Camera {
        id: 1,
        model: CameraModel::SimpleRadial,
        width: 640,
        height: 480,
        params: vec![500.0, 320.0, 240.0, 0.01],
    };
    let pose = Rigid3::IDENTITY;
    let mut rec = Reconstruction::default();
    rec.cameras.insert(1, cam.clone());
    let pts = [
        DVec3::new(0.1, 0.2, 2.0),
        DVec3::new(0.1, 0.2, 0.0),
        DVec3::new(0.1, 0.2, -3.0),
    ];
    let mut points2d = Vec::new();
    for (k, p) in pts.iter().enumerate() {
        let xy = cam.img_from_cam(*p).unwrap_or(DVec2::new(10.0, 10.0)) + DVec2::new(0.3, 0.4);
        points2d.push(Point2D {
            xy,
            point3d_id: k as u64 + 1,
        });
        rec.points.insert(
            k as u64 + 1,
            Point3D {
                id: k as u64 + 1,
                xyz: *p,
                rgb: [1, 2, 3],
                error: 0.5,
                track: vec![TrackElement {
                    image_id: 1,
                    point2d_idx: k as u32,
                }],
            },
        );
    }
    rec.images.insert(
        1,
        Image {
            id: 1,
            name: "a.jpg".into(),
            camera_id: 1,
            cam_from_world: pose,
            stored_quat_norm: 1.0,
            points2d,
        },
    );
    let (_tmp, back) = roundtrip(&rec, Format::Binary);
    let s = reprojection_stats(&back);
    assert_eq!((s.observations, s.not_visible), (1, 2));
    assert!((s.mean_px.unwrap() - 0.5).abs() < 1e-12, "{:?}", s.mean_px);
}

#[test]
fn zero_points_and_one_image_are_valid_models() {
    let Some(_) = shared::shared("data") else {
        return;
    };
    let mut rec = sacre_coeur();
    let keep = *rec.images.keys().next().unwrap();
    rec.images.retain(|id, _| *id == keep);
    rec.points.clear();
    for img in rec.images.values_mut() {
        for p in &mut img.points2d {
            p.point3d_id = nrw_colmap::NO_POINT3D;
        }
    }
    for f in [Format::Binary, Format::Text] {
        let (_tmp, back) = roundtrip(&rec, f);
        assert_eq!(
            (
                back.images.len(),
                back.points.len(),
                back.num_observations()
            ),
            (1, 0, 0)
        );
        let s = reprojection_stats(&back);
        assert_eq!((s.observations, s.mean_px, s.max_px), (0, None, None));
    }
    // An image with no keypoints at all writes an empty keypoint line; text must still parse.
    rec.images.values_mut().for_each(|i| i.points2d.clear());
    let (_tmp, back) = roundtrip(&rec, Format::Text);
    assert_eq!(back.images.values().next().unwrap().points2d.len(), 0);
}

#[test]
fn unnormalised_quaternions_are_normalised_reported_and_harmless() {
    let Some(_) = shared::shared("data") else {
        return;
    };
    let rec = sacre_coeur();
    let base = reprojection_stats(&rec);
    let dir = tempfile::tempdir().unwrap();
    write_model(&rec, dir.path(), Format::Text).unwrap();
    // Scale every stored quaternion by 3: same rotation, wrong norm.
    let path: PathBuf = dir.path().join("images.txt");
    let text = std::fs::read_to_string(&path).unwrap();
    let mut out = String::new();
    let mut header = true;
    for line in text.lines() {
        if line.starts_with('#') {
            out.push_str(line);
        } else if header {
            let mut f: Vec<String> = line.split(' ').map(String::from).collect();
            for v in &mut f[1..5] {
                *v = (v.parse::<f64>().unwrap() * 3.0).to_string();
            }
            out.push_str(&f.join(" "));
            header = false;
        } else {
            out.push_str(line);
            header = true;
        }
        out.push('\n');
    }
    std::fs::write(&path, out).unwrap();
    let back = read_model(dir.path(), Some(Format::Text)).unwrap();
    assert_eq!(back.warnings.len(), rec.images.len());
    assert!(
        back.warnings[0].message.contains("norm was 3.0"),
        "{}",
        back.warnings[0]
    );
    assert!(back.warnings[0].to_string().contains("images.txt"));
    let s = reprojection_stats(&back);
    assert!((s.mean_px.unwrap() - base.mean_px.unwrap()).abs() < 1e-12);
}
