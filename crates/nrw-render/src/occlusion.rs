//! Occlusion culling: a chunk whose every reachable pixel already holds a point nearer than
//! any of its own is skipped whole, projection and drawing. Chunks are drawn front to back so
//! that near surfaces fill the z-buffer before the chunks they hide come up. Renders are
//! unchanged: a skipped point would have lost the z-test at every pixel it reaches.

use glam::DVec3;
use nrw_colmap::CameraModel;

use crate::cloud::Chunk;
use crate::view::View;
use crate::zbuffer::{key, ZBuffer};

/// Screen rectangles larger than this many pixels are not scanned: the scan would cost
/// about what drawing the chunk does.
const MAX_SCAN: i64 = 1 << 16;

/// Relative error bound, with a wide margin, of a point's f32 camera-space coordinates: a
/// few roundings of terms up to |R p| + |t| (≈ 2.4·10⁻⁷ of that; 16× here). It also covers
/// the f32 roundings of an undistorted pixel (`view::pinhole_pixel`).
const F32_ERROR: f64 = 4e-6;

/// The lenses whose image of a box can be bounded cheaply: undistorted ones, and the radial
/// ones COLMAP gives internet photos (SIMPLE_RADIAL, RADIAL). Others are never culled.
#[derive(Debug, Clone, Copy)]
pub(crate) enum Lens {
    Pinhole {
        f: [f64; 2],
        c: [f64; 2],
    },
    /// Pixel = f · u (1 + k1 r² + k2 r⁴) + c, u normalised, r² = u² + v².
    Radial {
        f: f64,
        c: [f64; 2],
        k: [f64; 2],
    },
}

impl Lens {
    /// The view's lens, when it is one of those.
    pub(crate) fn of(v: &View) -> Option<Lens> {
        if let Some(k) = v.pinhole {
            // The f32 values the points are projected with.
            let k = k.map(|k| k as f64);
            return Some(Lens::Pinhole {
                f: [k[0], k[1]],
                c: [k[2], k[3]],
            });
        }
        let p = &v.camera.params;
        match v.camera.model {
            CameraModel::SimpleRadial => Some(Lens::Radial {
                f: p[0],
                c: [p[1], p[2]],
                k: [p[3], 0.0],
            }),
            CameraModel::Radial => Some(Lens::Radial {
                f: p[0],
                c: [p[1], p[2]],
                k: [p[3], p[4]],
            }),
            _ => None,
        }
    }

    /// Pixel bounds (x0, x1, y0, y1) of every point whose normalised coordinates lie in
    /// `[u0, u1] × [v0, v1]` (focal lengths are positive).
    fn image(&self, [u0, u1, v0, v1]: [f64; 4]) -> [f64; 4] {
        match *self {
            Lens::Pinhole { f, c } => [
                f[0] * u0 + c[0],
                f[0] * u1 + c[0],
                f[1] * v0 + c[1],
                f[1] * v1 + c[1],
            ],
            Lens::Radial { f, c, k } => {
                // The radial factor over the rectangle's range of r², then interval products.
                let sq = |a: f64, b: f64| {
                    let lo = if a <= 0.0 && b >= 0.0 {
                        0.0
                    } else {
                        (a * a).min(b * b)
                    };
                    (lo, (a * a).max(b * b))
                };
                let ((su0, su1), (sv0, sv1)) = (sq(u0, u1), sq(v0, v1));
                let (s0, s1) = (su0 + sv0, su1 + sv1);
                let d = |s: f64| 1.0 + k[0] * s + k[1] * s * s;
                let (mut d0, mut d1) = (d(s0).min(d(s1)), d(s0).max(d(s1)));
                if k[1] != 0.0 {
                    let vertex = -k[0] / (2.0 * k[1]);
                    if vertex > s0 && vertex < s1 {
                        (d0, d1) = (d0.min(d(vertex)), d1.max(d(vertex)));
                    }
                }
                let times = |a: f64, b: f64| {
                    let p = [a * d0, a * d1, b * d0, b * d1];
                    (
                        p.iter().copied().fold(f64::INFINITY, f64::min),
                        p.iter().copied().fold(f64::NEG_INFINITY, f64::max),
                    )
                };
                let ((x0, x1), (y0, y1)) = (times(u0, u1), times(v0, v1));
                [f * x0 + c[0], f * x1 + c[0], f * y0 + c[1], f * y1 + c[1]]
            }
        }
    }
}

