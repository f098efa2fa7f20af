//! The PINHOLE camera COLMAP's `image_undistorter` resamples a distorted photo to, computed
//! as COLMAP 3.8's `UndistortCamera` does with the options it exposes, so an undistorted
//! dataset has exactly the cameras of COLMAP's `dense/sparse` folder.
//!
//! In outline, for a camera with distortion: focal length and principal point are kept; every
//! border pixel centre of the distorted photo is unprojected (this crate's exact inverse of the
//! camera model) and projected with the pinhole camera; the pinhole image is then scaled about
//! the principal point so that, with `blank_pixels = 0`, no pixel of it falls outside the photo
//! (with 1, no photo pixel falls outside it), clipped to [`min_scale`, `max_scale`], and the
//! principal point follows the new size. Pinhole cameras keep their size and numbers.
//!
//! [`min_scale`]: UndistortOptions::min_scale
//! [`max_scale`]: UndistortOptions::max_scale

use std::collections::BTreeMap;

use glam::DVec2;

use crate::camera::{Camera, CameraModel};
use crate::model::Reconstruction;

/// COLMAP's `UndistortCameraOptions` that shape the pinhole camera; [`Default`] is COLMAP's.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct UndistortOptions {
    /// 0 keeps only pixels that see the photo (COLMAP's default, no blank border); 1 keeps
    /// every photo pixel (blank corners); values between interpolate the scale.
    pub blank_pixels: f64,
    /// Smallest allowed scale of the pinhole image relative to the photo (COLMAP: 0.2).
    pub min_scale: f64,
    /// Largest allowed scale (COLMAP: 2.0).
    pub max_scale: f64,
    /// Longest side of the pinhole image; `None` = no limit (COLMAP's −1).
    pub max_image_size: Option<u64>,
}

impl Default for UndistortOptions {
    fn default() -> Self {
        UndistortOptions {
            blank_pixels: 0.0,
            min_scale: 0.2,
            max_scale: 2.0,
            max_image_size: None,
        }
    }
}

/// Why a camera has no undistorted pinhole camera.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum UndistortError {
    /// A border pixel of the photo has no ray (beyond a fisheye's 90°, or a lens model that
    /// folds back inside the image).
    #[error("camera {camera} ({model}): the border pixel at ({x:.1}, {y:.1}) has no viewing ray, so no pinhole camera covers the photo")]
    NoRay {
        camera: u32,
        model: &'static str,
        x: f64,
        y: f64,
    },
    /// Options outside their meaning.
    #[error("undistortion options: {0}")]
    Options(String),
    /// A 360° panorama: no pinhole camera covers it (COLMAP's undistorter refuses it too).
    #[error("camera {camera} ({model}) is a 360° panorama: no pinhole camera covers it, and COLMAP's image_undistorter refuses it too (camera.IsPerspective())")]
    Spherical { camera: u32, model: &'static str },
    /// An image names a camera the model does not have.
    #[error("image {image} names camera {camera}, which the model does not have")]
    MissingCamera { image: u32, camera: u32 },
}

/// The normalised image-plane point (x/z, y/z) whose projection is `px` (COLMAP's
/// `ImageToWorld`), or `None` where no ray in front of the camera projects there.
fn image_to_world(camera: &Camera, px: DVec2) -> Option<DVec2> {
    let ray = camera.cam_ray_from_img(px)?;
    (ray.z > 0.0).then(|| DVec2::new(ray.x / ray.z, ray.y / ray.z))
}

/// COLMAP's `SelectPointOnRay` with its default 180° field-of-view limits: the point at
/// distance min(`max_length`, |target − origin|) from `origin` toward `target`, found by the
/// same 32 bisection steps (so it stops 2⁻³² short of it, as COLMAP does).
fn select_point_on_ray(
    camera: &Camera,
    origin: DVec2,
    target: DVec2,
    max_length: f64,
) -> Option<DVec2> {
    let half = std::f64::consts::FRAC_PI_2;
    let diff = target - origin;
    let dir = diff.normalize_or_zero();
    let (mut l, mut r) = (0.0f64, max_length.min(diff.length()));
    for _ in 0..32 {
        let m = (l + r) / 2.0;
        let valid = image_to_world(camera, origin + dir * m)
            .is_some_and(|w| w.y.atan() < half && w.x.atan() < half && w.length().atan() < half);
        if valid {
            l = m;
        } else {
            r = m;
        }
    }
    Some(origin + dir * l)
}

