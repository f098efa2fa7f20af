//! `nrw-etl style --image`: the five VGG16 Gram matrices of one image exactly as given, so
//! anyone can check parity against another implementation without writing code.

use std::path::PathBuf;

use clap::{Args, ValueEnum};
use nrw_style::{Parallelism, Preprocess, Vgg16};

use crate::error::{EtlError, Result};

/// `--preprocess` values.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum Pre {
    /// RGB in [0,1], minus ImageNet mean, divided by std (what the weights were trained with)
    Imagenet,
    /// v/127.5 − 1, as the paper's official code scaled its inputs
    MinusOneToOne,
}

/// Arguments of `style`.
#[derive(Debug, Args)]
pub struct StyleArgs {
    /// Image to describe as given: no resize, no crop (8/16-bit, grey or colour; at least 16×16, at most 2 MP)
    #[arg(long)]
    pub image: PathBuf,
    /// VGG16 weights: safetensors with torchvision names (features.N.weight / .bias)
    #[arg(long)]
    pub weights: PathBuf,
    /// Output safetensors with f32 tensors gram_relu1_2 … gram_relu5_2
    #[arg(long)]
    pub out: PathBuf,
    /// Input scaling
    #[arg(long, value_enum, default_value = "imagenet")]
    pub preprocess: Pre,
}

/// Run `style`.
pub fn run(args: &StyleArgs) -> Result<()> {
    let net = Vgg16::load(&args.weights).map_err(|e| EtlError::Usage(e.to_string()))?;
    let p = match args.preprocess {
        Pre::Imagenet => Preprocess::Imagenet,
        Pre::MinusOneToOne => Preprocess::MinusOneToOne,
    };
    let bytes = nrw_style::image_grams_safetensors(&net, &args.image, p, Parallelism::Rayon(0))
        .map_err(|e| EtlError::Usage(e.to_string()))?;
    nrw_dataset::atomic::write_bytes_atomic(&args.out, &bytes)?;
    println!("{}", args.out.display());
    Ok(())
}
