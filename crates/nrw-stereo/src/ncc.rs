//! The inner loop of the NCC: a window's samples warped into a source image by a homography,
//! read bilinearly, and summed in [`LANES`] independent lanes. Two kernels give the same
//! bits: a portable one and an AVX2 one (8 lanes per register, the image read by gathers),
//! chosen at run time. Both do the same IEEE operations in the same order (no fused
//! multiply-add), so the maps do not depend on the machine.

use crate::view::GrayImage;

/// Independent partial sums the NCC keeps (8 f32: one AVX register, two SSE ones).
pub(crate) const LANES: usize = 8;

/// Window samples the portable kernel handles at once (a multiple of `LANES`).
const CHUNK: usize = 64;

/// A homography applied to window offsets around one pixel: base + dx · hx + dy · hy (f32).
pub(crate) struct Warp {
    pub base: glam::Vec3,
    pub hx: glam::Vec3,
    pub hy: glam::Vec3,
}

/// A window's samples: offsets, weights and weight × centred reference grey value, each
/// padded to a multiple of `LANES` (padding: weight 0 at a real sample's offset).
pub(crate) struct Samples<'a> {
    pub dx: &'a [f32],
    pub dy: &'a [f32],
    pub w: &'a [f32],
    pub wa: &'a [f32],
    /// The real samples: those from here on are padding.
    pub count: usize,
}

/// Per lane: Σ w·b, Σ w·b², Σ wa·b over the warped samples b.
pub(crate) type Sums = [[f32; LANES]; 3];

/// The lane sums of `samples` warped into `img`, or `None` when a sample falls behind the
/// source or outside its pixel centres' hull.
pub(crate) fn sums(warp: &Warp, samples: &Samples, img: &GrayImage) -> Option<Sums> {
    debug_assert!(samples.w.len().is_multiple_of(LANES));
    #[cfg(target_arch = "x86_64")]
    if x86::usable(img) {
        // SAFETY: `usable` checked that the CPU has AVX2 and that the image's indices fit
        // the gathers' i32.
        return unsafe { x86::sums(warp, samples, img) };
    }
    portable(warp, samples, img)
}

/// The kernel every CPU runs: a warp loop and a sum loop the compiler vectorises, the
/// bilinear reads between them.
pub(crate) fn portable(warp: &Warp, samples: &Samples, img: &GrayImage) -> Option<Sums> {
    let last = ((img.width - 1) as f32, (img.height - 1) as f32);
    let (mut s_b, mut s_bb, mut s_ab) = ([0.0f32; LANES], [0.0f32; LANES], [0.0f32; LANES]);
    let (mut xs, mut ys, mut bs) = ([0.0f32; CHUNK], [0.0f32; CHUNK], [0.0f32; CHUNK]);
    for start in (0..samples.w.len()).step_by(CHUNK) {
        let end = (start + CHUNK).min(samples.w.len());
        let len = end - start;
        let inside = warp.samples(
            &samples.dx[start..end],
            &samples.dy[start..end],
            last,
            &mut xs[..len],
            &mut ys[..len],
        );
        if !inside {
            return None;
        }
        for k in 0..len {
            bs[k] = img.bilinear_f32(xs[k], ys[k]);
        }
        let (w, wa) = (&samples.w[start..end], &samples.wa[start..end]);
        for ((b, w), wa) in bs[..len]
            .chunks_exact(LANES)
            .zip(w.chunks_exact(LANES))
            .zip(wa.chunks_exact(LANES))
        {
            for l in 0..LANES {
                let wb = w[l] * b[l];
                s_b[l] += wb;
                s_bb[l] += wb * b[l];
                s_ab[l] += wa[l] * b[l];
            }
        }
    }
    Some([s_b, s_bb, s_ab])
}

