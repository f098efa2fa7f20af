//! Style descriptors of photos: the Gram matrices of VGG16 activations (Gatys et al.), the
//! appearance distance the paper mines its triplets with. Weights come from a file the user
//! gives; the tool never downloads anything.

pub mod error;
pub mod preprocess;
pub mod vgg;

pub use error::{Result, StyleError};
pub use gemm::Parallelism;
pub use preprocess::{to_input, Preprocess};
pub use vgg::{gram, Vgg16, STYLE_LAYERS};

/// The five Gram matrices (relu1_2 … relu5_2) of a preprocessed CHW input, f64, row-major.
pub fn grams(
    net: &Vgg16,
    input: &[f32],
    h: usize,
    w: usize,
    par: Parallelism,
) -> Vec<(usize, Vec<f64>)> {
    net.style_features(input, h, w, par)
        .into_iter()
        .map(|(c, fh, fw, f)| (c, gram(c, fh, fw, &f, par)))
        .collect()
}
