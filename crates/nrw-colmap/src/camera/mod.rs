//! COLMAP's camera models, with its exact camera→pixel projection in f64.
//!
//! Each model is a zero-sized type implementing [`Projection`]; [`Camera::project_many`]
//! matches on the model once per batch and then runs a monomorphised loop, so a pinhole
//! camera runs `f·x/z + c` and nothing else: models without distortion pay for none.
//!
//! Conventions follow COLMAP: the upper-left pixel's centre is (0.5, 0.5); a point with
//! camera-space z below `f64::EPSILON` is not visible (this also bounds fisheye models to
//! the forward hemisphere, i.e. incidence angles below 90°).

use glam::{DVec2, DVec3};

mod projection;

pub use projection::*;

/// The camera models COLMAP defines that this crate projects; ids are COLMAP's.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum CameraModel {
    SimplePinhole,
    Pinhole,
    SimpleRadial,
    Radial,
    OpenCv,
    OpenCvFisheye,
    FullOpenCv,
    Fov,
    SimpleRadialFisheye,
    RadialFisheye,
    ThinPrismFisheye,
    RadTanThinPrismFisheye,
    SimpleDivision,
    Division,
    SimpleFisheye,
    Fisheye,
    Eucm,
    Equirectangular,
}

impl CameraModel {
    /// Every supported model, in COLMAP id order.
    pub const ALL: [CameraModel; 18] = [
        CameraModel::SimplePinhole,
        CameraModel::Pinhole,
        CameraModel::SimpleRadial,
        CameraModel::Radial,
        CameraModel::OpenCv,
        CameraModel::OpenCvFisheye,
        CameraModel::FullOpenCv,
        CameraModel::Fov,
        CameraModel::SimpleRadialFisheye,
        CameraModel::RadialFisheye,
        CameraModel::ThinPrismFisheye,
        CameraModel::RadTanThinPrismFisheye,
        CameraModel::SimpleDivision,
        CameraModel::Division,
        CameraModel::SimpleFisheye,
        CameraModel::Fisheye,
        CameraModel::Eucm,
        CameraModel::Equirectangular,
    ];

    /// COLMAP's numeric model id, as stored in cameras.bin.
    pub fn id(self) -> i32 {
        match self {
            CameraModel::SimplePinhole => 0,
            CameraModel::Pinhole => 1,
            CameraModel::SimpleRadial => 2,
            CameraModel::Radial => 3,
            CameraModel::OpenCv => 4,
            CameraModel::OpenCvFisheye => 5,
            CameraModel::FullOpenCv => 6,
            CameraModel::Fov => 7,
            CameraModel::SimpleRadialFisheye => 8,
            CameraModel::RadialFisheye => 9,
            CameraModel::ThinPrismFisheye => 10,
            CameraModel::RadTanThinPrismFisheye => 11,
            CameraModel::SimpleDivision => 12,
            CameraModel::Division => 13,
            CameraModel::SimpleFisheye => 14,
            CameraModel::Fisheye => 15,
            CameraModel::Eucm => 16,
            CameraModel::Equirectangular => 17,
        }
    }

    /// The model for a cameras.bin id; `None` for ids COLMAP does not define or we do not project.
    pub fn from_id(id: i32) -> Option<CameraModel> {
        CameraModel::ALL.into_iter().find(|m| m.id() == id)
    }

