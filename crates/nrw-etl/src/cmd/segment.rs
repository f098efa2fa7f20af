//! `nrw-etl segment`: arguments → `nrw_pipeline::segment` (ADE20K label maps of a scene's
//! photos from a user-given SegFormer), and what it did, printed.

use std::path::PathBuf;

use clap::Args;
use nrw_pipeline::segment::SegmentConfig;
use nrw_segment::{Mode, ModeKind};

use super::{Bars, UnitArgs};
use crate::error::{EtlError, Result};
use nrw_colmap::Format;

/// The library's mode for `--mode`/`--size` (or ingest's `--segment-mode`/`--segment-size`).
pub fn mode(kind: ModeKind, size: u32) -> Result<Mode> {
    Mode::new(kind, size).map_err(|problem| EtlError::Flag {
        flag: "--size".into(),
        problem: format!("{size}: {problem}"),
    })
}

/// Arguments of `segment`.
#[derive(Debug, Clone, Args)]
#[command(after_help = "Examples:
  nrw-etl segment SCENE --weights segformer-b0-finetuned-ade-512-512/ --out SCENE/labels
  nrw-etl ingest SCENE --out DATASET --semantics SCENE/labels
  nrw-etl ingest SCENE --out DATASET --segment-weights segformer-b0-finetuned-ade-512-512/
  nrw-etl segment SCENE --weights MODEL --out LABELS --unit 2/8   # one of 8 machines
  nrw-etl segment --images ADEChallengeData2016/images/validation --weights MODEL --out L

The model is a SegFormer fine-tuned on ADE20K-150 in the Hugging Face layout (a folder with
config.json and model.safetensors, e.g. `huggingface-cli download nvidia/segformer-b0-finetuned-ade-512-512`
on a machine with network). Nothing is downloaded. Each photo's map is an 8-bit PNG of ADE20K
ids 1..150 (schemas/ade20k.csv; 0 = unlabelled), named like the photo with .png. A run that
stops resumes: maps already written are kept. Work units (--unit I/N) write disjoint maps
into the same folder and need no finalize. docs/segmentation.md has the details.")]
pub struct SegmentArgs {
    /// Scene folder holding sparse/0/ (or sparse/) and images/, or a model folder itself;
    /// without it, every photo in --images is segmented (a folder without a model)
    #[arg(required_unless_present = "images")]
    pub scene: Option<PathBuf>,
    /// SegFormer folder (config.json + model.safetensors), or its model.safetensors
    #[arg(long)]
    pub weights: PathBuf,
    /// Label folder to write (created if missing; segment.json records the model and mode)
    #[arg(long)]
    pub out: PathBuf,
    /// Folder of the photos named in the model [default: <scene>/images]; without SCENE, the
    /// folder whose .jpg/.jpeg/.png photos (subfolders included) are segmented
    #[arg(long)]
    pub images: Option<PathBuf>,
    /// Read this encoding even if the other exists [default: bin when present, else txt]
    #[arg(long, value_parser = super::names(&Format::ALL, Format::name, Format::summary))]
    pub format: Option<Format>,
    /// How a photo is fed to the network
    #[arg(long, value_parser = super::names(&ModeKind::ALL, ModeKind::name, ModeKind::summary), default_value = "resize")]
    pub mode: ModeKind,
    /// Network input size in pixels (resize: SIZE×SIZE; whole: shorter side; slide: window and shorter side; crop: crop side)
    #[arg(long, default_value_t = 512)]
    pub size: u32,
    /// Stop with an error at the first photo that cannot be decoded, instead of warning
    #[arg(long)]
    pub strict: bool,
    /// Read photos that are symbolic links out of the images folder (refused by default: a
    /// model's image names cannot make the tool read files you did not put there)
    #[arg(long)]
    pub follow_outside_links: bool,
    #[command(flatten)]
    pub unit: UnitArgs,
    /// Worker threads [default: all cores]; the maps do not depend on it
    #[arg(long)]
    pub threads: Option<usize>,
    /// No progress bar or summary
    #[arg(long)]
    pub quiet: bool,
    /// Print a JSON summary on stdout (for scripts)
    #[arg(long)]
    pub json: bool,
}

/// Run `segment`.
pub fn run(args: &SegmentArgs) -> Result<()> {
    let cfg = SegmentConfig {
        images: args.images.clone(),
        format: args.format,
        mode: mode(args.mode, args.size)?,
        strict: args.strict,
        follow_outside_links: args.follow_outside_links,
        unit: args.unit.unit()?.unwrap_or(nrw_pipeline::Unit::WHOLE),
        scene: args.scene.clone(),
        ..SegmentConfig::new("", &args.weights, &args.out)
    };
    let bars = Bars::new(args.quiet);
    let s = nrw_pipeline::segment::segment(&cfg, &bars)?;
    if !args.quiet {
        super::print_report(&nrw_pipeline::report::segment(&s));
    }
    if args.json {
        println!(
            "{}",
            serde_json::to_string_pretty(&s).expect("summary serialises")
        );
    }
    Ok(())
}
