//! The z-buffer the splat loops share: one key per pixel (depth bits over point index) in a
//! bordered grid, kept nearest by a branch-free min. Its own module so the portable loops
//! (`splat`), the AVX2 kernels (`simd`) and occlusion culling (`occlusion`) all depend on it
//! and not on each other.

/// Nearest-point keys, one per pixel, row-major, with a border of 2 × `reach` pixels on every
/// side: a splat is drawn when its centre pixel is at most `reach` outside the image, so its
/// square never needs clipping (the border is not part of the render).
///
/// A key is stored as the f64 whose bits it is: keys are below f32::INFINITY's bits shifted
/// by 32, so as f64 they are positive, finite and normal, and f64 order is key order. That
/// lets one `minsd` keep the nearest point without a branch (see `keep_nearest`).
pub(crate) struct ZBuffer {
    pub(crate) keys: Vec<f64>,
    pub(crate) width: i64,
    pub(crate) height: i64,
    /// Pixels a splat reaches from the pixel holding its centre: floor(r + 0.5).
    pub(crate) reach: i64,
    /// Row length including the border.
    pub(crate) stride: i64,
}

/// A pixel no point reached (every key is smaller).
pub(crate) const EMPTY: f64 = f64::INFINITY;

/// Keys allocated past the last row (see `ZBuffer::new`).
pub(crate) const SLACK: usize = 3;

impl ZBuffer {
    pub(crate) fn new(width: u32, height: u32, radius: f32) -> ZBuffer {
        let reach = (radius as f64 + 0.5).floor() as i64;
        let stride = width as i64 + 4 * reach;
        ZBuffer {
            // (+ SLACK: the AVX2 kernel reads and writes back up to 3 keys past a square.)
            keys: vec![EMPTY; (stride * (height as i64 + 4 * reach)) as usize + SLACK],
            width: width as i64,
            height: height as i64,
            reach,
            stride,
        }
    }

    /// The keys of image row `y` (border excluded).
    pub(crate) fn row(&self, y: i64) -> &[f64] {
        let start = ((y + 2 * self.reach) * self.stride + 2 * self.reach) as usize;
        &self.keys[start..start + self.width as usize]
    }
}

/// `slot = min(slot, cand)` as one `minsd`, which returns `slot` when `cand` is NaN.
///
/// Written with SSE2 intrinsics on purpose: LLVM may turn a plain `min` or `if` whose
/// operand is a load into a conditional branch (it did in a stand-alone scatter loop, where
/// the near coin-toss z-test then ran 2.2× slower), and the intrinsic leaves it no choice.
#[inline(always)]
pub(crate) fn keep_nearest(slot: &mut f64, cand: f64) {
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::x86_64::{_mm_cvtsd_f64, _mm_min_sd, _mm_set_sd};
        // SAFETY: SSE2 is part of every x86_64 target; these touch registers only.
        *slot = unsafe { _mm_cvtsd_f64(_mm_min_sd(_mm_set_sd(cand), _mm_set_sd(*slot))) };
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        if cand < *slot {
            *slot = cand;
        }
    }
}

/// Positive f32 bits order like the values: one u64 min = nearest, then lowest index.
#[inline(always)]
pub(crate) fn key(z: f32, index: usize) -> f64 {
    // z > near > 0 and finite, so the bits are those of a positive normal f64 (`ZBuffer`).
    f64::from_bits((z.to_bits() as u64) << 32 | index as u64)
}