    /// COLMAP's model name, as written in cameras.txt.
    pub fn name(self) -> &'static str {
        match self {
            CameraModel::SimplePinhole => "SIMPLE_PINHOLE",
            CameraModel::Pinhole => "PINHOLE",
            CameraModel::SimpleRadial => "SIMPLE_RADIAL",
            CameraModel::Radial => "RADIAL",
            CameraModel::OpenCv => "OPENCV",
            CameraModel::OpenCvFisheye => "OPENCV_FISHEYE",
            CameraModel::FullOpenCv => "FULL_OPENCV",
            CameraModel::Fov => "FOV",
            CameraModel::SimpleRadialFisheye => "SIMPLE_RADIAL_FISHEYE",
            CameraModel::RadialFisheye => "RADIAL_FISHEYE",
            CameraModel::ThinPrismFisheye => "THIN_PRISM_FISHEYE",
            CameraModel::RadTanThinPrismFisheye => "RAD_TAN_THIN_PRISM_FISHEYE",
            CameraModel::SimpleDivision => "SIMPLE_DIVISION",
            CameraModel::Division => "DIVISION",
            CameraModel::SimpleFisheye => "SIMPLE_FISHEYE",
            CameraModel::Fisheye => "FISHEYE",
            CameraModel::Eucm => "EUCM",
            CameraModel::Equirectangular => "EQUIRECTANGULAR",
        }
    }

    /// The model for a cameras.txt name.
    pub fn from_name(name: &str) -> Option<CameraModel> {
        CameraModel::ALL.into_iter().find(|m| m.name() == name)
    }

    /// Parameter names in file order, so errors and tables can name them.
    pub fn param_names(self) -> &'static [&'static str] {
        match self {
            CameraModel::SimplePinhole | CameraModel::SimpleFisheye => &["f", "cx", "cy"],
            CameraModel::Pinhole | CameraModel::Fisheye => &["fx", "fy", "cx", "cy"],
            CameraModel::SimpleRadial
            | CameraModel::SimpleRadialFisheye
            | CameraModel::SimpleDivision => &["f", "cx", "cy", "k"],
            CameraModel::Division => &["fx", "fy", "cx", "cy", "k"],
            CameraModel::Eucm => &["fx", "fy", "cx", "cy", "alpha", "beta"],
            // COLMAP 4.2 spells them "w,h": the panorama's size, its only parameters.
            CameraModel::Equirectangular => &["w", "h"],
            CameraModel::Radial | CameraModel::RadialFisheye => &["f", "cx", "cy", "k1", "k2"],
            CameraModel::OpenCv => &["fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2"],
            CameraModel::OpenCvFisheye => &["fx", "fy", "cx", "cy", "k1", "k2", "k3", "k4"],
            CameraModel::FullOpenCv => &[
                "fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6",
            ],
            CameraModel::Fov => &["fx", "fy", "cx", "cy", "omega"],
            CameraModel::ThinPrismFisheye => &[
                "fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3", "k4", "sx1", "sy1",
            ],
            CameraModel::RadTanThinPrismFisheye => &[
                "fx", "fy", "cx", "cy", "k0", "k1", "k2", "k3", "k4", "k5", "p0", "p1", "s0", "s1",
                "s2", "s3",
            ],
        }
    }

    /// How many parameters a camera of this model stores.
    pub fn num_params(self) -> usize {
        self.param_names().len()
    }

    /// Whether the model has a single focal length (f) rather than fx, fy.
    pub fn single_focal(self) -> bool {
        self.param_names()[0] == "f"
    }

    /// Whether the model maps incidence angle (not its tangent) to image radius.
    pub fn is_fisheye(self) -> bool {
        matches!(
            self,
            CameraModel::OpenCvFisheye
                | CameraModel::SimpleRadialFisheye
                | CameraModel::RadialFisheye
                | CameraModel::ThinPrismFisheye
                | CameraModel::RadTanThinPrismFisheye
                | CameraModel::SimpleFisheye
                | CameraModel::Fisheye
        )
    }

    /// Whether the model sees the whole sphere (COLMAP's `IsSpherical`): it has no focal
    /// length or principal point, projects points behind the camera too, and COLMAP's
    /// undistorter refuses it (`camera.IsPerspective()`), so no pinhole view is made of it.
    pub fn is_spherical(self) -> bool {
        self == CameraModel::Equirectangular
    }

    /// Whether projecting through this model does more than `f·x/z + c`.
    pub fn has_distortion(self) -> bool {
        !matches!(self, CameraModel::SimplePinhole | CameraModel::Pinhole)
    }
}

impl std::fmt::Display for CameraModel {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// Run `$body` with `$m` bound to the zero-sized projection type of `$model`.
macro_rules! dispatch {
    ($model:expr, $m:ident => $body:expr) => {
        match $model {
            CameraModel::SimplePinhole => {
                type $m = SimplePinholeP;
                $body
            }
            CameraModel::Pinhole => {
                type $m = PinholeP;
                $body
            }
            CameraModel::SimpleRadial => {
                type $m = SimpleRadialP;
                $body
            }
            CameraModel::Radial => {
                type $m = RadialP;
                $body
            }
            CameraModel::OpenCv => {
                type $m = OpenCvP;
                $body
            }
            CameraModel::OpenCvFisheye => {
                type $m = OpenCvFisheyeP;
                $body
            }
            CameraModel::FullOpenCv => {
                type $m = FullOpenCvP;
                $body
            }
            CameraModel::Fov => {
                type $m = FovP;
                $body
            }
            CameraModel::SimpleRadialFisheye => {
                type $m = SimpleRadialFisheyeP;
                $body
            }
            CameraModel::RadialFisheye => {
                type $m = RadialFisheyeP;
                $body
            }
            CameraModel::ThinPrismFisheye => {
                type $m = ThinPrismFisheyeP;
                $body
            }
            CameraModel::RadTanThinPrismFisheye => {
                type $m = RadTanThinPrismFisheyeP;
                $body
            }
            CameraModel::SimpleDivision => {
                type $m = SimpleDivisionP;
                $body
            }
            CameraModel::Division => {
                type $m = DivisionP;
                $body
            }
            CameraModel::SimpleFisheye => {
                type $m = SimpleFisheyeP;
                $body
            }
            CameraModel::Fisheye => {
                type $m = FisheyeP;
                $body
            }
            CameraModel::Eucm => {
                type $m = EucmP;
                $body
            }
            CameraModel::Equirectangular => {
                type $m = EquirectangularP;
                $body
            }
        }
    };
}

/// A calibrated camera as COLMAP stores it.
#[derive(Debug, Clone, PartialEq)]
pub struct Camera {
    pub id: u32,
    pub model: CameraModel,
    pub width: u64,
    pub height: u64,
    /// Parameters in COLMAP's order (see [`CameraModel::param_names`]); length is checked on read.
    pub params: Vec<f64>,
}

impl Camera {
    /// Project a camera-space point to pixels; `None` where COLMAP's projection is undefined.
    #[inline]
    pub fn img_from_cam(&self, p: DVec3) -> Option<DVec2> {
        dispatch!(self.model, M => M::project(&self.params, p))
    }

