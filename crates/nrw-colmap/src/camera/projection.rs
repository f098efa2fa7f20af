//! Each camera model's projection as COLMAP's `ImgFromCam` computes it, one zero-sized type
//! per model so that loops over many points monomorphise: a pinhole camera runs `f·x/z + c`
//! and nothing else.

use glam::{DVec2, DVec3};

/// A computation generic over the projection model; see [`Camera::visit_projection`].
pub trait ProjectionVisitor {
    type Output;
    /// Called once with the camera's model as `P` and its parameters.
    fn visit<P: Projection>(self, params: &[f64]) -> Self::Output;
}

/// One camera model's projection, implemented by a zero-sized type so loops monomorphise.
pub trait Projection {
    /// Camera-space point to pixel, exactly as COLMAP's `ImgFromCam`; `None` when undefined.
    fn project(params: &[f64], p: DVec3) -> Option<DVec2>;

    /// Whether `pixel` is straight-line arithmetic (no branch, no libm call), so that a loop
    /// over many points can run without per-point branches.
    const STRAIGHT: bool = false;

    /// `project`'s arithmetic without its checks: equal to `project`'s pixel wherever that is
    /// `Some` (z ≥ f64::EPSILON and a finite result); anything elsewhere.
    #[inline(always)]
    fn pixel(params: &[f64], p: DVec3) -> DVec2 {
        Self::project(params, p).unwrap_or(DVec2::NAN)
    }
}

/// `project` from `pixel` for the straight-line models: the same arithmetic, then the checks.
#[inline(always)]
fn checked<P: Projection>(params: &[f64], p: DVec3) -> Option<DVec2> {
    normalise(p)?;
    let q = P::pixel(params, p);
    finite(q.x, q.y)
}

/// Normalised image-plane coordinates, or `None` behind or on the camera plane.
#[inline(always)]
fn normalise(p: DVec3) -> Option<(f64, f64)> {
    // COLMAP rejects w < epsilon; NaN is rejected too (it compares as unordered).
    if p.z.partial_cmp(&f64::EPSILON)?.is_lt() {
        return None;
    }
    Some((p.x / p.z, p.y / p.z))
}

/// Finite pixel or `None`: a huge distortion polynomial can overflow, and overflow is not a pixel.
#[inline(always)]
fn finite(x: f64, y: f64) -> Option<DVec2> {
    (x.is_finite() && y.is_finite()).then_some(DVec2::new(x, y))
}

/// Equidistant fisheye angle coordinates from normalised ones (COLMAP's FisheyeFromNormal).
#[inline(always)]
fn fisheye_from_normal(u: f64, v: f64) -> (f64, f64) {
    let r = (u * u + v * v).sqrt();
    if r > f64::EPSILON {
        let s = r.atan() / r;
        (u * s, v * s)
    } else {
        (u, v)
    }
}

macro_rules! zst {
    ($($name:ident),*) => { $(
        #[doc = concat!("Projection of the `", stringify!($name), "` model.")]
        #[derive(Debug, Clone, Copy)]
        pub struct $name;
    )* };
}
zst!(
    SimplePinholeP,
    PinholeP,
    SimpleRadialP,
    RadialP,
    OpenCvP,
    OpenCvFisheyeP,
    FullOpenCvP,
    FovP,
    SimpleRadialFisheyeP,
    RadialFisheyeP,
    ThinPrismFisheyeP,
    RadTanThinPrismFisheyeP,
    SimpleDivisionP,
    DivisionP,
    SimpleFisheyeP,
    FisheyeP,
    EucmP,
    EquirectangularP
);

impl Projection for SimplePinholeP {
    #[inline(always)]
    fn project(p_: &[f64], p: DVec3) -> Option<DVec2> {
        let (u, v) = normalise(p)?;
        finite(p_[0] * u + p_[1], p_[0] * v + p_[2])
    }
}

impl Projection for PinholeP {
    #[inline(always)]
    fn project(p_: &[f64], p: DVec3) -> Option<DVec2> {
        let (u, v) = normalise(p)?;
        finite(p_[0] * u + p_[2], p_[1] * v + p_[3])
    }
}

