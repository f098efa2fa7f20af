//! The splat loops for CPUs with AVX2, chosen at run time (the build stays baseline x86-64).
//! Same arithmetic as the portable code, so renders are bit-identical (tested). Undistorted
//! lenses project, floor and bounds-check 8 points per instruction; every lens draws each row
//! of a splat's square as one 4-lane vector (distances, disc test and z-test together)
//! instead of a scalar step per pixel. Lenses with distortion still project one point at a
//! time through COLMAP's f64 formulas. Measured ratios to the portable kernel:
//! docs/bench/render_speed.md (`cargo bench -p nrw-render --bench render -- speed`).

use glam::{Mat3, Vec3};
use nrw_colmap::Projection;

use crate::splat::ZBuffer;

/// Widest square the AVX2 kernel draws: reach 32 (`nrw-etl`'s largest radius), 65 columns.
const MAX_REACH: i64 = 32;
const MAX_VECTORS: usize = (2 * MAX_REACH as usize + 1).div_ceil(4);

/// A projected point: pixel position and depth (as `splat::project`), and the top-left key
/// of its square in the bordered z-buffer as (row, column), or `SKIP` when it draws nothing.
#[derive(Debug, Clone, Copy, Default)]
#[repr(C)]
pub(crate) struct Projected {
    x: f32,
    y: f32,
    z: f32,
    at: u32,
}

/// `Projected::at` of a point on or behind the camera plane, or whose square misses the image.
const SKIP: u32 = u32::MAX;

/// A point projected through a lens with distortion (f64, by COLMAP's formulas), placed like
/// a `Projected`: its pixel position, key, and square position (or `SKIP`).
#[derive(Debug, Clone, Copy)]
pub(crate) struct Placed {
    pub(crate) px: f64,
    pub(crate) py: f64,
    pub(crate) key: f64,
    pub(crate) at: u32,
}

impl Placed {
    /// A point at pixel (px, py) in pixel (xc, yc) with `key`, for a z-buffer of `z`'s shape.
    pub(crate) fn new(z: &ZBuffer, (px, py): (f64, f64), (xc, yc): (i64, i64), key: f64) -> Placed {
        let (xs, ys) = ((xc + z.reach) as u64, (yc + z.reach) as u64);
        let inside = xs < (z.width + 2 * z.reach) as u64 && ys < (z.height + 2 * z.reach) as u64;
        let at = if inside { (ys << 16 | xs) as u32 } else { SKIP };
        Placed { px, py, key, at }
    }
}

/// What the draw loops read of a point; point `i` of a batch starting at index `first`.
trait Splat {
    /// The pixel position is an f32 value (so px - floor(px) is exact).
    const F32: bool;
    fn at(&self) -> u32;
    fn pixel(&self) -> (f64, f64);
    fn key(&self, first: usize, i: usize) -> f64;
}

impl Splat for Projected {
    const F32: bool = true;
    #[inline(always)]
    fn at(&self) -> u32 {
        self.at
    }
    #[inline(always)]
    fn pixel(&self) -> (f64, f64) {
        (self.x as f64, self.y as f64)
    }
    #[inline(always)]
    fn key(&self, first: usize, i: usize) -> f64 {
        crate::splat::key(self.z, first + i)
    }
}

impl Splat for Placed {
    const F32: bool = false;
    #[inline(always)]
    fn at(&self) -> u32 {
        self.at
    }
    #[inline(always)]
    fn pixel(&self) -> (f64, f64) {
        (self.px, self.py)
    }
    #[inline(always)]
    fn key(&self, _: usize, _: usize) -> f64 {
        self.key
    }
}

/// Whether this CPU runs the AVX2 kernel.
fn has_avx2() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        is_x86_feature_detected!("avx2")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// Whether `splat` can draw into `z`: AVX2, and a square position that fits `Projected::at`.
pub(crate) fn fits(z: &ZBuffer) -> bool {
    let span = |n: i64| n + 2 * z.reach < u16::MAX as i64;
    has_avx2() && z.reach <= MAX_REACH && span(z.width) && span(z.height)
}