/// COLMAP's estimate of the radius, along the direction to the farthest image corner, up to
/// which the lens maps radius to angle monotonically. COLMAP's corner list has (height,
/// width) as its third corner; that is transcribed as is, since it decides which corner is
/// "farthest" and so the cameras COLMAP writes.
fn max_valid_radius(camera: &Camera) -> f64 {
    let (w, h) = (camera.width as f64, camera.height as f64);
    let pp = camera.principal_point();
    let corners = [
        DVec2::new(0.0, 0.0),
        DVec2::new(w, 0.0),
        DVec2::new(h, w),
        DVec2::new(0.0, h),
    ];
    let (mut max_radius, mut corner_dir) = (0.0, DVec2::ZERO);
    for c in corners {
        let d = c - pp;
        if d.length() > max_radius {
            max_radius = d.length();
            corner_dir = d.normalize();
        }
    }
    let mut radius = DVec2::new(w, h).length();
    let mut fov_half = 0.0;
    let mut i = 1.0;
    while i < max_radius {
        let Some(world) = image_to_world(camera, pp + corner_dir * i) else {
            break;
        };
        let phi = world.length().atan();
        if phi <= fov_half || 2.0 * phi > std::f64::consts::PI {
            break;
        }
        fov_half = phi;
        radius = i;
        i += 1.0;
    }
    radius
}

/// The PINHOLE camera COLMAP 3.8's `image_undistorter` gives `camera` under `options`
/// (same id). Only the `estimate_focal_length_from_fov`, ROI and model-override options of
/// COLMAP are not offered; their defaults are what this computes.
pub fn undistort_camera(
    camera: &Camera,
    options: &UndistortOptions,
) -> Result<Camera, UndistortError> {
    check_options(options)?;
    if camera.model.is_spherical() {
        return Err(UndistortError::Spherical {
            camera: camera.id,
            model: camera.model.name(),
        });
    }
    let f = camera.focal();
    let pp = camera.principal_point();
    let mut out = Camera {
        id: camera.id,
        model: CameraModel::Pinhole,
        width: camera.width,
        height: camera.height,
        params: vec![f.x, f.y, pp.x, pp.y],
    };
    if camera.model.has_distortion() {
        let scale = border_scale(camera, options)?;
        let (w, h) = (camera.width as f64, camera.height as f64);
        // static_cast<size_t>(max(1, scale · size)): truncation, as COLMAP.
        out.width = (scale.x * w).max(1.0) as u64;
        out.height = (scale.y * h).max(1.0) as u64;
        out.params[2] = pp.x * out.width as f64 / w;
        out.params[3] = pp.y * out.height as f64 / h;
    }
    if let Some(max) = options.max_image_size {
        let s = (max as f64 / out.width as f64).min(max as f64 / out.height as f64);
        if s < 1.0 {
            out = rescaled(&out, s);
        }
    }
    Ok(out)
}

/// The model COLMAP 3.8's `image_undistorter` writes into `dense/sparse` (its
/// `UndistortReconstruction`): every camera replaced by its pinhole camera
/// ([`undistort_camera`]) and every keypoint carried through the distorted camera's
/// unprojection and the pinhole camera's projection (which includes the size change), so the
/// keypoints lie where the undistorted photos show them. Returns the distorted cameras.
pub fn undistort_reconstruction(
    rec: &mut Reconstruction,
    options: &UndistortOptions,
) -> Result<BTreeMap<u32, Camera>, UndistortError> {
    let distorted = rec.cameras.clone();
    for cam in rec.cameras.values_mut() {
        *cam = undistort_camera(cam, options)?;
    }
    for image in rec.images.values_mut() {
        let missing = UndistortError::MissingCamera {
            image: image.id,
            camera: image.camera_id,
        };
        let (Some(from), Some(to)) = (
            distorted.get(&image.camera_id),
            rec.cameras.get(&image.camera_id),
        ) else {
            return Err(missing);
        };
        for p in image.points2d.iter_mut() {
            p.xy = undistorted_keypoint(from, to, p.xy)
                .unwrap_or_else(|| undistortion_ignored(from, to, p.xy));
        }
    }
    Ok(distorted)
}

/// Where a keypoint that has no viewing ray (past a fisheye's 90°, beyond the fold of a
/// strong radial distortion; a noisy keypoint of a point seen at 89.9° can land there) goes:
/// the pinhole projection of its distortion-free lift, finite and deterministic. COLMAP's
/// iterative undistortion does not converge there and writes an arbitrary position (seen:
/// 1e13 px and beyond), so no reader can use either.
fn undistortion_ignored(from: &Camera, to: &Camera, xy: DVec2) -> DVec2 {
    let lift = (xy - from.principal_point()) / from.focal();
    lift * to.focal() + to.principal_point()
}

