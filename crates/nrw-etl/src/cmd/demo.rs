//! `nrw-etl demo`: the main job end to end on the embedded synthetic scene, so a fresh
//! machine can run the tool before its user owns a reconstruction.

use std::path::PathBuf;

use clap::Args;

use super::Bars;
use crate::error::Result;

/// Arguments of `demo`.
#[derive(Debug, Args)]
pub struct DemoArgs {
    /// Folder for the demo: DIR/scene (the synthetic COLMAP scene), DIR/dataset, DIR/export
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

/// Run `demo`: synthesise the scene, then every stage (ingest, split, style, triplets,
/// export, qa) through the pipeline runner.
pub fn run(args: &DemoArgs) -> Result<()> {
    let dataset = nrw_dataset::Location::from(args.out.join("dataset"));
    let (report, out) = nrw_pipeline::runner::demo(
        &args.out,
        args.spec.as_deref(),
        args.seed,
        args.weights.as_deref(),
        &Bars::new(false),
        &mut |d| super::print_report(&nrw_pipeline::report::stage(&dataset, d)),
    )?;
    super::print_report(&nrw_pipeline::report::synth(&report));
    println!("scene:   {}", args.out.join("scene").display());
    println!("dataset: {}", out.dataset);
    println!("export:  {}", out.export.expect("the demo exports"));
    println!("report:  {}", out.report.expect("the demo writes a report"));
    Ok(())
}