/// Project `pts` (point `i` has index `first + i`) through the undistorted lens `k` and draw
/// them as discs of squared radius `r2`, or as the pixel that holds them when `r2` is 0.
/// `scratch` holds the projections. Call only where `fits(z)`.
#[allow(clippy::too_many_arguments)]
pub(crate) fn splat(
    z: &mut ZBuffer,
    pts: &[Vec3],
    first: usize,
    (r, t, k): (Mat3, Vec3, [f32; 4]),
    near: f32,
    r2: f64,
    scratch: &mut Vec<Projected>,
) {
    assert!(fits(z));
    scratch.resize(pts.len(), Projected::default());
    #[cfg(target_arch = "x86_64")]
    // SAFETY: the CPU has AVX2 (asserted; `is_x86_feature_detected` caches its answer).
    unsafe {
        x86::project(scratch, pts, (r, t, k), near, z);
        if r2 == 0.0 {
            x86::draw_pixel(z, scratch, first)
        } else if z.reach == 1 {
            x86::draw::<true, _>(z, scratch, first, r2)
        } else {
            x86::draw::<false, _>(z, scratch, first, r2)
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    unreachable!("fits() is false off x86_64: {first} {near} {r2} {r:?} {t:?} {k:?}");
}

/// For a lens `P` whose `pixel` is straight-line arithmetic: transform, project (COLMAP's
/// f64 formulas), check and place points in one branch-free loop, as the one-at-a-time loop
/// would (near plane, z ≥ f64::EPSILON, finite pixel, not beyond the lens's `fold` when
/// given). The compiler does not vectorise it (yet); it saves the per-point `Option`s and
/// branches: SIMPLE_RADIAL, 10⁶ points, r = 0: 6.2 → 4.6 ms/view. Point `i` has index
/// `first + i`. Call only where `fits(z)`.
pub(crate) fn place<P: Projection>(
    z: &ZBuffer,
    pts: &[Vec3],
    first: usize,
    (r, t, params): (Mat3, Vec3, &[f64]),
    (near, fold): (f32, Option<f64>),
    out: &mut Vec<Placed>,
) {
    assert!(fits(z) && P::STRAIGHT);
    out.clear();
    out.resize(
        pts.len(),
        Placed {
            px: 0.0,
            py: 0.0,
            key: 0.0,
            at: SKIP,
        },
    );
    #[cfg(target_arch = "x86_64")]
    // SAFETY: the CPU has AVX2 (asserted; `is_x86_feature_detected` caches its answer).
    unsafe {
        x86::place::<P>(z, pts, first, (r, t, params), (near, fold), out)
    }
    #[cfg(not(target_arch = "x86_64"))]
    unreachable!("fits() is false off x86_64: {first} {near} {fold:?} {r:?} {t:?} {params:?}");
}

/// Draw points placed by `Placed::new` (any lens) as `splat` does. Call only where `fits(z)`.
pub(crate) fn draw_placed(z: &mut ZBuffer, placed: &[Placed], r2: f64) {
    assert!(fits(z));
    #[cfg(target_arch = "x86_64")]
    // SAFETY: the CPU has AVX2 (asserted; `is_x86_feature_detected` caches its answer).
    unsafe {
        if r2 == 0.0 {
            x86::draw_pixel(z, placed, 0)
        } else if z.reach == 1 {
            x86::draw::<true, _>(z, placed, 0, r2)
        } else {
            x86::draw::<false, _>(z, placed, 0, r2)
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    unreachable!("fits() is false off x86_64: {} {r2}", placed.len());
}

#[cfg(target_arch = "x86_64")]
mod x86 {
    use std::arch::x86_64::*;

    use glam::{Mat3, Vec3};

    use glam::DVec3;
    use nrw_colmap::Projection;

    use super::{Placed, Projected, Splat, MAX_VECTORS, SKIP};
    use crate::splat::{keep_nearest, ZBuffer, SLACK};

    /// `splat::project`, plus each square's position: floor(x) in f32 is exact and equals the
    /// portable `floor_f32` (coordinates are clamped to ±2^20 first, far outside any image).
    #[target_feature(enable = "avx2")]
    pub(super) fn project(
        out: &mut [Projected],
        pts: &[Vec3],
        (r, t, k): (Mat3, Vec3, [f32; 4]),
        near: f32,
        z: &ZBuffer,
    ) {
        const FAR: f32 = (1 << 20) as f32;
        let reach = z.reach as i32;
        let (xspan, yspan) = (
            (z.width as i32 + 2 * reach) as u32,
            (z.height as i32 + 2 * reach) as u32,
        );
        for (o, p) in out.iter_mut().zip(pts) {
            let c = r * *p + t;
            let (x, y) = crate::view::pinhole_pixel(k, c);
            // Not `clamp`, which keeps NaN (this maps it to -FAR, outside).
            #[allow(clippy::manual_clamp)]
            let (fx, fy) = (x.max(-FAR).min(FAR).floor(), y.max(-FAR).min(FAR).floor());
            // SAFETY: fx, fy are integers within ±2^20, which i32 holds (`as` would check
            // each lane for NaN and overflow, and stop the loop from vectorising).
            let (ix, iy): (i32, i32) = unsafe { (fx.to_int_unchecked(), fy.to_int_unchecked()) };
            // -reach <= floor < span - reach, as one unsigned comparison per axis.
            let (xs, ys) = ((ix + reach) as u32, (iy + reach) as u32);
            // On or behind the camera plane (z ≈ 0 included): never drawn.
            let drawn = c.z > near && xs < xspan && ys < yspan;
            let at = if drawn { ys << 16 | xs } else { SKIP };
            *o = Projected { x, y, z: c.z, at };
        }
    }

    /// See `super::place`: the one-at-a-time loop's checks and placement (`Placed::new`),
    /// without its per-point `Option`s and early exits.
    #[target_feature(enable = "avx2")]
    pub(super) fn place<P: Projection>(
        z: &ZBuffer,
        pts: &[Vec3],
        first: usize,
        (r, t, params): (Mat3, Vec3, &[f64]),
        (near, fold): (f32, Option<f64>),
        out: &mut [Placed],
    ) {
        const FAR: f64 = (1u64 << 30) as f64;
        let (check_fold, fold) = (fold.is_some(), fold.unwrap_or(f64::INFINITY));
        for (i, (o, p)) in out.iter_mut().zip(pts).enumerate() {
            let c = r * *p + t;
            let cd = DVec3::new(c.x as f64, c.y as f64, c.z as f64);
            let q = P::pixel(params, cd);
            // `Camera::normalized_radius` of a lens that is not a fisheye.
            let folded = check_fold & ((cd.x * cd.x + cd.y * cd.y).sqrt() / cd.z > fold);
            let valid = (c.z > near) & (cd.z >= f64::EPSILON) & q.x.is_finite() & q.y.is_finite();
            // Not `floor_i`: clamped to ±2^30 (outside any image; NaN to -2^30), `floor` is
            // one instruction here and the cast needs no check (the loop ran 1.3× faster).
            #[allow(clippy::manual_clamp)]
            let (fx, fy) = (
                q.x.max(-FAR).min(FAR).floor(),
                q.y.max(-FAR).min(FAR).floor(),
            );
            // SAFETY: integers within ±2^30, which i64 holds.
            let at: (i64, i64) = unsafe { (fx.to_int_unchecked(), fy.to_int_unchecked()) };
            *o = Placed::new(z, (q.x, q.y), at, crate::splat::key(c.z, first + i));
            // Not drawn: all bits set, `SKIP`.
            o.at |= ((!valid | folded) as u32).wrapping_neg();
        }
    }

    /// r = 0: the pixel that holds the point (the z-buffer has no border at reach 0).
    #[target_feature(enable = "avx2")]
    pub(super) fn draw_pixel<P: Splat>(z: &mut ZBuffer, proj: &[P], first: usize) {
        let stride = z.stride as usize;
        for (i, p) in proj.iter().enumerate() {
            let at = p.at();
            if at != SKIP {
                let slot = (at >> 16) as usize * stride + (at & 0xffff) as usize;
                keep_nearest(&mut z.keys[slot], p.key(first, i));
            }
        }
    }

    /// `REACH1`: the z-buffer's reach is 1, so the 3×3 square unrolls.
    ///
    /// Lane l of vector v covers column x = x0 + 4v + l of the square (x0 its first column),
    /// at horizontal offset (x + 0.5) - px from the point, computed as the difference of
    /// x0 + (4v + l + 0.5) and px: the sum is exact, so this is the portable (x + 0.5) - px
    /// rounded once, and the disc test agrees bit for bit (for f32 positions a form with one
    /// op fewer, below). Lanes past the square get an offset of 10⁶, fail the disc test and
    /// write back the key they read.
    #[target_feature(enable = "avx2")]
    pub(super) fn draw<const REACH1: bool, P: Splat>(
        z: &mut ZBuffer,
        proj: &[P],
        first: usize,
        r2: f64,
    ) {
        let reach = if REACH1 { 1 } else { z.reach };
        let stride = z.stride as usize;
        let side = (2 * reach + 1) as usize;
        let vectors = side.div_ceil(4);
        assert!(vectors <= MAX_VECTORS && 4 * vectors - side <= SLACK);
        let mut offsets = [_mm256_setzero_pd(); MAX_VECTORS];
        for (v, o) in offsets[..vectors].iter_mut().enumerate() {
            let lane = |l: usize| {
                let col = 4 * v + l;
                if col < side {
                    if P::F32 {
                        (col as i64 - reach) as f64 + 0.5
                    } else {
                        col as f64 + 0.5
                    }
                } else {
                    1e6
                }
            };
            *o = _mm256_set_pd(lane(3), lane(2), lane(1), lane(0));
        }
        let offsets = &offsets[..vectors];
        let mut dx2 = [_mm256_setzero_pd(); MAX_VECTORS];
        let dx2 = &mut dx2[..vectors];
        let r2v = _mm256_set1_pd(r2);
        // The square's last key plus the lanes past it lie within the buffer (SLACK).
        let last = (side - 1) * stride + 4 * vectors - 1;
        for (i, p) in proj.iter().enumerate() {
            let at = p.at();
            if at == SKIP {
                continue;
            }
            let (xs, ys) = ((at & 0xffff) as i64, (at >> 16) as i64);
            let corner = ys as usize * stride + xs as usize;
            let square = &mut z.keys[corner..corner + last + 1];
            // The square's first column and row in the image: the point's pixel minus reach,
            // which in the bordered buffer (2 × reach wide) is at xs, ys.
            let (x0, y0) = ((xs - 2 * reach) as f64, (ys - 2 * reach) as f64);
            let (px, py) = p.pixel();
            if P::F32 {
                // px - floor(px) is exact for an f32 px, so (col - reach + 0.5) - fx rounds
                // the same real number once: one vector op fewer per point.
                let fx = _mm256_set1_pd(px - (x0 + reach as f64));
                for (d, o) in dx2.iter_mut().zip(offsets) {
                    let dx = _mm256_sub_pd(*o, fx);
                    *d = _mm256_mul_pd(dx, dx);
                }
            } else {
                let (x0, pxv) = (_mm256_set1_pd(x0), _mm256_set1_pd(px));
                for (d, o) in dx2.iter_mut().zip(offsets) {
                    let dx = _mm256_sub_pd(_mm256_add_pd(x0, *o), pxv);
                    *d = _mm256_mul_pd(dx, dx);
                }
            }
            let kv = _mm256_set1_pd(p.key(first, i));
            for j in 0..side {
                let dy = (y0 + j as f64) + 0.5 - py;
                let dy2 = _mm256_set1_pd(dy * dy);
                for (v, d) in dx2.iter().enumerate() {
                    let d2 = _mm256_add_pd(*d, dy2);
                    // Outside the disc (or NaN): all-ones bits, a NaN that `min` never keeps.
                    let cand = _mm256_or_pd(kv, _mm256_cmp_pd::<_CMP_NLE_UQ>(d2, r2v));
                    let at = j * stride + 4 * v;
                    let slots = &mut square[at..at + 4];
                    let s = slots.as_mut_ptr();
                    // SAFETY: `slots` holds the 4 keys read and written.
                    unsafe { _mm256_storeu_pd(s, _mm256_min_pd(cand, _mm256_loadu_pd(s))) };
                }
            }
        }
    }
}
