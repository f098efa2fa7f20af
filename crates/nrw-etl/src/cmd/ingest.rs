//! `nrw-etl ingest`: arguments → `nrw_pipeline::ingest`, and what it did, printed.

use std::path::PathBuf;

use clap::Args;
use nrw_pipeline::ingest::IngestConfig;

use super::{Bars, UnitArgs};
use crate::error::Result;
use nrw_colmap::Format;

/// Exit code of `ingest` and `run` when the run completed but every view was dropped by the
/// filters (README's exit codes).
pub const EXIT_NOTHING_KEPT: u8 = 3;

/// Arguments of `ingest`.
#[derive(Debug, Clone, Args)]
#[command(after_help = "Examples:
  nrw-etl ingest SCENE --out DATASET
  nrw-etl ingest SCENE --out DATASET --unit 2/8     # one of 8 work units, then:
  nrw-etl finalize DATASET

Work units (--unit I/N) may run in any order, at the same time, on machines sharing the
dataset folder; each renders its own shards and writes nothing else, and finalize merges
them into the bytes one process writes. docs/scale-out.md shows Slurm and Kubernetes jobs.")]
pub struct IngestArgs {
    /// Scene folder holding sparse/0/ (or sparse/) and images/, or a model folder itself;
    /// with several sub-models (sparse/0, sparse/1, …) the one with the most registered
    /// images is read, and the summary says which
    pub scene: PathBuf,
    /// Read the sub-model sparse/N instead (`nrw-etl inspect SCENE` lists them)
    #[arg(long, value_name = "N")]
    pub model: Option<u32>,
    /// Dataset folder to write (created if missing; files in it are replaced atomically)
    #[arg(long)]
    pub out: nrw_dataset::Location,
    /// Folder of the photos named in the model [default: <scene>/images]
    #[arg(long)]
    pub images: Option<PathBuf>,
    /// Read this encoding even if the other exists [default: bin when present, else txt]
    #[arg(long, value_parser = super::names(&Format::ALL, Format::name, Format::summary))]
    pub format: Option<Format>,
    /// Point cloud to render [default: <scene>/dense/fused.ply if present, else the sparse points]
    #[arg(long)]
    pub points: Option<PathBuf>,
    /// Each photo's origin: a CSV (header row) or JSON Lines file keyed by image name, with
    /// licence, author, source URL and date taken (any other column kept as given); stored in
    /// scene/photos.parquet, counted by `inspect`, written by every export as attribution.csv.
    /// Licences as SPDX ids (CC-BY-2.0), Creative Commons names or URLs, Flickr's ids 0-10
    /// or names; photos it does not name are "unknown", never guessed
    #[arg(long, value_name = "FILE")]
    pub photo_info: Option<PathBuf>,
    /// Segment each kept photo with this SegFormer (config.json + model.safetensors) instead
    /// of reading --semantics; see `nrw-etl segment --help`
    #[arg(long, conflicts_with = "semantics")]
    pub segment_weights: Option<PathBuf>,
    /// Read photos that are symbolic links out of the images folder (refused by default: a
    /// model's image names cannot make the tool read files you did not put there)
    #[arg(long)]
    pub follow_outside_links: bool,
    #[command(flatten)]
    pub settings: nrw_pipeline::settings::ingest::IngestSettings,
    #[command(flatten)]
    pub unit: UnitArgs,
    /// Worker threads [default: all cores]; output bytes do not depend on it
    #[arg(long)]
    pub threads: Option<usize>,
    /// No progress bars or summary
    #[arg(long)]
    pub quiet: bool,
    /// Print a JSON summary on stdout (for scripts)
    #[arg(long)]
    pub json: bool,
    /// Stop after this many groups of photos (a group: one views file and its record), as an
    /// interruption would (for resume tests; `--stop-after-shards` is its old name)
    #[arg(long, hide = true, alias = "stop-after-shards")]
    pub stop_after_groups: Option<usize>,
    /// Sleep this many milliseconds after each group (so tests can kill a unit mid-way;
    /// `--pause-after-shard-ms` is its old name)
    #[arg(long, hide = true, alias = "pause-after-shard-ms")]
    pub pause_after_group_ms: Option<u64>,
}

impl IngestArgs {
    /// The stage's configuration.
    pub fn config(&self) -> Result<IngestConfig> {
        let c = self
            .settings
            .config(&self.scene, &self.out, self.segment_weights.clone())?;
        Ok(IngestConfig {
            images: self.images.clone(),
            format: self.format,
            model: self.model,
            photo_info: self.photo_info.clone(),
            points: self.points.clone(),
            follow_outside_links: self.follow_outside_links,
            stop_after_groups: self.stop_after_groups,
            pause_after_group: self
                .pause_after_group_ms
                .map(std::time::Duration::from_millis),
            ..c
        })
    }
}

/// Run `ingest` (whole, or one unit); returns whether any view was kept (a unit: true).
pub fn run(args: &IngestArgs) -> Result<bool> {
    let bars = Bars::new(args.quiet);
    let cfg = args.config()?;
    match args.unit.unit()? {
        Some(unit) => {
            let s = nrw_pipeline::ingest::ingest_unit(&cfg, unit, &bars)?;
            if !args.quiet {
                super::print_report(&nrw_pipeline::report::ingest_unit(&s));
            }
            if args.json {
                println!(
                    "{}",
                    serde_json::to_string_pretty(&s).expect("summary serialises")
                );
            }
            Ok(true)
        }
        None => {
            let s = nrw_pipeline::ingest::ingest(&cfg, &bars)?;
            if !args.quiet {
                super::print_report(&nrw_pipeline::report::ingest(&s));
            }
            if args.json {
                println!(
                    "{}",
                    serde_json::to_string_pretty(&s).expect("summary serialises")
                );
            }
            Ok(s.kept > 0)
        }
    }
}