impl Projection for SimpleRadialP {
    const STRAIGHT: bool = true;
    #[inline(always)]
    fn project(p_: &[f64], p: DVec3) -> Option<DVec2> {
        checked::<Self>(p_, p)
    }
    #[inline(always)]
    fn pixel(p_: &[f64], p: DVec3) -> DVec2 {
        let (u, v) = (p.x / p.z, p.y / p.z);
        let radial = p_[3] * (u * u + v * v);
        let (x, y) = (u + u * radial, v + v * radial);
        DVec2::new(p_[0] * x + p_[1], p_[0] * y + p_[2])
    }
}

impl Projection for RadialP {
    const STRAIGHT: bool = true;
    #[inline(always)]
    fn project(p_: &[f64], p: DVec3) -> Option<DVec2> {
        checked::<Self>(p_, p)
    }
    #[inline(always)]
    fn pixel(p_: &[f64], p: DVec3) -> DVec2 {
        let (u, v) = (p.x / p.z, p.y / p.z);
        let r2 = u * u + v * v;
        let radial = p_[3] * r2 + p_[4] * r2 * r2;
        let (x, y) = (u + u * radial, v + v * radial);
        DVec2::new(p_[0] * x + p_[1], p_[0] * y + p_[2])
    }
}

/// OpenCV radial-tangential distortion increments (k1, k2, p1, p2).
#[inline(always)]
fn opencv_delta(k1: f64, k2: f64, p1: f64, p2: f64, u: f64, v: f64) -> (f64, f64) {
    let (u2, uv, v2) = (u * u, u * v, v * v);
    let r2 = u2 + v2;
    let radial = k1 * r2 + k2 * r2 * r2;
    (
        u * radial + 2.0 * p1 * uv + p2 * (r2 + 2.0 * u2),
        v * radial + 2.0 * p2 * uv + p1 * (r2 + 2.0 * v2),
    )
}

impl Projection for OpenCvP {
    const STRAIGHT: bool = true;
    #[inline(always)]
    fn project(p_: &[f64], p: DVec3) -> Option<DVec2> {
        checked::<Self>(p_, p)
    }
    #[inline(always)]
    fn pixel(p_: &[f64], p: DVec3) -> DVec2 {
        let (u, v) = (p.x / p.z, p.y / p.z);
        let (du, dv) = opencv_delta(p_[4], p_[5], p_[6], p_[7], u, v);
        DVec2::new(p_[0] * (u + du) + p_[2], p_[1] * (v + dv) + p_[3])
    }
}

impl Projection for FullOpenCvP {
    #[inline(always)]
    fn project(p_: &[f64], p: DVec3) -> Option<DVec2> {
        let (u, v) = normalise(p)?;
        let (k1, k2, p1, p2, k3, k4, k5, k6) =
            (p_[4], p_[5], p_[6], p_[7], p_[8], p_[9], p_[10], p_[11]);
        let (u2, uv, v2) = (u * u, u * v, v * v);
        let r2 = u2 + v2;
        let r4 = r2 * r2;
        let r6 = r4 * r2;
        let radial = (1.0 + k1 * r2 + k2 * r4 + k3 * r6) / (1.0 + k4 * r2 + k5 * r4 + k6 * r6);
        let du = u * radial + 2.0 * p1 * uv + p2 * (r2 + 2.0 * u2) - u;
        let dv = v * radial + 2.0 * p2 * uv + p1 * (r2 + 2.0 * v2) - v;
        finite(p_[0] * (u + du) + p_[2], p_[1] * (v + dv) + p_[3])
    }
}

impl Projection for FovP {
    #[inline(always)]
    fn project(p_: &[f64], p: DVec3) -> Option<DVec2> {
        let (u, v) = normalise(p)?;
        let omega = p_[4];
        // COLMAP's switch points between the Taylor expansions and the closed form.
        const EPS: f64 = 1e-4;
        let radius2 = u * u + v * v;
        let omega2 = omega * omega;
        let factor = if omega2 < EPS {
            (omega2 * radius2) / 3.0 - omega2 / 12.0 + 1.0
        } else if radius2 < EPS {
            let t = (omega / 2.0).tan();
            (-2.0 * t * (4.0 * radius2 * t * t - 3.0)) / (3.0 * omega)
        } else {
            let radius = radius2.sqrt();
            (radius * 2.0 * (omega / 2.0).tan()).atan() / (radius * omega)
        };
        finite(p_[0] * (u * factor) + p_[2], p_[1] * (v * factor) + p_[3])
    }
}

