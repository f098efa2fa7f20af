//! A counter-based random stream: each pixel's draws follow from (seed, view, iteration,
//! pixel), so the maps are the same whatever the thread count or order.

/// SplitMix64's finaliser.
fn mix(mut x: u64) -> u64 {
    x = x.wrapping_add(0x9e37_79b9_7f4a_7c15);
    x = (x ^ (x >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    x = (x ^ (x >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    x ^ (x >> 31)
}

/// The draws of one pixel in one iteration.
pub(crate) struct PixelRng(u64);

impl PixelRng {
    /// The stream of `pixel` in `iteration` of view `view` under `seed`.
    pub(crate) fn new(seed: u64, view: u64, iteration: u64, pixel: u64) -> PixelRng {
        PixelRng(mix(mix(mix(seed ^ mix(view)) ^ iteration) ^ pixel))
    }

    /// Uniform in [0, 1).
    pub(crate) fn uniform(&mut self) -> f64 {
        self.0 = mix(self.0);
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }

    /// Uniform in [-1, 1).
    pub(crate) fn signed(&mut self) -> f64 {
        2.0 * self.uniform() - 1.0
    }
}
