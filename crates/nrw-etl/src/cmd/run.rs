//! `nrw-etl run PIPELINE SCENE --out DIR`: the stages a pipeline file lists, in order, with
//! its parameters (`pipelines/paper.toml` reproduces the paper's settings).

use std::path::PathBuf;

use clap::Args;
use nrw_pipeline::runner::Pipeline;

use super::Bars;
use crate::error::Result;

/// Arguments of `run`.
#[derive(Debug, Args)]
pub struct RunArgs {
    /// Pipeline file (TOML), e.g. pipelines/paper.toml
    pub pipeline: PathBuf,
    /// Scene folder (COLMAP layout)
    pub scene: PathBuf,
    /// Output folder: DIR is the dataset; an export goes to DIR/export, the report to DIR/qa
    #[arg(long)]
    pub out: nrw_dataset::Location,
    /// VGG weights for a style stage with a VGG tier (safetensors; never downloaded)
    #[arg(long)]
    pub weights: Option<PathBuf>,
    /// A SegFormer (config.json + model.safetensors): ingest labels every kept photo with it
    /// (mode and size from [ingest] segment_mode / segment_size) and the export includes them
    #[arg(long)]
    pub segment_weights: Option<PathBuf>,
    /// Where a [densify] table writes its dense workspace when the scene folder cannot take
    /// it (read-only, or a dense/ of COLMAP's undistorter without a cloud); ingest then
    /// renders DIR/fused.ply [default: SCENE/dense]
    #[arg(long, value_name = "DIR")]
    pub dense_out: Option<PathBuf>,
    /// Change one key of the pipeline file for this run, as the file would spell it
    /// (repeatable): `--set split.val=20 --set export.layout=gsplat`. Checked as the file's own
    /// keys are (unknown keys and wrong types are refused, naming the key) before any stage
    /// runs; the effective settings are recorded with the dataset
    #[arg(long = "set", value_name = "TABLE.KEY=VALUE")]
    pub set: Vec<nrw_pipeline::runner::Override>,
}

/// Run `run`; returns whether any view was kept (the caller maps "none" to exit code 3).
pub fn run(args: &RunArgs) -> Result<bool> {
    let p = Pipeline::load_with(&args.pipeline, &args.set).map_err(file_setting)?;
    let out = nrw_pipeline::runner::run(
        &p,
        &args.scene,
        args.dense_out.as_deref(),
        &args.out,
        &args.out.join(nrw_dataset::EXPORT_DIR),
        nrw_pipeline::runner::Models {
            vgg: args.weights.as_deref(),
            segformer: args.segment_weights.as_deref(),
        },
        &Bars::new(false),
        &mut |d| super::print_report(&nrw_pipeline::report::stage(&args.out, d)),
    )
    .map_err(file_setting)?;
    Ok(out.kept)
}

/// A run's settings come from its pipeline file, so an error names them by their keys there;
/// only the models and densify's workspace are flags of `run` itself.
fn file_setting(e: nrw_pipeline::PipelineError) -> crate::error::EtlError {
    use nrw_pipeline::{PipelineError, Setting};
    match e {
        PipelineError::Config {
            setting: Setting::Weights | Setting::SegmentWeights,
            ..
        } => e.into(),
        // The one setting of a run that is a flag of `run` itself: densify's workspace.
        PipelineError::Config { setting, problem } => {
            crate::error::EtlError::Pipeline(PipelineError::Config {
                setting,
                problem: problem.replace(&Setting::DenseOut.to_string(), "--dense-out"),
            })
        }
        e @ (PipelineError::Preflight { .. } | PipelineError::Override { .. }) => {
            crate::error::EtlError::Keys(e)
        }
        e => crate::error::EtlError::Pipeline(e),
    }
}