    /// Run `v` with this camera's projection as a type parameter, so a caller's hot loop is
    /// monomorphised per model (a pinhole loop then contains no distortion code at all).
    pub fn visit_projection<V: ProjectionVisitor>(&self, v: V) -> V::Output {
        dispatch!(self.model, M => v.visit::<M>(&self.params))
    }

    /// Project many points, matching on the model once for the whole batch.
    pub fn project_many(&self, points: &[DVec3], out: &mut Vec<Option<DVec2>>) {
        out.clear();
        out.reserve(points.len());
        let params = self.params.as_slice();
        dispatch!(self.model, M => out.extend(points.iter().map(|&p| M::project(params, p))))
    }

    /// Unit ray in the camera frame whose projection is `px`; `None` where no ray projects there.
    ///
    /// Pinhole models invert in closed form. Every other model is inverted by Newton's method
    /// on this crate's own forward projection (numeric Jacobian, bounded steps), so the ray is
    /// exactly consistent with [`Camera::img_from_cam`]: the result reprojects to within
    /// 1e-6 px or `None` is returned (e.g. beyond the fold of a strong radial distortion, or
    /// past a fisheye's 90°).
    pub fn cam_ray_from_img(&self, px: DVec2) -> Option<DVec3> {
        if self.model.is_spherical() {
            return equirectangular_ray(&self.params, px);
        }
        let mut guess = (px - self.principal_point()) / self.focal();
        if let Some(k) = self.division_k() {
            // COLMAP's closed-form lift: the distorted guess may lie past the fold (k > 0),
            // where the projection Newton needs is undefined; this one is the answer.
            guess /= 1.0 + k * guess.length_squared();
        }
        if !self.model.has_distortion() {
            return Some(DVec3::new(guess.x, guess.y, 1.0).normalize());
        }
        let fisheye = self.model.is_fisheye();
        // Unknowns: normalised image-plane coordinates, or angle coordinates for fisheye
        // models (|q| = incidence angle), which stay finite up to 90°.
        let dir = |q: DVec2| -> Option<DVec3> {
            if !fisheye {
                return Some(DVec3::new(q.x, q.y, 1.0));
            }
            let theta = q.length();
            if theta >= std::f64::consts::FRAC_PI_2 {
                return None;
            }
            if theta < 1e-12 {
                return Some(DVec3::new(q.x, q.y, 1.0));
            }
            let s = theta.sin() / theta;
            Some(DVec3::new(q.x * s, q.y * s, theta.cos()))
        };
        let mut q = if fisheye {
            let r = guess.length();
            if r > 1e-12 {
                guess * (r.atan() / r)
            } else {
                guess
            }
        } else {
            guess
        };
        for _ in 0..100 {
            let d = dir(q)?;
            let p = self.img_from_cam(d)?;
            let r = p - px;
            if r.length() < 1e-10 * (1.0 + px.length()) {
                break;
            }
            let h = 1e-7 * (1.0 + q.length());
            let jx = (self.img_from_cam(dir(q + DVec2::new(h, 0.0))?)? - p) / h;
            let jy = (self.img_from_cam(dir(q + DVec2::new(0.0, h))?)? - p) / h;
            let det = jx.x * jy.y - jx.y * jy.x;
            if det.is_nan() || det.abs() <= 1e-300 {
                return None;
            }
            let mut step = DVec2::new(jy.y * r.x - jy.x * r.y, -jx.y * r.x + jx.x * r.y) / det;
            // Trust region, as COLMAP's undistortion: at most 10% of |q| or 0.1 per step.
            let max = (0.1 * q.length()).max(0.1);
            if step.length() > max {
                step *= max / step.length();
            }
            q -= step;
        }
        let d = dir(q)?;
        let back = self.img_from_cam(d)?;
        ((back - px).length() < 1e-6).then(|| d.normalize())
    }