impl Projection for OpenCvFisheyeP {
    #[inline(always)]
    fn project(p_: &[f64], p: DVec3) -> Option<DVec2> {
        let (u, v) = normalise(p)?;
        let (uu, vv) = fisheye_from_normal(u, v);
        let t2 = uu * uu + vv * vv;
        let t4 = t2 * t2;
        let radial = p_[4] * t2 + p_[5] * t4 + p_[6] * t4 * t2 + p_[7] * t4 * t4;
        finite(
            p_[0] * (uu + uu * radial) + p_[2],
            p_[1] * (vv + vv * radial) + p_[3],
        )
    }
}

impl Projection for SimpleRadialFisheyeP {
    #[inline(always)]
    fn project(p_: &[f64], p: DVec3) -> Option<DVec2> {
        let (u, v) = normalise(p)?;
        let (uu, vv) = fisheye_from_normal(u, v);
        let radial = p_[3] * (uu * uu + vv * vv);
        finite(
            p_[0] * (uu + uu * radial) + p_[1],
            p_[0] * (vv + vv * radial) + p_[2],
        )
    }
}

impl Projection for RadialFisheyeP {
    #[inline(always)]
    fn project(p_: &[f64], p: DVec3) -> Option<DVec2> {
        let (u, v) = normalise(p)?;
        let (uu, vv) = fisheye_from_normal(u, v);
        let t2 = uu * uu + vv * vv;
        let radial = p_[3] * t2 + p_[4] * t2 * t2;
        finite(
            p_[0] * (uu + uu * radial) + p_[1],
            p_[0] * (vv + vv * radial) + p_[2],
        )
    }
}

impl Projection for ThinPrismFisheyeP {
    #[inline(always)]
    fn project(p_: &[f64], p: DVec3) -> Option<DVec2> {
        let (u, v) = normalise(p)?;
        let (uu, vv) = fisheye_from_normal(u, v);
        let (k1, k2, p1, p2, k3, k4, sx1, sy1) =
            (p_[4], p_[5], p_[6], p_[7], p_[8], p_[9], p_[10], p_[11]);
        let (u2, uv, v2) = (uu * uu, uu * vv, vv * vv);
        let r2 = u2 + v2;
        let r4 = r2 * r2;
        let r6 = r4 * r2;
        let r8 = r6 * r2;
        let radial = k1 * r2 + k2 * r4 + k3 * r6 + k4 * r8;
        let du = uu * radial + 2.0 * p1 * uv + p2 * (r2 + 2.0 * u2) + sx1 * r2;
        let dv = vv * radial + 2.0 * p2 * uv + p1 * (r2 + 2.0 * v2) + sy1 * r2;
        finite(p_[0] * (uu + du) + p_[2], p_[1] * (vv + dv) + p_[3])
    }
}

impl Projection for RadTanThinPrismFisheyeP {
    #[inline(always)]
    fn project(p_: &[f64], p: DVec3) -> Option<DVec2> {
        let (u, v) = normalise(p)?;
        let (uu, vv) = fisheye_from_normal(u, v);
        let e = &p_[4..16];
        let theta2 = uu * uu + vv * vv;
        let mut th_radial = 1.0;
        let mut power = 1.0;
        for k in &e[..6] {
            power *= theta2;
            th_radial += k * power;
        }
        let (p0, p1, s0, s1, s2, s3) = (e[6], e[7], e[8], e[9], e[10], e[11]);
        let x = th_radial * uu;
        let y = th_radial * vv;
        let (x2, y2, xy) = (x * x, y * y, x * y);
        let r2 = x2 + y2;
        let r4 = r2 * r2;
        let xd = x + (2.0 * p1 * xy + p0 * (r2 + 2.0 * x2)) + (s0 * r2 + s1 * r4);
        let yd = y + (2.0 * p0 * xy + p1 * (r2 + 2.0 * y2)) + (s2 * r2 + s3 * r4);
        // COLMAP forms du = xd - uu and then adds uu back; kept for bit-level parity.
        let (du, dv) = (xd - uu, yd - vv);
        finite(p_[0] * (uu + du) + p_[2], p_[1] * (vv + dv) + p_[3])
    }
}

impl Projection for SimpleFisheyeP {
    #[inline(always)]
    fn project(p_: &[f64], p: DVec3) -> Option<DVec2> {
        let (u, v) = normalise(p)?;
        let (uu, vv) = fisheye_from_normal(u, v);
        finite(p_[0] * uu + p_[1], p_[0] * vv + p_[2])
    }
}

