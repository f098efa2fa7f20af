//! The splat loops for CPUs with AVX2, chosen at run time (the build stays baseline x86-64).
//! Same arithmetic as the portable code, so renders are bit-identical (tested). Undistorted
//! lenses project, floor and bounds-check 8 points per instruction; every lens draws each row
//! of a splat's square as one 4-lane vector (distances, disc test and z-test together)
//! instead of a scalar step per pixel. Lenses with distortion still project one point at a
//! time through COLMAP's f64 formulas. Measured ratios to the portable kernel:
//! docs/bench/render_speed.md (`cargo bench -p nrw-render --bench render -- speed`).

use glam::{Mat3, Vec3};
use nrw_colmap::Projection;

use crate::cloud::Span;
use crate::zbuffer::ZBuffer;

/// Widest square the AVX2 kernel draws: reach 32 (`nrw-etl`'s largest radius), 65 columns.
const MAX_REACH: i64 = 32;
const MAX_VECTORS: usize = (2 * MAX_REACH as usize + 1).div_ceil(4);

/// A batch of points projected through an undistorted lens, one array per field so that the
/// projection loop vectorises without shuffles: pixel position and depth (as
/// `splat::project`), and the index of each square's top-left key in the bordered z-buffer,
/// or `SKIP` when the point draws nothing.
#[derive(Debug, Default)]
pub(crate) struct Batch {
    x: Vec<f32>,
    y: Vec<f32>,
    z: Vec<f32>,
    at: Vec<u32>,
    /// Index of the batch's first point.
    first: usize,
}

/// `at` of a point on or behind the camera plane, or whose square misses the image. It lies
/// past every square's corner (`fits` keeps the buffer shorter), so the draw loops' one range
/// check, which keeps their writes inside the buffer, also skips it.
const SKIP: u32 = u32::MAX;

/// A point projected through a lens with distortion (f64, by COLMAP's formulas), placed like
/// a `Batch`'s point: its pixel position, key, square (or `SKIP`), and the square's position as
/// (row, column) in the bordered buffer, from which its first pixel centre is computed.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Placed {
    pub(crate) px: f64,
    pub(crate) py: f64,
    pub(crate) key: f64,
    pub(crate) at: u32,
    square: u32,
}

impl Placed {
    /// A point at pixel (px, py) in pixel (xc, yc) with `key`, for a z-buffer of `z`'s shape.
    pub(crate) fn new(z: &ZBuffer, (px, py): (f64, f64), (xc, yc): (i64, i64), key: f64) -> Placed {
        let (xs, ys) = ((xc + z.reach) as u64, (yc + z.reach) as u64);
        let inside = xs < (z.width + 2 * z.reach) as u64 && ys < (z.height + 2 * z.reach) as u64;
        let at = if inside {
            (ys * z.stride as u64 + xs) as u32
        } else {
            SKIP
        };
        let square = (ys << 16 | xs) as u32;
        Placed {
            px,
            py,
            key,
            at,
            square,
        }
    }
}

/// What the draw loops read of point `i` of a batch.
trait Splats {
    /// The pixel position is an f32 value (so px - floor(px) is exact).
    const F32: bool;
    fn len(&self) -> usize;
    fn at(&self, i: usize) -> u32;
    fn pixel(&self, i: usize) -> (f64, f64);
    /// The square's first column and row in the image (used where `F32` is false).
    fn origin(&self, i: usize, reach: i64) -> (f64, f64);
    fn key(&self, i: usize) -> f64;
}

impl Splats for Batch {
    const F32: bool = true;
    #[inline(always)]
    fn len(&self) -> usize {
        self.at.len()
    }
    #[inline(always)]
    fn at(&self, i: usize) -> u32 {
        self.at[i]
    }
    #[inline(always)]
    fn pixel(&self, i: usize) -> (f64, f64) {
        (self.x[i] as f64, self.y[i] as f64)
    }
    #[inline(always)]
    fn origin(&self, _: usize, _: i64) -> (f64, f64) {
        unreachable!("F32 positions draw from their fractions")
    }
    #[inline(always)]
    fn key(&self, i: usize) -> f64 {
        crate::zbuffer::key(self.z[i], self.first + i)
    }
}

