//! The pinhole splat loop for CPUs with AVX2, chosen at run time (the build stays baseline
//! x86-64). Same arithmetic as the portable code, so renders are bit-identical: projection
//! runs 8 points per instruction, and each row of a splat's square is one 4-lane vector
//! (distances, disc test and z-test together) instead of a scalar step per pixel. Measured
//! on the 10⁷-point benchmark: r = 1 took 0.6× the time of the portable kernel.

use glam::{Mat3, Vec3};

use crate::splat::ZBuffer;

/// Widest square the AVX2 kernel draws: reach 32 (`nrw-etl`'s largest radius), 65 columns.
pub(crate) const MAX_REACH: i64 = 32;
const MAX_VECTORS: usize = (2 * MAX_REACH as usize + 1).div_ceil(4);

/// Whether this CPU runs the AVX2 kernel.
pub(crate) fn has_avx2() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        is_x86_feature_detected!("avx2")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// `splat::project`, compiled for AVX2. Call only where `has_avx2()`.
#[cfg(target_arch = "x86_64")]
pub(crate) fn project(out: &mut [[f32; 3]], pts: &[Vec3], r: Mat3, t: Vec3, k: [f32; 4]) {
    assert!(has_avx2());
    // SAFETY: the CPU has AVX2 (asserted; `is_x86_feature_detected` caches its answer).
    unsafe { x86::project(out, pts, r, t, k) }
}

/// Draw projected points (from `splat::project`) as discs of squared radius `r2` within the
/// z-buffer's reach, or as the pixel that holds them when `r2` is 0; point `i` has index
/// `first + i`. Call only where `has_avx2()`.
#[cfg(target_arch = "x86_64")]
pub(crate) fn draw(z: &mut ZBuffer, proj: &[[f32; 3]], first: usize, near: f32, r2: f64) {
    assert!(has_avx2() && (0..=MAX_REACH).contains(&z.reach));
    // SAFETY: the CPU has AVX2 (asserted above).
    unsafe {
        if r2 == 0.0 {
            x86::draw_pixel(z, proj, first, near)
        } else if z.reach == 1 {
            x86::draw::<true>(z, proj, first, near, r2)
        } else {
            x86::draw::<false>(z, proj, first, near, r2)
        }
    }
}

#[cfg(not(target_arch = "x86_64"))]
pub(crate) fn project(_: &mut [[f32; 3]], _: &[Vec3], _: Mat3, _: Vec3, _: [f32; 4]) {
    unreachable!("has_avx2() is false off x86_64")
}

#[cfg(not(target_arch = "x86_64"))]
pub(crate) fn draw(_: &mut ZBuffer, _: &[[f32; 3]], _: usize, _: f32, _: f64) {
    unreachable!("has_avx2() is false off x86_64")
}

#[cfg(target_arch = "x86_64")]
mod x86 {
    use std::arch::x86_64::*;

    use glam::{Mat3, Vec3};

    use super::MAX_VECTORS;
    use crate::splat::{floor_f32, keep_nearest, key, ZBuffer, SLACK};

    /// r = 0: the pixel that holds the point (the portable loop, compiled for AVX2: it ran
    /// in 0.75× the time, measured; the z-buffer has no border at reach 0).
    #[target_feature(enable = "avx2")]
    pub(super) fn draw_pixel(z: &mut ZBuffer, proj: &[[f32; 3]], first: usize, near: f32) {
        let stride = z.stride as usize;
        let (xspan, yspan) = (z.width as u64, z.height as u64);
        for (i, &[x, y, zz]) in proj.iter().enumerate() {
            if zz <= near {
                continue;
            }
            let (xs, ys) = (floor_f32(x as f64) as u64, floor_f32(y as f64) as u64);
            if xs >= xspan || ys >= yspan {
                continue;
            }
            keep_nearest(
                &mut z.keys[ys as usize * stride + xs as usize],
                key(zz, first + i),
            );
        }
    }

    #[target_feature(enable = "avx2")]
    pub(super) fn project(out: &mut [[f32; 3]], pts: &[Vec3], r: Mat3, t: Vec3, k: [f32; 4]) {
        crate::splat::project(out, pts, r, t, k)
    }

    /// `REACH1`: the z-buffer's reach is 1, so the 3×3 square unrolls.
    ///
    /// Lane l of vector v covers column 4v + l of the square, at horizontal offset
    /// (4v + l - reach) + 0.5 - fx from the point, where fx = px - floor(px) is exact (px is
    /// an f32 value): the same rounding of the same real number as the portable
    /// (x + 0.5) - px, so the disc test agrees bit for bit. Lanes past the square get an
    /// offset of 10⁶, fail the disc test and write back the key they read.
    #[target_feature(enable = "avx2")]
    pub(super) fn draw<const REACH1: bool>(
        z: &mut ZBuffer,
        proj: &[[f32; 3]],
        first: usize,
        near: f32,
        r2: f64,
    ) {
        let reach = if REACH1 { 1 } else { z.reach };
        let stride = z.stride as usize;
        let (xspan, yspan) = ((z.width + 2 * reach) as u64, (z.height + 2 * reach) as u64);
        let side = (2 * reach + 1) as usize;
        let vectors = side.div_ceil(4);
        assert!(vectors <= MAX_VECTORS);
        let mut offsets = [_mm256_setzero_pd(); MAX_VECTORS];
        for (v, o) in offsets[..vectors].iter_mut().enumerate() {
            let lane = |l: usize| {
                let col = 4 * v + l;
                if col < side {
                    (col as i64 - reach) as f64 + 0.5
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
        assert!(4 * vectors - side <= SLACK);
        for (i, &[x, y, zz]) in proj.iter().enumerate() {
            // On or behind the camera plane (z ≈ 0 included): never drawn.
            if zz <= near {
                continue;
            }
            let (px, py) = (x as f64, y as f64);
            let (xc, yc) = (floor_f32(px), floor_f32(py));
            // A splat whose centre pixel is more than `reach` outside touches no pixel:
            // -reach <= xc < w + reach, as one unsigned comparison (and the same for y).
            let (xs, ys) = ((xc + reach) as u64, (yc + reach) as u64);
            if xs >= xspan || ys >= yspan {
                continue;
            }
            let corner = ys as usize * stride + xs as usize;
            let square = &mut z.keys[corner..corner + last + 1];
            let fx = _mm256_set1_pd(px - xc as f64);
            for (d, o) in dx2.iter_mut().zip(offsets) {
                let dx = _mm256_sub_pd(*o, fx);
                *d = _mm256_mul_pd(dx, dx);
            }
            let kv = _mm256_set1_pd(key(zz, first + i));
            let fy = py - yc as f64;
            for j in 0..side {
                let dy = (j as i64 - reach) as f64 + 0.5 - fy;
                let dy2 = _mm256_set1_pd(dy * dy);
                for (v, d) in dx2.iter().enumerate() {
                    let d2 = _mm256_add_pd(*d, dy2);
                    // Outside the disc (or NaN): all-ones bits, a NaN that `min` never keeps.
                    let cand = _mm256_or_pd(kv, _mm256_cmp_pd::<_CMP_NLE_UQ>(d2, r2v));
                    let at = j * stride + 4 * v;
                    let slots = &mut square[at..at + 4];
                    let p = slots.as_mut_ptr();
                    // SAFETY: `slots` holds the 4 keys read and written.
                    unsafe { _mm256_storeu_pd(p, _mm256_min_pd(cand, _mm256_loadu_pd(p))) };
                }
            }
        }
    }
}
