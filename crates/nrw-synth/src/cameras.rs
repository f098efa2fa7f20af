//! The photographers: intrinsics of the chosen COLMAP model, sizes, and poses around the
//! landmark, including small photos and views that look mostly away.

use glam::{DMat3, DQuat, DVec3};
use nrw_colmap::{Camera, CameraModel, Rigid3};
use rand::Rng;

use crate::geometry::Landmark;
use crate::spec::CameraSpec;

/// One synthetic photo's camera and pose (in the landmark's local frame).
#[derive(Debug, Clone)]
pub struct Shot {
    pub image_id: u32,
    pub camera_id: u32,
    pub name: String,
    pub camera: Camera,
    /// World→camera in the local frame (before the spec's origin offset).
    pub pose: Rigid3,
    pub centre: DVec3,
    /// Both sides under 450 px: the size filter's business.
    pub small: bool,
    /// Aimed mostly away from the landmark: the sparsity filter's business.
    pub away: bool,
}

/// Distortion coefficients of a model at strength `d` (0 gives an undistorted lens).
pub fn default_extra(model: CameraModel, d: f64) -> Vec<f64> {
    let v: &[f64] = match model {
        CameraModel::SimplePinhole
        | CameraModel::Pinhole
        | CameraModel::SimpleFisheye
        | CameraModel::Fisheye => &[],
        CameraModel::SimpleRadial | CameraModel::SimpleDivision | CameraModel::Division => &[-0.04],
        // α = 0 is a pinhole whatever β; β stays 1 (a sphere).
        CameraModel::Eucm => return vec![0.1 * d, 1.0],
        // A panorama's parameters are its size (spec checks refuse it before this).
        CameraModel::Equirectangular => &[],
        CameraModel::Radial => &[-0.04, 0.008],
        CameraModel::OpenCv => &[-0.04, 0.008, 0.0005, -0.0003],
        CameraModel::FullOpenCv => &[-0.04, 0.008, 0.0005, -0.0003, 0.001, 0.002, 0.0005, 0.0001],
        CameraModel::Fov => &[0.6],
        CameraModel::OpenCvFisheye => &[0.02, -0.004, 0.001, -0.0002],
        CameraModel::SimpleRadialFisheye => &[0.02],
        CameraModel::RadialFisheye => &[0.02, -0.004],
        CameraModel::ThinPrismFisheye => &[
            0.02, -0.004, 0.0005, -0.0003, 0.001, -0.0002, 0.0004, -0.0003,
        ],
        CameraModel::RadTanThinPrismFisheye => &[
            0.02, -0.004, 0.001, -0.0002, 0.0001, 0.0, 0.0005, -0.0003, 0.0004, 0.0, -0.0003, 0.0,
        ],
    };
    v.iter().map(|x| x * d).collect()
}

fn intrinsics<R: Rng>(
    model: CameraModel,
    w: u32,
    h: u32,
    distortion: f64,
    rng: &mut R,
) -> Vec<f64> {
    let (wf, hf) = (w as f64, h as f64);
    let f = if model.is_fisheye() {
        // Wide: the short side's half spans 63°–77°; corners may pass 90° and stay black.
        (wf.min(hf) / 2.0) / rng.random_range(1.1..1.35)
    } else {
        wf.max(hf) * rng.random_range(0.85..1.3)
    };
    let cx = wf / 2.0 + rng.random_range(-0.01..0.01) * wf;
    let cy = hf / 2.0 + rng.random_range(-0.01..0.01) * hf;
    let mut p = if model.single_focal() {
        vec![f, cx, cy]
    } else {
        vec![f, f * rng.random_range(0.995..1.005), cx, cy]
    };
    p.extend(default_extra(model, distortion));
    p
}

fn size<R: Rng>(spec: &CameraSpec, small: bool, rng: &mut R) -> (u32, u32) {
    // The shorter side is drawn; the longer follows from the aspect ratio.
    let short = if small {
        rng.random_range(200..=330)
    } else {
        rng.random_range(spec.min_size..=spec.max_size)
    };
    let (a, b) = match rng.random_range(0..4) {
        0 | 1 => (4, 3),
        2 => (3, 4),
        _ => (3, 2),
    };
    if a >= b {
        (short * a / b, short)
    } else {
        (short, short * b / a)
    }
}

/// World→camera rotation looking along `forward` with world z up, rolled by `roll`.
fn look(forward: DVec3, roll: f64) -> DMat3 {
    let f = forward.normalize();
    let r0 = f.cross(DVec3::Z).normalize();
    let d0 = f.cross(r0);
    let (s, c) = roll.sin_cos();
    let r = r0 * c + d0 * s;
    let d = d0 * c - r0 * s;
    DMat3::from_cols(r, d, f).transpose()
}

/// Draw every photo's camera and pose.
pub fn shots<R: Rng>(spec: &CameraSpec, landmark: &Landmark, ext: &str, rng: &mut R) -> Vec<Shot> {
    let model = CameraModel::from_name(&spec.model).expect("validated model name");
    let mut out = Vec::with_capacity(spec.count);
    let mut shared: Option<Camera> = None;
    for i in 0..spec.count {
        let small = !spec.shared && rng.random_bool(spec.small_fraction);
        let away = rng.random_bool(spec.away_fraction);
        let camera = match &shared {
            Some(c) => c.clone(),
            None => {
                let (w, h) = size(spec, small, rng);
                let params = intrinsics(model, w, h, spec.distortion, rng);
                let c = Camera {
                    id: i as u32 + 1,
                    model,
                    width: w as u64,
                    height: h as u64,
                    params,
                };
                if spec.shared {
                    shared = Some(c.clone());
                }
                c
            }
        };
        let target = landmark.facade_target(rng);
        let dist = rng.random_range(spec.min_distance..=spec.max_distance);
        let az = rng.random_range(-55f64..55.0).to_radians();
        let height = if rng.random_bool(0.2) {
            rng.random_range(4.0..12.0)
        } else {
            rng.random_range(1.4..2.0)
        };
        let centre = DVec3::new(target.x + dist * az.sin(), -dist * az.cos(), height);
        let mut forward = target - centre;
        if away {
            let yaw = rng.random_range(100f64..260.0).to_radians();
            let (s, c) = yaw.sin_cos();
            let horiz = DVec3::new(
                forward.x * c - forward.y * s,
                forward.x * s + forward.y * c,
                0.0,
            )
            .normalize();
            let tilt = rng.random_range(-25f64..-8.0).to_radians();
            forward = horiz * tilt.cos() + DVec3::Z * tilt.sin();
        }
        let r = look(forward, rng.random_range(-2f64..2.0).to_radians());
        let rotation = DQuat::from_mat3(&r).normalize();
        let pose = Rigid3 {
            rotation,
            translation: -(r * centre),
        };
        out.push(Shot {
            image_id: i as u32 + 1,
            camera_id: camera.id,
            name: format!("photo_{:04}.{ext}", i + 1),
            camera,
            pose,
            centre,
            small,
            away,
        });
    }
    out
}
