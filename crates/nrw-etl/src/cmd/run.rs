//! `nrw-etl run PIPELINE SCENE --out DIR`: the stages a pipeline file lists, in order, with
//! its parameters (`pipelines/paper.toml` reproduces the paper's settings).

use std::path::{Path, PathBuf};

use clap::Args;
use serde::Deserialize;

use super::export::{ExportArgs, Layout};
use super::ingest::IngestArgs;
use super::split::SplitArgs;
use crate::error::{EtlError, Result};

/// A pipeline file: each table present is a stage to run, with its parameters.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Pipeline {
    pub name: String,
    pub ingest: Option<IngestStage>,
    pub split: Option<SplitStage>,
    pub export: Option<ExportStage>,
}

/// `[ingest]`: render and filter.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct IngestStage {
    pub min_dim: u32,
    pub radius: f32,
    pub max_empty: f64,
    pub min_photo_side: u32,
    pub rows_per_shard: usize,
}

/// `[split]`: validation photos and seed.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SplitStage {
    pub val: usize,
    pub seed: u64,
}

/// `[export]`: the layout to write into DIR/export.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ExportStage {
    pub layout: String,
    /// false: export without semantics (train with --use_semantic=False)
    #[serde(default = "yes")]
    pub semantics: bool,
}

fn yes() -> bool {
    true
}

/// Arguments of `run`.
#[derive(Debug, Args)]
pub struct RunArgs {
    /// Pipeline file (TOML), e.g. pipelines/paper.toml
    pub pipeline: PathBuf,
    /// Scene folder (COLMAP layout)
    pub scene: PathBuf,
    /// Output folder: DIR is the dataset; an export goes to DIR/export
    #[arg(long)]
    pub out: PathBuf,
}

/// Parse a pipeline file, naming the file in errors.
pub fn load(path: &Path) -> Result<Pipeline> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| EtlError::Usage(format!("{}: {e}", path.display())))?;
    toml::from_str(&text).map_err(|e| EtlError::Usage(format!("{}: {e}", path.display())))
}

/// Run `run`; returns whether any view was kept (the caller maps "none" to exit code 3).
pub fn run(args: &RunArgs) -> Result<bool> {
    let p = load(&args.pipeline)?;
    let mut kept = true;
    if let Some(i) = &p.ingest {
        let mut a = IngestArgs::new(args.scene.clone(), args.out.clone());
        (
            a.min_dim,
            a.radius,
            a.max_empty,
            a.min_photo_side,
            a.rows_per_shard,
        ) = (
            i.min_dim,
            i.radius,
            i.max_empty,
            i.min_photo_side,
            i.rows_per_shard,
        );
        kept = super::ingest::run(&a)?.kept > 0;
    }
    if !kept {
        eprintln!("pipeline {}: no view kept, later stages skipped", p.name);
        return Ok(false);
    }
    if let Some(s) = &p.split {
        super::split::run(&SplitArgs {
            dataset: args.out.clone(),
            val: s.val,
            seed: s.seed,
        })?;
    }
    if let Some(e) = &p.export {
        let layout = match e.layout.as_str() {
            "official" => Layout::Official,
            "tfrecord" => Layout::Tfrecord,
            "files" => Layout::Files,
            other => {
                return Err(EtlError::Usage(format!(
                    "{}: export.layout {other:?} is not official, tfrecord or files",
                    args.pipeline.display()
                )))
            }
        };
        super::export::run(&ExportArgs {
            layout,
            no_semantics: !e.semantics,
            ..ExportArgs::official(args.out.clone(), args.out.join("export"))
        })?;
    }
    Ok(true)
}
