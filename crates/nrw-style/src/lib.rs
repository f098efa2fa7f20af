//! Style descriptors of photos: the Gram matrices of VGG16 activations (Gatys et al.), the
//! appearance distance the paper mines its triplets with. Weights come from a file the user
//! gives; the tool never downloads anything.

pub mod backend;
#[macro_use]
pub mod isa;
pub mod conv;
pub mod descriptor;
pub mod error;
pub mod matmul;
mod pool;
pub mod preprocess;
pub mod tensor;
pub mod vgg;
pub mod winograd;

pub use backend::{Backend, Grams, NetInput};
pub use conv::ConvAlgo;
pub use descriptor::{
    central_crop, color_stats, describe, distance2, from_grams, network_input, Tier,
};
pub use error::{Result, StyleError};
pub use matmul::gram;
pub use nrw_gemm::Parallelism;
pub use preprocess::{load_rgb01, to_input, to_input_01, Preprocess, MAX_EXACT_PIXELS, MIN_SIDE};
pub use tensor::Activation;
pub use vgg::{Arch, Convention, Vgg, STYLE_LAYERS};

/// The five Gram matrices (relu1_2 … relu5_2) of a preprocessed CHW input, f64, row-major.
pub fn grams(
    net: &Vgg,
    input: &[f32],
    h: usize,
    w: usize,
    par: Parallelism,
) -> Vec<(usize, Vec<f64>)> {
    net.grams_of_taps(input, h, w, &[0, 1, 2, 3, 4], par)
}

/// The five Gram matrices of one image file exactly as given (no resize or crop), as
/// safetensors bytes with f32 tensors `gram_relu1_2` … `gram_relu5_2`.
pub fn image_grams_safetensors(
    net: &dyn Backend,
    path: &std::path::Path,
    p: Preprocess,
) -> Result<Vec<u8>> {
    let img = load_rgb01(path)?;
    let input = NetInput {
        chw: to_input_01(&img, p),
        height: img.height() as usize,
        width: img.width() as usize,
    };
    let all: Vec<usize> = (0..STYLE_LAYERS.len()).collect();
    let g = backend::grams_of_one(net, &input, &all)?;
    let data: Vec<(String, usize, Vec<u8>)> = g
        .iter()
        .zip(STYLE_LAYERS)
        .map(|((c, m), layer)| {
            (
                format!("gram_{layer}"),
                *c,
                m.iter().flat_map(|v| (*v as f32).to_le_bytes()).collect(),
            )
        })
        .collect();
    let views: Vec<(String, safetensors::tensor::TensorView)> = data
        .iter()
        .map(|(n, c, b)| {
            (
                n.clone(),
                safetensors::tensor::TensorView::new(safetensors::Dtype::F32, vec![*c, *c], b)
                    .expect("consistent tensor"),
            )
        })
        .collect();
    let mut meta = std::collections::HashMap::new();
    meta.insert(
        "weights_sha256".to_string(),
        net.weights_sha256().to_string(),
    );
    meta.insert("preprocess".to_string(), p.name().to_string());
    meta.insert(
        "gram".to_string(),
        "G = F F^T / (C*H*W), F = ReLU output as C x (H*W)".to_string(),
    );
    safetensors::serialize(views, Some(meta)).map_err(|e| StyleError::Image {
        path: path.into(),
        problem: format!("cannot serialise: {e}"),
    })
}