impl Warp {
    /// The source image coordinates (pixel centres at integers) of each offset, into `xs`,
    /// `ys`; whether every sample lies in front of the source and within [0, last].
    fn samples(
        &self,
        dx: &[f32],
        dy: &[f32],
        last: (f32, f32),
        xs: &mut [f32],
        ys: &mut [f32],
    ) -> bool {
        let (b, hx, hy) = (self.base, self.hx, self.hy);
        let mut inside = true;
        for k in 0..xs.len() {
            let (dx, dy) = (dx[k], dy[k]);
            let pz = b.z + hx.z * dx + hy.z * dy;
            let inv = 1.0 / pz;
            let sx = (b.x + hx.x * dx + hy.x * dy) * inv - 0.5;
            let sy = (b.y + hx.y * dx + hy.y * dy) * inv - 0.5;
            // NaN fails every comparison, so it counts as outside.
            inside &= (pz > 0.0) & (sx >= 0.0) & (sy >= 0.0) & (sx <= last.0) & (sy <= last.1);
            xs[k] = sx;
            ys[k] = sy;
        }
        inside
    }
}

#[cfg(target_arch = "x86_64")]
mod x86 {
    use std::arch::x86_64::*;

    use super::{Samples, Sums, Warp, LANES};
    use crate::view::GrayImage;

    /// Whether the AVX2 kernel may read `img`: the CPU has AVX2, and every pixel index
    /// (and the clamps' 2-pixel minimum) fits an i32.
    pub(super) fn usable(img: &GrayImage) -> bool {
        img.width >= 2
            && img.height >= 2
            && img
                .width
                .checked_mul(img.height)
                .is_some_and(|n| n <= i32::MAX as usize)
            && is_x86_feature_detected!("avx2")
    }

    /// `portable`, eight samples per register: the same operations in the same order per
    /// sample (warp, range test, truncation and clamps of `GrayImage::bilinear_f32`, its
    /// three interpolations), lane l summing samples l, l + 8, … as there.
    ///
    /// # Safety
    /// The CPU has AVX2, and `usable(img)` holds.
    #[target_feature(enable = "avx2")]
    pub(super) unsafe fn sums(warp: &Warp, s: &Samples, img: &GrayImage) -> Option<Sums> {
        let n = s.w.len();
        assert!(s.dx.len() >= n && s.dy.len() >= n && s.wa.len() >= n && n.is_multiple_of(LANES));
        let h = Homography8::new(warp);
        let set = |v: f32| _mm256_set1_ps(v);
        let last_x = set((img.width - 1) as f32);
        let last_y = set((img.height - 1) as f32);
        let int = |v: usize| _mm256_set1_epi32(v as i32);
        let max_x0 = int(img.width - 2);
        let max_y0 = int(img.height - 2);
        let stride = int(img.width);
        let data = img.data.as_ptr();
        let zero = set(0.0);
        let (mut s_b, mut s_bb, mut s_ab) = (zero, zero, zero);
        for k in (0..n).step_by(LANES) {
            // SAFETY: k + 8 ≤ n ≤ each slice's length (asserted above).
            let (dx, dy) = unsafe {
                (
                    _mm256_loadu_ps(s.dx.as_ptr().add(k)),
                    _mm256_loadu_ps(s.dy.as_ptr().add(k)),
                )
            };
            let (sx, sy, pz) = h.apply(dx, dy);
            // Ordered comparisons: NaN is outside, as in the portable kernel.
            let inside = _mm256_and_ps(
                _mm256_and_ps(
                    _mm256_cmp_ps::<_CMP_GT_OQ>(pz, zero),
                    _mm256_cmp_ps::<_CMP_GE_OQ>(sx, zero),
                ),
                _mm256_and_ps(
                    _mm256_and_ps(
                        _mm256_cmp_ps::<_CMP_GE_OQ>(sy, zero),
                        _mm256_cmp_ps::<_CMP_LE_OQ>(sx, last_x),
                    ),
                    _mm256_cmp_ps::<_CMP_LE_OQ>(sy, last_y),
                ),
            );
            if _mm256_movemask_ps(inside) != 0xff {
                return None;
            }
            // In range, so truncation is the portable kernel's `as i32`.
            let x0 = _mm256_min_epi32(_mm256_cvttps_epi32(sx), max_x0);
            let y0 = _mm256_min_epi32(_mm256_cvttps_epi32(sy), max_y0);
            let fx = _mm256_sub_ps(sx, _mm256_cvtepi32_ps(x0));
            let fy = _mm256_sub_ps(sy, _mm256_cvtepi32_ps(y0));
            // x0 ≤ width − 2, so bilinear_f32's x1 is x0 + 1: each row's two values are one
            // 8-byte read, four samples to a gather. Likewise y0 ≤ height − 2, so its y1 is
            // y0 + 1: the bottom row starts one stride after the top.
            let at0 = _mm256_add_epi32(_mm256_mullo_epi32(y0, stride), x0);
            let at1 = _mm256_add_epi32(at0, stride);
            // A last run whose samples 4–7 are padding reads 0–3 only (see `pairs`).
            let low = s.count <= k + 4;
            // SAFETY: every index and its right neighbour are pixels of the image (clamped
            // above, below width × height ≤ i32::MAX).
            let (top, bottom) = unsafe { (pairs(data, at0, low), pairs(data, at1, low)) };
            let v = bilinear(top, bottom, fx, fy);
            // SAFETY: as for dx, dy.
            let (w, wa) = unsafe {
                (
                    _mm256_loadu_ps(s.w.as_ptr().add(k)),
                    _mm256_loadu_ps(s.wa.as_ptr().add(k)),
                )
            };
            let wb = _mm256_mul_ps(w, v);
            s_b = _mm256_add_ps(s_b, wb);
            s_bb = _mm256_add_ps(s_bb, _mm256_mul_ps(wb, v));
            s_ab = _mm256_add_ps(s_ab, _mm256_mul_ps(wa, v));
        }
        let out = |v: __m256| {
            let mut a = [0.0f32; LANES];
            // SAFETY: `a` holds 8 f32.
            unsafe { _mm256_storeu_ps(a.as_mut_ptr(), v) };
            a
        };
        Some([out(s_b), out(s_bb), out(s_ab)])
    }

