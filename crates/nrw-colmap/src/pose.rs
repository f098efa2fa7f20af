//! Rigid world→camera transforms in f64, and their re-centring for scenes far from the origin.

use glam::{DMat3, DQuat, DVec3};

/// A world→camera rigid transform: x_cam = R · x_world + t (COLMAP's `cam_from_world`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Rigid3 {
    /// Unit quaternion (normalised on read).
    pub rotation: DQuat,
    pub translation: DVec3,
}

/// How far a stored quaternion's norm may stray from 1 before we say we normalised it.
pub const QUAT_NORM_TOLERANCE: f64 = 1e-6;

impl Rigid3 {
    /// The identity transform.
    pub const IDENTITY: Rigid3 = Rigid3 {
        rotation: DQuat::IDENTITY,
        translation: DVec3::ZERO,
    };

    /// Build from COLMAP's (qw, qx, qy, qz) and t, normalising the quaternion.
    ///
    /// Returns the transform and the stored quaternion's norm; `None` if the norm is zero or
    /// not finite, where no rotation can be recovered.
    pub fn from_colmap(q: [f64; 4], t: [f64; 3]) -> Option<(Rigid3, f64)> {
        let norm = (q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]).sqrt();
        if !(norm.is_finite() && norm > 0.0) {
            return None;
        }
        let rotation = DQuat::from_xyzw(q[1] / norm, q[2] / norm, q[3] / norm, q[0] / norm);
        Some((
            Rigid3 {
                rotation,
                translation: DVec3::from_array(t),
            },
            norm,
        ))
    }

    /// COLMAP's (qw, qx, qy, qz) order.
    pub fn qvec(&self) -> [f64; 4] {
        let q = self.rotation;
        [q.w, q.x, q.y, q.z]
    }

    /// Rotation matrix R.
    pub fn matrix(&self) -> DMat3 {
        DMat3::from_quat(self.rotation)
    }

    /// Apply to a world point.
    pub fn transform(&self, p: DVec3) -> DVec3 {
        self.matrix() * p + self.translation
    }

    /// The camera centre in world coordinates, C = −Rᵀ t.
    pub fn centre(&self) -> DVec3 {
        -(self.matrix().transpose() * self.translation)
    }

    /// Composition `self ∘ other` (apply `other` first).
    pub fn compose(&self, other: &Rigid3) -> Rigid3 {
        Rigid3 {
            rotation: (self.rotation * other.rotation).normalize(),
            translation: self.matrix() * other.translation + self.translation,
        }
    }

    /// The same transform for points expressed relative to `origin`: x_cam = R · (x − o) + t_o.
    ///
    /// t_o = t + R·o is where a naive evaluation loses digits for georeferenced scenes (R·o
    /// and t are both ~10⁶ and cancel), so it is summed with error-free transformations
    /// (FMA two-product, two-sum): t_o is correct to about one ulp of its own, small, size.
    /// Callers then subtract `origin` from points in f64, which is exact for points within a
    /// factor of two of it, and only then may cast to f32.
    pub fn recentred(&self, origin: DVec3) -> LocalRigid3 {
        let r = self.matrix();
        let rows = r.transpose(); // columns of Rᵀ are the rows of R
        let t = self.translation;
        LocalRigid3 {
            matrix: r,
            translation: DVec3::new(
                dot3_plus(rows.x_axis, origin, t.x),
                dot3_plus(rows.y_axis, origin, t.y),
                dot3_plus(rows.z_axis, origin, t.z),
            ),
        }
    }
}

/// A world→camera transform for points already shifted by a scene origin.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LocalRigid3 {
    pub matrix: DMat3,
    pub translation: DVec3,
}

impl LocalRigid3 {
    /// Apply to a point given relative to the origin this transform was made for.
    #[inline]
    pub fn transform(&self, local: DVec3) -> DVec3 {
        self.matrix * local + self.translation
    }
}

#[inline]
fn two_sum(a: f64, b: f64) -> (f64, f64) {
    let s = a + b;
    let bb = s - a;
    (s, (a - (s - bb)) + (b - bb))
}

/// a·b + c with compensated summation (Ogita–Rump–Oishi Dot2); about twice f64's precision.
pub fn dot3_plus(a: DVec3, b: DVec3, c: f64) -> f64 {
    let mut s = c;
    let mut err = 0.0;
    for (x, y) in [(a.x, b.x), (a.y, b.y), (a.z, b.z)] {
        let p = x * y;
        let pe = x.mul_add(y, -p);
        let (s2, se) = two_sum(s, p);
        s = s2;
        err += pe + se;
    }
    s + err
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unnormalised_quaternion_is_normalised_and_reported() {
        let (r, norm) = Rigid3::from_colmap([2.0, 0.0, 0.0, 0.0], [1.0, 2.0, 3.0]).unwrap();
        assert_eq!(norm, 2.0);
        assert_eq!(r.rotation, DQuat::IDENTITY);
        assert!(Rigid3::from_colmap([0.0; 4], [0.0; 3]).is_none());
        assert!(Rigid3::from_colmap([f64::NAN, 0.0, 0.0, 1.0], [0.0; 3]).is_none());
    }

    #[test]
    fn centre_inverts_translation() {
        let (r, _) = Rigid3::from_colmap([0.9, 0.1, -0.3, 0.2], [1.0, -2.0, 0.5]).unwrap();
        assert!(r.transform(r.centre()).length() < 1e-12);
    }

    #[test]
    fn recentring_keeps_digits_far_from_origin() {
        // A camera 5·10⁶ m from the origin and points a few metres in front of it. The
        // reference is R·p + t evaluated with compensated sums (≈ 1 ulp of the small result).
        let (rot, _) = Rigid3::from_colmap([0.9, 0.1, -0.3, 0.2], [0.0; 3]).unwrap();
        let r = rot.matrix();
        let rows = r.transpose();
        let centre = DVec3::new(5.0e6 + 0.125, 5.0e6 + 0.5, 5.0e6 + 0.25);
        let t = -(r * centre);
        let pose = Rigid3 {
            rotation: rot.rotation,
            translation: t,
        };
        let origin = DVec3::new(5.0e6, 5.0e6, 5.0e6);
        let local = pose.recentred(origin);
        let (mut worst_local, mut worst_naive) = (0.0f64, 0.0f64);
        for k in 0..100 {
            let p = centre
                + r.transpose() * DVec3::new(0.01 * k as f64 - 0.5, 0.3, 3.0 + 0.01 * k as f64);
            let exact = DVec3::new(
                dot3_plus(rows.x_axis, p, t.x),
                dot3_plus(rows.y_axis, p, t.y),
                dot3_plus(rows.z_axis, p, t.z),
            );
            worst_local = worst_local.max((local.transform(p - origin) - exact).length());
            worst_naive = worst_naive.max((pose.transform(p) - exact).length());
        }
        assert!(worst_local < 1e-14, "re-centred error {worst_local:e}");
        assert!(
            worst_naive > 1e-11,
            "the naive path should visibly lose digits: {worst_naive:e}"
        );
    }
}