impl Splats for [Placed] {
    const F32: bool = false;
    #[inline(always)]
    fn len(&self) -> usize {
        <[Placed]>::len(self)
    }
    #[inline(always)]
    fn at(&self, i: usize) -> u32 {
        self[i].at
    }
    #[inline(always)]
    fn pixel(&self, i: usize) -> (f64, f64) {
        (self[i].px, self[i].py)
    }
    #[inline(always)]
    fn origin(&self, i: usize, reach: i64) -> (f64, f64) {
        // In the bordered buffer (2 × reach wide) the square's corner is at (xs, ys).
        let square = self[i].square;
        let (xs, ys) = ((square & 0xffff) as i64, (square >> 16) as i64);
        ((xs - 2 * reach) as f64, (ys - 2 * reach) as f64)
    }
    #[inline(always)]
    fn key(&self, i: usize) -> f64 {
        self[i].key
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

/// Whether `splat` can draw into `z`: AVX2, a square position that fits `Placed`'s 16-bit
/// row and column, and keys that a `u32` below `SKIP` indexes.
pub(crate) fn fits(z: &ZBuffer) -> bool {
    let span = |n: i64| n + 2 * z.reach < u16::MAX as i64;
    has_avx2()
        && z.reach <= MAX_REACH
        && span(z.width)
        && span(z.height)
        && z.keys.len() < SKIP as usize
}

/// Project `pts` (point `i` has index `first + i`) through the undistorted lens `k` and draw
/// them as discs of squared radius `r2`, or as the pixel that holds them when `r2` is 0.
/// `batch` holds the projections; `next` is the piece of the cloud drawn after this one,
/// which the draw loops prefetch (see `Ahead`). Call only where `fits(z)`.
#[allow(clippy::too_many_arguments)]
pub(crate) fn splat(
    z: &mut ZBuffer,
    pts: Span,
    first: usize,
    (r, t, k): (Mat3, Vec3, [f32; 4]),
    near: f32,
    r2: f64,
    batch: &mut Batch,
    next: Span,
) {
    assert!(fits(z));
    let n = pts.len();
    batch.x.resize(n, 0.0);
    batch.y.resize(n, 0.0);
    batch.z.resize(n, 0.0);
    batch.at.resize(n, SKIP);
    batch.first = first;
    #[cfg(target_arch = "x86_64")]
    // SAFETY: the CPU has AVX2 (asserted; `is_x86_feature_detected` caches its answer).
    unsafe {
        x86::project(batch, pts, (r, t, k), near, z);
        if r2 == 0.0 {
            x86::draw_pixel(z, &*batch, next)
        } else if z.reach == 1 {
            x86::draw_reach1(z, &*batch, r2, next)
        } else {
            x86::draw(z, &*batch, r2, next)
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    unreachable!("fits() is false off x86_64: {first} {near} {r2} {r:?} {t:?} {k:?}");
}

/// For a lens `P` whose `pixel` is straight-line arithmetic: transform, project (COLMAP's
/// f64 formulas), check and place points in one branch-free loop, as the one-at-a-time loop
/// would (near plane, z ≥ f64::EPSILON, finite pixel, not beyond the lens's `fold` when
/// given). The compiler does not vectorise it (yet); it saves the per-point `Option`s and
/// branches (docs/rendering.md has the figures). Point `i` has index `first + i`. Call only where `fits(z)`.
pub(crate) fn place<P: Projection>(
    z: &ZBuffer,
    pts: Span,
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
            square: 0,
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
            x86::draw_pixel(z, placed, Span::EMPTY)
        } else if z.reach == 1 {
            x86::draw_reach1(z, placed, r2, Span::EMPTY)
        } else {
            x86::draw(z, placed, r2, Span::EMPTY)
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

    use super::{Batch, Placed, Span, Splats, MAX_VECTORS, SKIP};
    use crate::zbuffer::{keep_nearest, ZBuffer, SLACK};

    /// `splat::project`, plus each square's position: floor(x) in f32 is exact and equals the
    /// portable `floor_f32` (coordinates are clamped to ±2^20 first, far outside any image).
    #[target_feature(enable = "avx2")]
    pub(super) fn project(
        out: &mut Batch,
        pts: Span,
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
        let stride = z.stride as u32;
        let n = pts.len();
        let [px, py, pz] = pts.0.map(|a| &a[..n]);
        let (xo, yo, zo, ato) = (
            &mut out.x[..n],
            &mut out.y[..n],
            &mut out.z[..n],
            &mut out.at[..n],
        );
        for i in 0..n {
            let c = r * Vec3::new(px[i], py[i], pz[i]) + t;
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
            // Below the buffer's length (`fits`), so no wrap-around.
            let at = if drawn {
                ys.wrapping_mul(stride) + xs
            } else {
                SKIP
            };
            (xo[i], yo[i], zo[i], ato[i]) = (x, y, c.z, at);
        }
    }

    /// See `super::place`: the one-at-a-time loop's checks and placement (`Placed::new`),
    /// without its per-point `Option`s and early exits.
    #[target_feature(enable = "avx2")]
    pub(super) fn place<P: Projection>(
        z: &ZBuffer,
        pts: Span,
        first: usize,
        (r, t, params): (Mat3, Vec3, &[f64]),
        (near, fold): (f32, Option<f64>),
        out: &mut [Placed],
    ) {
        const FAR: f64 = (1u64 << 30) as f64;
        let (check_fold, fold) = (fold.is_some(), fold.unwrap_or(f64::INFINITY));
        for (i, o) in out.iter_mut().enumerate() {
            let c = r * pts.get(i) + t;
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
            *o = Placed::new(z, (q.x, q.y), at, crate::zbuffer::key(c.z, first + i));
            // Not drawn: all bits set, `SKIP`.
            o.at |= ((!valid | folded) as u32).wrapping_neg();
        }
    }

    /// Where the draw loops prefetch the cloud's next piece: its projection, which follows,
    /// then reads from cache instead of waiting on memory (the hardware prefetcher restarts at
    /// every chunk, whose positions lie apart in memory when chunks in between are culled;
    /// docs/rendering.md has the figures).
    struct Ahead {
        /// Each axis's first byte.
        start: [*const i8; 3],
        /// Last byte of an axis (0 when there is no point, and `start` is any valid address).
        last: usize,
    }

    impl Ahead {
        fn new(next: Span, fallback: *const f64) -> Ahead {
            match next.len() {
                0 => Ahead {
                    start: [fallback as *const i8; 3],
                    last: 0,
                },
                n => Ahead {
                    start: next.0.map(|a| a.as_ptr() as *const i8),
                    last: n * size_of::<f32>() - 1,
                },
            }
        }

        /// Prefetch the lines holding point `i` of the piece (or its last point).
        #[inline(always)]
        fn fetch(&self, i: usize) {
            let b = (i * size_of::<f32>()).min(self.last);
            for s in self.start {
                // SAFETY: an address within the piece (or `fallback`); prefetching never faults.
                unsafe { _mm_prefetch::<_MM_HINT_T0>(s.add(b)) }
            }
        }
    }

    /// r = 0: the pixel that holds the point (the z-buffer has no border at reach 0).
    #[target_feature(enable = "avx2")]
    pub(super) fn draw_pixel<P: Splats + ?Sized>(z: &mut ZBuffer, proj: &P, next: Span) {
        let ahead = Ahead::new(next, z.keys.as_ptr());
        for i in 0..proj.len() {
            // One line per axis every 16 points.
            if i % 16 == 0 {
                ahead.fetch(i);
            }
            if let Some(slot) = z.keys.get_mut(proj.at(i) as usize) {
                keep_nearest(slot, proj.key(i));
            }
        }
    }

    /// Discs of any reach up to `MAX_REACH` (reach 1 has its own loop, `draw_reach1`).
    ///
    /// Lane l of vector v covers column x = x0 + 4v + l of the square (x0 its first column),
    /// at horizontal offset (x + 0.5) - px from the point, computed as the difference of
    /// x0 + (4v + l + 0.5) and px: the sum is exact, so this is the portable (x + 0.5) - px
    /// rounded once, and the disc test agrees bit for bit. For f32 positions the offsets are
    /// taken from the fraction f = px - floor(px) as (4v + l - reach + 0.5) - f, one vector op
    /// fewer per point, as the portable pinhole loop does (same rounding: see
    /// `splat::Footprint::draw`). Rows are the same vectors with y for x, one lane per row.
    /// Lanes past the square get an offset of 10⁶, fail the disc test and write back the key
    /// they read.
    #[target_feature(enable = "avx2")]
    pub(super) fn draw<P: Splats + ?Sized>(z: &mut ZBuffer, proj: &P, r2: f64, next: Span) {
        let reach = z.reach;
        let stride = z.stride as usize;
        let side = (2 * reach + 1) as usize;
        let vectors = side.div_ceil(4);
        assert!(vectors <= MAX_VECTORS && 4 * vectors - side <= SLACK);
        let offsets = lane_offsets(P::F32, reach, side, vectors);
        let offsets = &offsets[..vectors];
        // Squared offsets: columns as vectors, rows one lane each.
        let mut dx2 = [_mm256_setzero_pd(); MAX_VECTORS];
        let dx2 = &mut dx2[..vectors];
        let mut dy2 = [0f64; 4 * MAX_VECTORS];
        let r2v = _mm256_set1_pd(r2);
        // The last square's corner; `at` beyond it (`SKIP`) draws nothing. From there, the
        // square's last key plus the lanes past it lie within the buffer (SLACK).
        let Some(corners) = z.keys.len().checked_sub((side - 1) * stride + 4 * vectors) else {
            return; // (no square fits: an image without pixels)
        };
        let keys = z.keys.as_mut_ptr();
        // Squared offsets of `vectors` vectors of lanes along one axis: (lane offset) - p where
        // p is the position's fraction (F32), or (o + lane offset) - p where o is the square's
        // first column or row and p the position (else).
        let squares = |d: &mut [__m256d], o: f64, p: f64| {
            let (ov, pv) = (_mm256_set1_pd(o), _mm256_set1_pd(p));
            for (d, off) in d.iter_mut().zip(offsets) {
                let t = if P::F32 {
                    _mm256_sub_pd(*off, pv)
                } else {
                    _mm256_sub_pd(_mm256_add_pd(ov, *off), pv)
                };
                *d = _mm256_mul_pd(t, t);
            }
        };
        let ahead = Ahead::new(next, z.keys.as_ptr());
        // (Wider squares overlap less, and ran slower interleaved.)
        for i in 0..proj.len() {
            if i % 16 == 0 {
                ahead.fetch(i);
            }
            let corner = proj.at(i) as usize;
            if corner > corners {
                continue;
            }
            let (px, py) = proj.pixel(i);
            // Offsets from the fractions (F32) or from the square's first pixel centre.
            let (x0, y0) = if P::F32 {
                (0.0, 0.0)
            } else {
                proj.origin(i, reach)
            };
            let (fx, fy) = if P::F32 {
                (px - px.floor(), py - py.floor())
            } else {
                (px, py)
            };
            squares(dx2, x0, fx);
            for (j, d) in dy2[..side].iter_mut().enumerate() {
                let t = if P::F32 {
                    (j as i64 - reach) as f64 + 0.5 - fy
                } else {
                    (y0 + j as f64) + 0.5 - fy
                };
                *d = t * t;
            }
            let kv = _mm256_set1_pd(proj.key(i));
            for (j, dy2) in dy2[..side].iter().enumerate() {
                let dy2 = _mm256_set1_pd(*dy2);
                for (v, d) in dx2.iter().enumerate() {
                    let d2 = _mm256_add_pd(*d, dy2);
                    // Outside the disc (or NaN): all-ones bits, a NaN that `min` never keeps.
                    let cand = _mm256_or_pd(kv, _mm256_cmp_pd::<_CMP_NLE_UQ>(d2, r2v));
                    // SAFETY: corner <= corners, so the 4 keys lie within the buffer (above).
                    unsafe {
                        let s = keys.add(corner + j * stride + 4 * v);
                        _mm256_storeu_pd(s, _mm256_min_pd(cand, _mm256_loadu_pd(s)));
                    }
                }
            }
        }
    }

    /// The lanes' offsets of `draw`: column 4v + l of a `side`-wide square at (col − reach) +
    /// 0.5 from the fraction (`f32`) or col + 0.5 from the square's first column; 10⁶ past
    /// the square.
    #[target_feature(enable = "avx2")]
    fn lane_offsets(f32: bool, reach: i64, side: usize, vectors: usize) -> [__m256d; MAX_VECTORS] {
        let mut offsets = [_mm256_setzero_pd(); MAX_VECTORS];
        for (v, o) in offsets[..vectors].iter_mut().enumerate() {
            let lane = |l: usize| {
                let col = 4 * v + l;
                match (col < side, f32) {
                    (true, true) => (col as i64 - reach) as f64 + 0.5,
                    (true, false) => col as f64 + 0.5,
                    (false, _) => 1e6,
                }
            };
            *o = _mm256_set_pd(lane(3), lane(2), lane(1), lane(0));
        }
        offsets
    }

    /// Reach 1 (radius in [0.5, 1.5), the paper's 1 included): `draw`'s arithmetic for a 3×3
    /// square, lane for lane (columns as one vector, the three rows' offsets as another,
    /// broadcast per row), with a batch's four quarters drawn interleaved. Consecutive points
    /// of a chunk (Morton order) mostly hit the same square or one that overlaps it (in the
    /// benchmark's whole views at 10⁷ points: 55% the same pixel, 42% a neighbour within 2),
    /// so each point's loads would wait for the stores of the one before; the quarters of a
    /// chunk lie apart in the image, and four such chains overlap in time.
    /// Not for r = 0, whose single-key update ran slower interleaved, nor
    /// for wider squares, which overlap less (docs/rendering.md has the figures). Its own loop, with
    /// the body a macro (a closure was not inlined), rather than `draw`'s generic one: half
    /// the instructions per point.
    #[target_feature(enable = "avx2")]
    pub(super) fn draw_reach1<P: Splats + ?Sized>(z: &mut ZBuffer, proj: &P, r2: f64, next: Span) {
        let stride = z.stride as usize;
        let Some(corners) = z.keys.len().checked_sub(2 * stride + 4) else {
            return;
        };
        let keys = z.keys.as_mut_ptr();
        let r2v = _mm256_set1_pd(r2);
        // Column offsets before the point's fraction (F32) or position is subtracted; the
        // lane past the square fails the disc test and writes back the key it read.
        let lanes = if P::F32 {
            _mm256_set_pd(1e6, 1.5, 0.5, -0.5)
        } else {
            _mm256_set_pd(1e6, 2.5, 1.5, 0.5)
        };
        // Point i; squares at corners past the last one (`SKIP`) draw nothing.
        macro_rules! body {
            ($i:expr) => {{
                let i: usize = $i;
                let corner = proj.at(i) as usize;
                if corner <= corners {
                    let (px, py) = proj.pixel(i);
                    let (dx, dy) = if P::F32 {
                        let (fx, fy) = (px - px.floor(), py - py.floor());
                        let sub = |f: f64| _mm256_sub_pd(lanes, _mm256_set1_pd(f));
                        (sub(fx), sub(fy))
                    } else {
                        let (x0, y0) = proj.origin(i, 1);
                        let sub = |o: f64, p: f64| {
                            _mm256_sub_pd(
                                _mm256_add_pd(_mm256_set1_pd(o), lanes),
                                _mm256_set1_pd(p),
                            )
                        };
                        (sub(x0, px), sub(y0, py))
                    };
                    let (dx2, dy2) = (_mm256_mul_pd(dx, dx), _mm256_mul_pd(dy, dy));
                    let kv = _mm256_set1_pd(proj.key(i));
                    let rows = [
                        _mm256_permute4x64_pd::<0x00>(dy2),
                        _mm256_permute4x64_pd::<0x55>(dy2),
                        _mm256_permute4x64_pd::<0xaa>(dy2),
                    ];
                    for (j, dy2) in rows.into_iter().enumerate() {
                        let d2 = _mm256_add_pd(dx2, dy2);
                        // Outside the disc (or NaN): all-ones bits, a NaN `min` never keeps.
                        let cand = _mm256_or_pd(kv, _mm256_cmp_pd::<_CMP_NLE_UQ>(d2, r2v));
                        // SAFETY: corner <= corners, so the 4 keys lie within the buffer.
                        unsafe {
                            let s = keys.add(corner + j * stride);
                            _mm256_storeu_pd(s, _mm256_min_pd(cand, _mm256_loadu_pd(s)));
                        }
                    }
                }
            }};
        }
        let ahead = Ahead::new(next, keys);
        let n = proj.len();
        let q = n / 4;
        for k in 0..q {
            // One line per axis every 16 points (4 rounds).
            if k % 4 == 0 {
                ahead.fetch(4 * k);
            }
            body!(k);
            body!(q + k);
            body!(2 * q + k);
            body!(3 * q + k);
        }
        for i in 4 * q..n {
            body!(i);
        }
    }
}