/// Where one chunk's splats can land in one view, and how near its points can be.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Shadow {
    /// Every point of the chunk has a key at least this (depth lower bound, index 0).
    pub(crate) floor: f64,
    /// Pixels its splats can reach, inclusive: x0, x1, y0, y1 (clipped when tested).
    rect: [i64; 4],
}

impl Shadow {
    /// The chunk's shadow through `lens` for splats of `reach`; `None` when the box is not
    /// wholly in front of the camera or too wide on screen to be worth testing.
    ///
    /// Bounds are in f64 from the box's corners: a box in front of the camera projects
    /// (before distortion) inside the hull of its projected corners, and camera-space z is
    /// linear, so its least corner z bounds every point's. The margins cover the f32
    /// arithmetic of the points' camera-space coordinates and undistorted pixels.
    pub(crate) fn of(v: &View, lens: &Lens, c: &Chunk, reach: i64) -> Option<Shadow> {
        let (r, t) = (v.rotation.as_dmat3(), v.translation.as_dvec3());
        let (lo, hi) = (c.min.as_dvec3(), c.max.as_dvec3());
        let mut zmin = f64::INFINITY;
        let mut uv = [
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::INFINITY,
            f64::NEG_INFINITY,
        ];
        for i in 0..8 {
            let p = DVec3::new(
                if i & 1 == 0 { lo.x } else { hi.x },
                if i & 2 == 0 { lo.y } else { hi.y },
                if i & 4 == 0 { lo.z } else { hi.z },
            );
            let q = r * p + t;
            if q.z.is_nan() || q.z <= 0.0 {
                return None;
            }
            zmin = zmin.min(q.z);
            let (u, w) = (q.x / q.z, q.y / q.z);
            uv = [uv[0].min(u), uv[1].max(u), uv[2].min(w), uv[3].max(w)];
        }
        let err = F32_ERROR * (lo.abs().max(hi.abs()).length() + t.length());
        // Every point's f32 depth is above this (the cast below rounds by at most 2⁻²⁴ of
        // it, less than the 15/16 of err left in hand).
        let depth = zmin - err;
        if depth.is_nan() || depth <= 0.0 {
            return None;
        }
        // Normalised coordinates computed from f32 camera coordinates are off by at most
        // this; the rectangle grows by it before the lens maps it.
        let widest = uv.iter().fold(0.0f64, |m, a| m.max(a.abs()));
        let slack = 2.0 * err * (1.0 + widest) / depth;
        let uv = [uv[0] - slack, uv[1] + slack, uv[2] - slack, uv[3] + slack];
        let [x0, x1, y0, y1] = lens.image(uv);
        // Then the f32 roundings of undistorted pixels, and the splat's reach.
        let far = [x0, x1, y0, y1].iter().fold(0.0f64, |m, a| m.max(a.abs()));
        if far.is_nan() || far >= 1e7 {
            return None;
        }
        let pad = F32_ERROR * far + reach as f64;
        let (w, h) = (v.width as i64, v.height as i64);
        let rect = [
            ((x0 - pad).floor() as i64).max(0),
            ((x1 + pad).floor() as i64).min(w - 1),
            ((y0 - pad).floor() as i64).max(0),
            ((y1 + pad).floor() as i64).min(h - 1),
        ];
        let area = (rect[1] - rect[0] + 1).max(0) * (rect[3] - rect[2] + 1).max(0);
        if area > MAX_SCAN {
            return None;
        }
        Some(Shadow {
            floor: key(depth as f32, 0),
            rect,
        })
    }

    /// Whether every pixel the chunk's splats can reach already holds a nearer key.
    pub(crate) fn hidden(&self, z: &ZBuffer) -> bool {
        let [x0, x1, y0, y1] = self.rect;
        if x0 > x1 || y0 > y1 {
            // No splat of the chunk reaches the image.
            return true;
        }
        (y0..=y1).all(|y| {
            z.row(y)[x0 as usize..=x1 as usize]
                .iter()
                .all(|&k| k < self.floor)
        })
    }
}
