//! The seam between descriptors and the network that computes them: what the style stage
//! calls. Only the CPU backend ([`Vgg`]) exists, since nothing here is built that cannot be
//! tested; a GPU backend implements [`Backend`] and the stage takes it unchanged (it holds no
//! CPU-only type: threads, kernels and memory are the backend's business).

use rayon::prelude::*;

use crate::error::{Result, StyleError};
use crate::vgg::{Arch, Vgg};
use nrw_gemm::Parallelism;

/// One preprocessed image for a network: CHW f32, `3 × height × width` values.
#[derive(Debug, Clone)]
pub struct NetInput {
    pub chw: Vec<f32>,
    pub height: usize,
    pub width: usize,
}

/// The Gram matrices of one input: (channels, f64 row-major) for each tapped style layer.
pub type Grams = Vec<(usize, Vec<f64>)>;

/// What a style descriptor needs from a network.
pub trait Backend: Sync {
    /// Which VGG the weights are (tiers name their architecture).
    fn arch(&self) -> Arch;
    /// SHA-256 of the weights file, recorded with every descriptor.
    fn weights_sha256(&self) -> &str;
    /// What did the arithmetic (an instruction set, a GPU), recorded with the descriptors
    /// because the last bits of their values depend on it.
    fn device(&self) -> String;
    /// How many inputs one call should take: callers batch by it, and it bounds their memory.
    fn batch_size(&self) -> usize;
    /// The Gram matrices of the style layers listed in `taps` (ascending indices into
    /// [`crate::STYLE_LAYERS`]) of every input, in the inputs' order.
    fn style_grams(&self, batch: &[NetInput], taps: &[usize]) -> Result<Vec<Grams>>;
}

/// The Grams of one input: a batch of one, and a backend that returns no Grams for it is an
/// error rather than a panic.
pub fn grams_of_one<B: Backend + ?Sized>(
    net: &B,
    input: &NetInput,
    taps: &[usize],
) -> Result<Grams> {
    net.style_grams(std::slice::from_ref(input), taps)?
        .pop()
        .ok_or_else(|| StyleError::Backend {
            device: net.device(),
            problem: "no Grams returned for the one input given".into(),
        })
}

/// Refuses an input whose values do not fill its stated size (a caller's bug, not a photo's).
fn check_input(i: usize, x: &NetInput) -> Result<()> {
    let want = 3usize
        .checked_mul(x.height)
        .and_then(|n| n.checked_mul(x.width));
    if x.height == 0 || x.width == 0 || want != Some(x.chw.len()) {
        return Err(StyleError::Input {
            index: i,
            problem: format!(
                "{} values for a 3 × {} × {} input",
                x.chw.len(),
                x.height,
                x.width
            ),
        });
    }
    Ok(())
}

impl Backend for Vgg {
    fn arch(&self) -> Arch {
        self.arch
    }

    fn weights_sha256(&self) -> &str {
        &self.sha256
    }

    fn device(&self) -> String {
        crate::isa::isa().name().to_string()
    }

    /// One input per thread: each runs on its own thread (kernels without inner threads),
    /// which is how the whole machine is busiest.
    fn batch_size(&self) -> usize {
        rayon::current_num_threads()
    }

    /// A single input uses every thread inside its convolutions; a batch runs one input per
    /// thread. Both give the same bits.
    fn style_grams(&self, batch: &[NetInput], taps: &[usize]) -> Result<Vec<Grams>> {
        for (i, x) in batch.iter().enumerate() {
            check_input(i, x)?;
        }
        let one = |x: &NetInput, par| self.grams_of_taps(&x.chw, x.height, x.width, taps, par);
        Ok(match batch {
            [x] => vec![one(x, Parallelism::Rayon(0))],
            _ => batch
                .par_iter()
                .map(|x| one(x, Parallelism::None))
                .collect(),
        })
    }
}
