//! `nrw-etl demo`: the main job end to end on the embedded synthetic scene, so a fresh
//! machine can run the tool before its user owns a reconstruction.

use std::path::PathBuf;

use clap::Args;

use super::ingest::{self, IngestArgs};
use crate::error::Result;

/// Arguments of `demo`.
#[derive(Debug, Args)]
pub struct DemoArgs {
    /// Folder for the demo: DIR/scene (the synthetic COLMAP scene) and DIR/dataset
    #[arg(long, default_value = "nrw-demo")]
    pub out: PathBuf,
    /// Scene spec to use instead of the embedded demo scene
    #[arg(long)]
    pub spec: Option<PathBuf>,
    /// Override the scene's seed
    #[arg(long)]
    pub seed: Option<u64>,
    /// VGG16 weights (safetensors, torchvision names) for the paper's style tier; without
    /// them the demo uses the colour-statistics tier
    #[arg(long)]
    pub weights: Option<std::path::PathBuf>,
}

/// Run `demo`: synthesise the scene, then every pipeline stage that exists (ingest, split,
/// style, triplets, export) and the QA report.
pub fn run(args: &DemoArgs) -> Result<()> {
    let spec = super::synth::load_spec(args.spec.as_deref(), args.seed)?;
    let scene = args.out.join("scene");
    super::synth::generate(&spec, &scene)?;
    let dataset = args.out.join("dataset");
    // The synthetic scene's ground-truth ADE20K labels stand in for a segmentation model.
    let summary = ingest::run(&IngestArgs {
        semantics: Some(scene.join("ground_truth/semantics")),
        ..IngestArgs::new(scene.clone(), dataset.clone())
    })?;
    if summary.kept == 0 {
        return Err(crate::error::EtlError::Usage(
            "the demo scene kept no view: this is a bug".into(),
        ));
    }
    // The paper holds out 100 photos of thousands; the demo holds out a fifth of its few.
    let val = (summary.kept / 5).max(1);
    super::split::run(&super::split::SplitArgs {
        dataset: dataset.clone(),
        val,
        seed: 0,
    })?;
    // The demo ships no network weights (nothing is downloaded): it describes style with the
    // explicit non-neural tier; `--weights FILE` selects the paper's VGG16 tier instead.
    let tier = if args.weights.is_some() {
        "vgg16-512"
    } else {
        "color-stats"
    };
    super::style::run(&super::style::StyleArgs {
        dataset: Some(dataset.clone()),
        tier: tier.into(),
        weights: args.weights.clone(),
        overwrite: true,
        image: None,
        out: None,
        preprocess: super::style::Pre::Imagenet,
        quiet: false,
    })?;
    let train = summary.kept - val;
    super::triplets::run(&super::triplets::TripletsArgs {
        dataset: dataset.clone(),
        k: 20.min(train.saturating_sub(1)).max(1),
        all_splits: false,
        pca: None,
        check_up_to: 20_000,
    })?;
    let export = args.out.join("export");
    super::export::run(&super::export::ExportArgs::official(
        dataset.clone(),
        export.clone(),
    ))?;
    let report = super::qa::run(&super::qa::QaArgs {
        dataset: dataset.clone(),
        out: None,
    })?;
    println!("scene:   {}", scene.display());
    println!("dataset: {}", dataset.display());
    println!("export:  {}", export.display());
    println!("report:  {}", report.display());
    Ok(())
}
