//! A photo's camera at render size, in the cloud's local frame, with the bounds used to
//! cull chunks.

use glam::{DVec2, DVec3, Mat3, Vec3};
use nrw_colmap::{Camera, Image};

/// Render size for a photo: scaled so its shorter side is `min_dim` (the paper uses 600).
pub fn render_size(width: u64, height: u64, min_dim: u32) -> (u32, u32) {
    let s = min_dim as f64 / width.min(height) as f64;
    (
        ((width as f64 * s).round() as u32).max(1),
        ((height as f64 * s).round() as u32).max(1),
    )
}

/// Pixel of a camera-space point in front of an undistorted lens `k` = (fx, fy, cx, cy).
///
/// Precision is given up here: f32 rather than COLMAP's f64, so a chunk of points projects
/// in SIMD lanes. The pixel error (four f32 roundings: ≤ 6·10⁻⁴ px at 4,000 px) is below
/// what the f32 local positions already carry (≈ 10⁻³ px for a 100 m scene seen from 10 m
/// at f = 3,000).
#[inline(always)]
pub fn pinhole_pixel(k: [f32; 4], c: Vec3) -> (f32, f32) {
    let iz = 1.0 / c.z;
    (k[0] * (c.x * iz) + k[2], k[1] * (c.y * iz) + k[3])
}

/// One photo's view: scaled camera, local pose in f32, lens fold and frustum bounds.
#[derive(Debug, Clone)]
pub struct View {
    pub image_id: u32,
    /// The photo's camera scaled to the render size (fx, cx by sx; fy, cy by sy).
    pub camera: Camera,
    pub width: u32,
    pub height: u32,
    /// Render size / photo size, per axis.
    pub scale: DVec2,
    /// World→camera for local (re-centred) points, in f32.
    pub rotation: Mat3,
    pub translation: Vec3,
    /// Beyond this normalised radius the lens folds back (see `Camera::injective_radius`).
    pub fold: f64,
    /// Whether points must be tested against `fold` (only lenses that fold).
    pub check_fold: bool,
    /// Normalised-coordinate bounds (x_min, x_max, y_min, y_max) of what the image can see,
    /// padded for splats; `None` when the lens sees to 90° or beyond (then only z culls).
    pub bounds: Option<[f32; 4]>,
    /// (fx, fy, cx, cy) in f32 for lenses without distortion, which project in f32.
    pub pinhole: Option<[f32; 4]>,
    /// The splat radius in output pixels that the bounds are padded for and `render` draws
    /// with: one value, so a view cannot be drawn with splats its culling did not allow for.
    radius: f32,
    /// `bounds` before padding, and one pixel in normalised units (1 / the smaller focal).
    unpadded: Option<[f64; 4]>,
    pixel: f64,
}