    /// A division lens's k (SIMPLE_DIVISION, DIVISION), None for every other model.
    fn division_k(&self) -> Option<f64> {
        match self.model {
            CameraModel::SimpleDivision => Some(self.params[3]),
            CameraModel::Division => Some(self.params[4]),
            _ => None,
        }
    }

    /// The radius, in normalised coordinates (tan of the incidence angle; for fisheye models
    /// the angle itself), up to which projection is one-to-one in every direction.
    ///
    /// A radial polynomial with a negative k folds back: points far off-axis project onto
    /// pixels that belong to other, in-view directions. COLMAP's projection returns those
    /// pixels; a renderer must not splat them. Found by scanning 16 directions (4096 steps up
    /// to 89.4° off-axis) for the first radius where the image radius stops growing; costs
    /// about a millisecond, so compute it once per camera.
    pub fn injective_radius(&self) -> f64 {
        let fisheye = self.model.is_fisheye();
        let r_max = if fisheye {
            std::f64::consts::FRAC_PI_2 * 0.9999
        } else {
            100.0
        };
        if !self.model.has_distortion() {
            return r_max;
        }
        let pp = self.principal_point();
        const STEPS: usize = 4096;
        let mut limit = r_max;
        for k in 0..16 {
            let phi = k as f64 * std::f64::consts::TAU / 16.0;
            let (s, c) = phi.sin_cos();
            let mut prev = 0.0;
            for i in 1..=STEPS {
                let r = r_max * i as f64 / STEPS as f64;
                if r >= limit {
                    break;
                }
                let p = if fisheye {
                    DVec3::new(r.sin() * c, r.sin() * s, r.cos())
                } else {
                    DVec3::new(r * c, r * s, 1.0)
                };
                let rad = match self.img_from_cam(p) {
                    Some(px) => (px - pp).length(),
                    None => f64::NAN,
                };
                if rad.is_nan() || rad <= prev {
                    limit = limit.min(r_max * (i - 1) as f64 / STEPS as f64);
                    break;
                }
                prev = rad;
            }
        }
        limit
    }

    /// Normalised radius of a camera-space point in the units of [`Camera::injective_radius`].
    #[inline]
    pub fn normalized_radius(&self, p: DVec3) -> f64 {
        let r = (p.x * p.x + p.y * p.y).sqrt() / p.z;
        if self.model.is_fisheye() {
            r.atan()
        } else {
            r
        }
    }

    /// Focal lengths (fx, fy); models with one focal length return it twice.
    pub fn focal(&self) -> DVec2 {
        if self.model.is_spherical() {
            // No focal length: the angular resolution, pixels per radian along each axis.
            return DVec2::new(
                self.params[0] / std::f64::consts::TAU,
                self.params[1] / std::f64::consts::PI,
            );
        }
        if self.model.single_focal() {
            DVec2::splat(self.params[0])
        } else {
            DVec2::new(self.params[0], self.params[1])
        }
    }

    /// Principal point (cx, cy) in pixels.
    pub fn principal_point(&self) -> DVec2 {
        if self.model.is_spherical() {
            // No principal point: the pixel the forward axis projects to.
            return DVec2::new(self.params[0], self.params[1]) * 0.5;
        }
        let i = if self.model.single_focal() { 1 } else { 2 };
        DVec2::new(self.params[i], self.params[i + 1])
    }

    /// The same lens on an image resized by (sx, sy): focal and principal point scale, distortion does not.
    ///
    /// With one focal length COLMAP scales f by the mean of sx and sy; resizing with equal
    /// factors keeps that exact.
    pub fn scaled(&self, sx: f64, sy: f64, width: u64, height: u64) -> Camera {
        let mut params = self.params.clone();
        if self.model.is_spherical() {
            // Its parameters are its size.
            params = vec![width as f64, height as f64];
        } else if self.model.single_focal() {
            params[0] *= 0.5 * (sx + sy);
            params[1] *= sx;
            params[2] *= sy;
        } else {
            params[0] *= sx;
            params[1] *= sy;
            params[2] *= sx;
            params[3] *= sy;
        }
        Camera {
            id: self.id,
            model: self.model,
            width,
            height,
            params,
        }
    }
}

#[cfg(test)]
mod tests;
