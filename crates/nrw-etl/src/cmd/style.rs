//! `nrw-etl style`: arguments → `nrw_pipeline::style` (a dataset's descriptors, whole or one
//! unit), or the exact Gram matrices of one image (`--image`).

use std::path::PathBuf;

use clap::{Args, ValueEnum};
use nrw_pipeline::style::StyleConfig;
use nrw_style::{Preprocess, Tier};

use super::{Bars, UnitArgs};
use crate::error::Result;

/// `--preprocess` values.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum Pre {
    /// RGB in [0,1], minus ImageNet mean, divided by std (what the weights were trained with)
    Imagenet,
    /// v/127.5 − 1, as the paper's official code scaled its inputs
    MinusOneToOne,
}

impl From<Pre> for Preprocess {
    fn from(p: Pre) -> Self {
        match p {
            Pre::Imagenet => Preprocess::Imagenet,
            Pre::MinusOneToOne => Preprocess::MinusOneToOne,
        }
    }
}

/// Arguments of `style`.
#[derive(Debug, Args)]
pub struct StyleArgs {
    /// Dataset folder: describe every kept photo into DATASET/descriptors/
    #[arg(required_unless_present = "image")]
    pub dataset: Option<nrw_dataset::Location>,
    /// Descriptor tier: vgg16-<128|256|512|full>[-l<layers 1-5>], the same with vgg19,
    /// official[-N] (the published code's distance: N×N centre crop, default 512, no resize,
    /// v·2/255 − 1 into tensorflow-vgg's Caffe VGG16, per-layer mean squared Gram difference;
    /// needs that vgg16.npy; for the official export's dist_<name>.pckl), or color-stats (no
    /// weights needed)
    #[arg(long, default_value_t = nrw_pipeline::style::StyleConfig::new("").tier, value_parser = |s: &str| s.parse::<Tier>())]
    pub tier: Tier,
    /// Weights, never downloaded: VGG16 or VGG19 safetensors with torchvision names
    /// (features.N.weight / .bias) for the vgg tiers; the published code's vgg16.npy
    /// (tensorflow-vgg, the file its README links) for the official tiers
    #[arg(long)]
    pub weights: Option<PathBuf>,
    /// Replace existing descriptors of another tier or weights
    #[arg(long)]
    pub overwrite: bool,
    /// Instead of a dataset: one image as given (no resize, no crop; 8/16-bit, grey or colour; 16×16 to 2 MP)
    #[arg(long, requires = "out")]
    pub image: Option<PathBuf>,
    /// With --image: output safetensors with f32 tensors gram_relu1_2 … gram_relu5_2
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Network input scaling: torchvision's ImageNet mean/std, or the official code's v/127.5 − 1 (recorded with the descriptors; the official tiers always use the published code's own)
    #[arg(long, value_enum, default_value = "imagenet")]
    pub preprocess: Pre,
    /// Photos per descriptor part (the unit of resumption and of --unit work units)
    #[arg(long, default_value_t = nrw_pipeline::style::PART_PHOTOS)]
    pub photos_per_part: usize,
    #[command(flatten)]
    pub unit: UnitArgs,
    /// No progress bar
    #[arg(long)]
    pub quiet: bool,
}

/// Run `style`.
pub fn run(args: &StyleArgs) -> Result<()> {
    if let Some(image) = &args.image {
        let out = args.out.as_ref().expect("clap requires --out with --image");
        nrw_pipeline::style::image_grams(
            args.weights.as_deref(),
            image,
            args.preprocess.into(),
            out,
        )?;
        println!("{}", out.display());
        return Ok(());
    }
    let dir = args
        .dataset
        .as_ref()
        .expect("clap requires DATASET without --image");
    let tier = args.tier.clone();
    let cfg = StyleConfig {
        tier,
        weights: args.weights.clone(),
        overwrite: args.overwrite,
        preprocess: args.preprocess.into(),
        photos_per_part: args.photos_per_part,
        ..StyleConfig::new(dir)
    };
    let bars = Bars::new(args.quiet);
    let s = match args.unit.unit()? {
        Some(unit) => nrw_pipeline::style::style_unit(&cfg, unit, &bars)?,
        None => nrw_pipeline::style::style(&cfg, &bars)?,
    };
    if !args.quiet {
        super::print_report(&nrw_pipeline::report::style(&s));
    }
    Ok(())
}
