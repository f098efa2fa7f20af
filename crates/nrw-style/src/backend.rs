//! The seam between descriptors and the network that computes them. Only the CPU backend
//! ([`Vgg`]) exists, since nothing here is built that cannot be tested; a GPU backend would
//! implement [`Backend`] and [`crate::describe`] would take it unchanged.

use crate::vgg::{Arch, Vgg};
use crate::Parallelism;

/// What a style descriptor needs from a network.
pub trait Backend: Sync {
    /// Which VGG the weights are (tiers name their architecture).
    fn arch(&self) -> Arch;
    /// SHA-256 of the weights file, recorded with every descriptor.
    fn weights_sha256(&self) -> &str;
    /// Gram matrices (channels, f64 row-major) of the style layers listed in `taps`
    /// (ascending indices into [`crate::STYLE_LAYERS`]) of a preprocessed CHW input.
    fn style_grams(
        &self,
        input: &[f32],
        h: usize,
        w: usize,
        taps: &[usize],
        par: Parallelism,
    ) -> Vec<(usize, Vec<f64>)>;
}

impl Backend for Vgg {
    fn arch(&self) -> Arch {
        self.arch
    }

    fn weights_sha256(&self) -> &str {
        &self.sha256
    }

    fn style_grams(
        &self,
        input: &[f32],
        h: usize,
        w: usize,
        taps: &[usize],
        par: Parallelism,
    ) -> Vec<(usize, Vec<f64>)> {
        Vgg::style_grams(self, input, h, w, taps, par)
    }
}