/// A pixel of camera `from` carried to camera `to` through its viewing ray (COLMAP's
/// `to.WorldToImage(from.ImageToWorld(xy))`); `None` where `from` has no ray there.
pub fn undistorted_keypoint(from: &Camera, to: &Camera, xy: DVec2) -> Option<DVec2> {
    to.img_from_cam(from.cam_ray_from_img(xy)?)
}

fn check_options(o: &UndistortOptions) -> Result<(), UndistortError> {
    if !(0.0..=1.0).contains(&o.blank_pixels) {
        return Err(UndistortError::Options(format!(
            "blank_pixels is {}, must be in [0, 1]",
            o.blank_pixels
        )));
    }
    if !(o.min_scale > 0.0 && o.min_scale <= o.max_scale && o.max_scale.is_finite()) {
        return Err(UndistortError::Options(format!(
            "min_scale {} and max_scale {} must satisfy 0 < min ≤ max < ∞",
            o.min_scale, o.max_scale
        )));
    }
    if o.max_image_size == Some(0) {
        return Err(UndistortError::Options(
            "max_image_size 0: use None for no limit".into(),
        ));
    }
    Ok(())
}

/// Scale (x, y) of the pinhole image relative to the photo: where the photo's border pixel
/// centres land on the pinhole image plane (focal and principal point unchanged), blended by
/// `blank_pixels` between "covers the whole photo" and "sees only the photo", clipped.
fn border_scale(camera: &Camera, o: &UndistortOptions) -> Result<DVec2, UndistortError> {
    let (w, h) = (camera.width as f64, camera.height as f64);
    let (f, pp) = (camera.focal(), camera.principal_point());
    let radius = max_valid_radius(camera);
    let land = |x: f64, y: f64| -> Result<DVec2, UndistortError> {
        let no_ray = || UndistortError::NoRay {
            camera: camera.id,
            model: camera.model.name(),
            x,
            y,
        };
        let border =
            select_point_on_ray(camera, pp, DVec2::new(x, y), radius).ok_or_else(no_ray)?;
        let world = image_to_world(camera, border).ok_or_else(no_ray)?;
        Ok(world * f + pp)
    };
    let (mut left, mut right) = (MinMax::default(), MinMax::default());
    for y in 0..camera.height {
        let yc = y as f64 + 0.5;
        left.add(land(0.5, yc)?.x);
        right.add(land(w - 0.5, yc)?.x);
    }
    let (mut top, mut bottom) = (MinMax::default(), MinMax::default());
    for x in 0..camera.width {
        let xc = x as f64 + 0.5;
        top.add(land(xc, 0.5)?.y);
        bottom.add(land(xc, h - 0.5)?.y);
    }
    let (cx, cy) = (pp.x, pp.y);
    // Scale such that the pinhole image contains every photo pixel …
    let min_x = (cx / (cx - left.min)).min((w - 0.5 - cx) / (right.max - cx));
    let min_y = (cy / (cy - top.min)).min((h - 0.5 - cy) / (bottom.max - cy));
    // … or such that it has no blank pixel.
    let max_x = (cx / (cx - left.max)).max((w - 0.5 - cx) / (right.min - cx));
    let max_y = (cy / (cy - top.max)).max((h - 0.5 - cy) / (bottom.min - cy));
    let b = o.blank_pixels;
    let sx = 1.0 / (min_x * b + max_x * (1.0 - b));
    let sy = 1.0 / (min_y * b + max_y * (1.0 - b));
    Ok(DVec2::new(
        sx.clamp(o.min_scale, o.max_scale),
        sy.clamp(o.min_scale, o.max_scale),
    ))
}

/// A running minimum and maximum.
struct MinMax {
    min: f64,
    max: f64,
}

impl Default for MinMax {
    fn default() -> Self {
        MinMax {
            min: f64::MAX,
            max: f64::MIN,
        }
    }
}

impl MinMax {
    fn add(&mut self, v: f64) {
        self.min = self.min.min(v);
        self.max = self.max.max(v);
    }
}

/// COLMAP's `Camera::Rescale(scale)` of a PINHOLE camera: sizes rounded, focal and principal
/// point scaled by the rounded sizes' actual ratios.
fn rescaled(c: &Camera, scale: f64) -> Camera {
    let (w, h) = (c.width as f64, c.height as f64);
    let (nw, nh) = ((scale * w).round(), (scale * h).round());
    let (sx, sy) = (nw / w, nh / h);
    let p = &c.params;
    Camera {
        id: c.id,
        model: CameraModel::Pinhole,
        width: nw as u64,
        height: nh as u64,
        params: vec![p[0] * sx, p[1] * sy, p[2] * sx, p[3] * sy],
    }
}