    /// A [`Warp`]'s nine coefficients, each in all eight lanes.
    struct Homography8 {
        base: [__m256; 3],
        hx: [__m256; 3],
        hy: [__m256; 3],
    }

    impl Homography8 {
        /// `warp`'s coefficients, broadcast.
        #[target_feature(enable = "avx2")]
        fn new(warp: &Warp) -> Homography8 {
            let lanes = |v: glam::Vec3| v.to_array().map(|c| _mm256_set1_ps(c));
            Homography8 {
                base: lanes(warp.base),
                hx: lanes(warp.hx),
                hy: lanes(warp.hy),
            }
        }

        /// Eight offsets' source coordinates (pixel centres at integers) and projective
        /// depths: `Warp::samples`'s operations in its order.
        #[target_feature(enable = "avx2")]
        fn apply(&self, dx: __m256, dy: __m256) -> (__m256, __m256, __m256) {
            let row = |c: usize| {
                _mm256_add_ps(
                    _mm256_add_ps(self.base[c], _mm256_mul_ps(self.hx[c], dx)),
                    _mm256_mul_ps(self.hy[c], dy),
                )
            };
            let (px, py, pz) = (row(0), row(1), row(2));
            let inv = _mm256_div_ps(_mm256_set1_ps(1.0), pz);
            let half = _mm256_set1_ps(0.5);
            let sx = _mm256_sub_ps(_mm256_mul_ps(px, inv), half);
            let sy = _mm256_sub_ps(_mm256_mul_ps(py, inv), half);
            (sx, sy, pz)
        }
    }

    /// `GrayImage::bilinear_f32`'s three interpolations, from the (left, right) values of
    /// the top and bottom rows.
    #[target_feature(enable = "avx2")]
    fn bilinear(top: (__m256, __m256), bottom: (__m256, __m256), fx: __m256, fy: __m256) -> __m256 {
        let ((d00, d01), (d10, d11)) = (top, bottom);
        let top = _mm256_add_ps(d00, _mm256_mul_ps(_mm256_sub_ps(d01, d00), fx));
        let bottom = _mm256_add_ps(d10, _mm256_mul_ps(_mm256_sub_ps(d11, d10), fx));
        _mm256_add_ps(top, _mm256_mul_ps(_mm256_sub_ps(bottom, top), fy))
    }