impl Projection for FisheyeP {
    #[inline(always)]
    fn project(p_: &[f64], p: DVec3) -> Option<DVec2> {
        let (u, v) = normalise(p)?;
        let (uu, vv) = fisheye_from_normal(u, v);
        finite(p_[0] * uu + p_[2], p_[1] * vv + p_[3])
    }
}

/// Fitzgibbon's one-parameter division model as COLMAP 4.2 projects it, on the camera point
/// as given (not its normalised coordinates): the smaller root of `ρ k r² − w r + ρ = 0`, or
/// `None` where the discriminant is negative (k > 0 past the fold). COLMAP's division models
/// ignore cheirality and project points behind the camera too; here, as for every other
/// perspective model, a point with z < ε is not visible (no photo shows it).
#[inline(always)]
fn division(f: DVec2, c: DVec2, k: f64, p: DVec3) -> Option<DVec2> {
    normalise(p)?;
    let (u, v, w) = (p.x, p.y, p.z);
    let rho = (u * u + v * v).sqrt();
    let disc_sq = w * w - 4.0 * rho * rho * k;
    if disc_sq < 0.0 {
        return None;
    }
    let r = 2.0 / (w + disc_sq.sqrt());
    finite(f.x * r * u + c.x, f.y * r * v + c.y)
}

impl Projection for SimpleDivisionP {
    #[inline(always)]
    fn project(p_: &[f64], p: DVec3) -> Option<DVec2> {
        division(DVec2::splat(p_[0]), DVec2::new(p_[1], p_[2]), p_[3], p)
    }
}

impl Projection for DivisionP {
    #[inline(always)]
    fn project(p_: &[f64], p: DVec3) -> Option<DVec2> {
        division(DVec2::new(p_[0], p_[1]), DVec2::new(p_[2], p_[3]), p_[4], p)
    }
}

impl Projection for EucmP {
    /// The Enhanced Unified Camera Model (Khomutenko, Garcia and Martinet) as COLMAP 4.2
    /// projects it: `den = α·sqrt(β(u² + v²) + w²) + (1 − α)·w`, both w and den at least ε.
    #[inline(always)]
    fn project(p_: &[f64], p: DVec3) -> Option<DVec2> {
        normalise(p)?;
        let (u, v, w) = (p.x, p.y, p.z);
        let (alpha, beta) = (p_[4], p_[5]);
        let rho2 = beta * (u * u + v * v) + w * w;
        if rho2 < 0.0 {
            return None;
        }
        let den = alpha * rho2.sqrt() + (1.0 - alpha) * w;
        if den.partial_cmp(&f64::EPSILON)?.is_lt() {
            return None;
        }
        finite(p_[0] * (u / den) + p_[2], p_[1] * (v / den) + p_[3])
    }
}

impl Projection for EquirectangularP {
    /// COLMAP 4.2's 360° panorama: azimuth from +z across the width, elevation (up is −y)
    /// down the height; every direction but the zero vector projects, behind the camera too.
    #[inline(always)]
    fn project(p_: &[f64], p: DVec3) -> Option<DVec2> {
        use std::f64::consts::PI;
        let (u, v, w) = (p.x, p.y, p.z);
        let horizontal = (u * u + w * w).sqrt();
        if (horizontal + v.abs()).partial_cmp(&f64::EPSILON)?.is_lt() {
            return None;
        }
        let theta = u.atan2(w);
        let phi = (-v).atan2(horizontal);
        finite((theta / (2.0 * PI) + 0.5) * p_[0], (0.5 - phi / PI) * p_[1])
    }
}

/// The unit ray of a panorama's pixel (COLMAP 4.2's `CamRayFromImg` for EQUIRECTANGULAR):
/// every pixel has one, behind the camera included.
pub(super) fn equirectangular_ray(p_: &[f64], px: DVec2) -> Option<DVec3> {
    use std::f64::consts::PI;
    let theta = 2.0 * PI * (px.x / p_[0] - 0.5);
    let phi = PI * (0.5 - px.y / p_[1]);
    let ray = DVec3::new(phi.cos() * theta.sin(), -phi.sin(), phi.cos() * theta.cos());
    ray.is_finite().then_some(ray)
}