impl View {
    /// The view of `image` through `camera`, rendered at `width` × `height` with splats of
    /// `radius` output pixels, for a cloud re-centred on `origin`.
    pub fn new(
        image: &Image,
        camera: &Camera,
        origin: DVec3,
        width: u32,
        height: u32,
        radius: f32,
    ) -> View {
        let scale = DVec2::new(
            width as f64 / camera.width as f64,
            height as f64 / camera.height as f64,
        );
        let cam = camera.scaled(scale.x, scale.y, width as u64, height as u64);
        let local = image.cam_from_world.recentred(origin);
        let fold = cam.injective_radius();
        let check_fold = cam.model.has_distortion();
        // Bounds from rays through the image border (every 8 px and the corners).
        let mut rays = Vec::new();
        let (w, h) = (width as f64, height as f64);
        let step = 8.0;
        let mut t = 0.0;
        while t <= w {
            rays.push(DVec2::new(t, 0.0));
            rays.push(DVec2::new(t, h));
            t += step;
        }
        let mut t = 0.0;
        while t <= h {
            rays.push(DVec2::new(0.0, t));
            rays.push(DVec2::new(w, t));
            t += step;
        }
        rays.extend([DVec2::new(w, 0.0), DVec2::new(0.0, h), DVec2::new(w, h)]);
        let mut b = [
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::INFINITY,
            f64::NEG_INFINITY,
        ];
        let mut bounded = true;
        for px in rays {
            match cam.cam_ray_from_img(px) {
                Some(r) if r.z > 1e-3 => {
                    let (x, y) = (r.x / r.z, r.y / r.z);
                    b = [b[0].min(x), b[1].max(x), b[2].min(y), b[3].max(y)];
                }
                _ => bounded = false,
            }
        }
        let f = cam.focal();
        let pinhole = (!cam.model.has_distortion()).then(|| {
            let (f, c) = (cam.focal(), cam.principal_point());
            [f.x as f32, f.y as f32, c.x as f32, c.y as f32]
        });
        View {
            image_id: image.id,
            camera: cam,
            width,
            height,
            scale,
            rotation: local.matrix.as_mat3(),
            translation: local.translation.as_vec3(),
            fold,
            check_fold,
            bounds: None,
            pinhole,
            radius: 0.0,
            unpadded: bounded.then_some(b),
            pixel: 1.0 / f.x.min(f.y),
        }
        .padded_for(radius)
    }

    /// The same view drawn with splats of another radius (bounds padded anew).
    pub fn with_radius(&self, radius: f32) -> View {
        self.clone().padded_for(radius)
    }

    /// The splat radius this view is drawn with.
    pub fn radius(&self) -> f32 {
        self.radius
    }

    /// Pad the frustum bounds by the splat radius plus one pixel, in normalised units.
    fn padded_for(mut self, radius: f32) -> View {
        self.radius = radius.max(0.0);
        let pad = (self.radius as f64 + 1.0) * self.pixel;
        self.bounds = self.unpadded.map(|b| {
            [
                (b[0] - pad) as f32,
                (b[1] + pad) as f32,
                (b[2] - pad) as f32,
                (b[3] + pad) as f32,
            ]
        });
        self
    }

    /// Pixel of a local-frame point by the same steps the splatter takes (f32 transform,
    /// near plane, lens fold, the model's projection); `None` where it draws nothing.
    pub fn project(&self, local: Vec3, near: f32) -> Option<DVec2> {
        let c = self.rotation * local + self.translation;
        if c.z <= near {
            return None;
        }
        if let Some(k) = self.pinhole {
            let (x, y) = pinhole_pixel(k, c);
            return Some(DVec2::new(x as f64, y as f64));
        }
        let cd = DVec3::new(c.x as f64, c.y as f64, c.z as f64);
        if self.check_fold && self.camera.normalized_radius(cd) > self.fold {
            return None;
        }
        self.camera.img_from_cam(cd)
    }

    /// Whether a local-frame box may contain visible points (conservative).
    pub fn may_see(&self, min: Vec3, max: Vec3, near: f32) -> bool {
        let corners = [
            Vec3::new(min.x, min.y, min.z),
            Vec3::new(max.x, min.y, min.z),
            Vec3::new(min.x, max.y, min.z),
            Vec3::new(max.x, max.y, min.z),
            Vec3::new(min.x, min.y, max.z),
            Vec3::new(max.x, min.y, max.z),
            Vec3::new(min.x, max.y, max.z),
            Vec3::new(max.x, max.y, max.z),
        ]
        .map(|c| self.rotation * c + self.translation);
        if corners.iter().all(|c| c.z <= near) {
            return false;
        }
        let Some([x0, x1, y0, y1]) = self.bounds else {
            return true;
        };
        // Outside one side plane of the frustum (planes through the camera centre).
        !(corners.iter().all(|c| c.x > x1 * c.z)
            || corners.iter().all(|c| c.x < x0 * c.z)
            || corners.iter().all(|c| c.y > y1 * c.z)
            || corners.iter().all(|c| c.y < y0 * c.z))
    }
}