    /// The values at `index` and `index + 1` of `data` for eight indices: (left, right), in
    /// the indices' order; with `low`, indices 4–7 are not read and get 0–3's values. (For
    /// padding only: its weight 0 makes its lanes add ±0, which leaves a lane's sum, never
    /// −0, unchanged: the portable kernel's bits.)
    ///
    /// # Safety
    /// The CPU has AVX2; every `index + 1` is within `data`.
    #[target_feature(enable = "avx2")]
    unsafe fn pairs(data: *const f32, index: __m256i, low: bool) -> (__m256, __m256) {
        // SAFETY: the caller's; scale 4 reads the 8 bytes at data[index].
        let lo = unsafe { _mm256_i32gather_pd::<4>(data.cast(), _mm256_castsi256_si128(index)) };
        let hi = if low {
            lo
        } else {
            // SAFETY: as above.
            unsafe { _mm256_i32gather_pd::<4>(data.cast(), _mm256_extracti128_si256::<1>(index)) }
        };
        // lo holds samples 0–3 as (left, right) pairs, hi samples 4–7. Per 128-bit half,
        // shuffle takes lefts (rights) of two samples from lo then two from hi: 0 1 4 5 | 2 3
        // 6 7; the 64-bit permutation restores 0 … 7.
        let (lo, hi) = (_mm256_castpd_ps(lo), _mm256_castpd_ps(hi));
        let order = |v: __m256| {
            _mm256_castpd_ps(_mm256_permute4x64_pd::<0b11_01_10_00>(_mm256_castps_pd(v)))
        };
        (
            order(_mm256_shuffle_ps::<0b10_00_10_00>(lo, hi)),
            order(_mm256_shuffle_ps::<0b11_01_11_01>(lo, hi)),
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::PixelRng;

    /// A random texture.
    fn image(w: usize, h: usize) -> GrayImage {
        let mut rng = PixelRng::new(7, 1, 2, 3);
        GrayImage {
            width: w,
            height: h,
            data: (0..w * h).map(|_| rng.uniform() as f32).collect(),
        }
    }

    /// The kernel chosen at run time gives the portable kernel's bits, for warps inside,
    /// straddling the border, exactly on the last pixel centre, and behind the camera.
    #[test]
    fn the_chosen_kernel_gives_the_portable_bits() {
        let img = image(97, 61);
        #[cfg(target_arch = "x86_64")]
        if is_x86_feature_detected!("avx2") {
            assert!(x86::usable(&img), "the AVX2 kernel is not the one chosen");
        }
        let mut rng = PixelRng::new(11, 0, 0, 0);
        let (mut dx, mut dy, mut w, mut wa) = (vec![], vec![], vec![], vec![]);
        for y in (-5..=5).step_by(2) {
            for x in (-5..=5).step_by(2) {
                dx.push(x as f32);
                dy.push(y as f32);
                w.push(rng.uniform() as f32);
                wa.push(rng.signed() as f32);
            }
        }
        let count = w.len();
        assert!(
            count % LANES <= 4,
            "the test's window must end in a half-padded run"
        );
        while !w.len().is_multiple_of(LANES) {
            dx.push(dx[0]);
            dy.push(dy[0]);
            w.push(0.0);
            wa.push(0.0);
        }
        let samples = Samples {
            dx: &dx,
            dy: &dy,
            w: &w,
            wa: &wa,
            count,
        };
        let (mut some, mut none) = (0, 0);
        for i in 0..4000 {
            let mut r = |s: f64| (rng.signed() * s) as f32;
            let z = if i % 50 == 0 { -1.0 } else { 1.0 + r(0.2) };
            // Bases from inside to beyond the image; every 97th puts the window's last
            // samples exactly on the last pixel centres (x = 96, y = 60).
            let warp = if i % 97 == 0 {
                Warp {
                    base: glam::Vec3::new(91.5, 55.5, 1.0),
                    hx: glam::Vec3::X,
                    hy: glam::Vec3::Y,
                }
            } else {
                Warp {
                    base: glam::Vec3::new((48.0 + r(60.0)) * z, (30.0 + r(40.0)) * z, z),
                    hx: glam::Vec3::new(1.0 + r(0.3), r(0.3), r(0.002)),
                    hy: glam::Vec3::new(r(0.3), 1.0 + r(0.3), r(0.002)),
                }
            };
            let a = sums(&warp, &samples, &img);
            let b = portable(&warp, &samples, &img);
            let bits = |s: Option<Sums>| s.map(|s| s.map(|l| l.map(f32::to_bits)));
            assert_eq!(bits(a), bits(b), "warp {i}");
            if a.is_some() {
                some += 1;
            } else {
                none += 1;
            }
        }
        assert!(some > 1000 && none > 500, "{some} inside, {none} outside");
    }
}
