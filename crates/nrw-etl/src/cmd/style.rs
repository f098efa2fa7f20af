//! `nrw-etl style`: arguments → `nrw_pipeline::style` (a dataset's descriptors, whole or one
//! unit), or the exact Gram matrices of one image (`--image`).

use std::path::PathBuf;

use clap::Args;
use nrw_pipeline::style::StyleConfig;

use super::{Bars, UnitArgs};
use crate::error::Result;

/// Arguments of `style`.
#[derive(Debug, Args)]
pub struct StyleArgs {
    /// Dataset folder: describe every kept photo into DATASET/descriptors/
    #[arg(required_unless_present = "image")]
    pub dataset: Option<nrw_dataset::Location>,
    #[command(flatten)]
    pub settings: nrw_pipeline::settings::style::StyleSettings,
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
            args.settings.preprocess.into(),
            out,
        )?;
        println!("{}", out.display());
        return Ok(());
    }
    let dir = args
        .dataset
        .as_ref()
        .expect("clap requires DATASET without --image");
    let cfg = StyleConfig {
        overwrite: args.overwrite,
        ..args.settings.config(dir, args.weights.clone())?
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
