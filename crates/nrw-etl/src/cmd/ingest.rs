//! `nrw-etl ingest`: arguments → `nrw_pipeline::ingest`, and what it did, printed.

use std::path::PathBuf;

use clap::Args;
use nrw_pipeline::ingest::IngestConfig;
use nrw_render::Filters;

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
    /// Scene folder holding sparse/0/ (or sparse/) and images/, or a model folder itself
    pub scene: PathBuf,
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
    /// Folder of per-photo ADE20K label maps (8-bit PNG of class ids, named like the photo
    /// with .png); stored colour-coded with a transient mask
    #[arg(long)]
    pub semantics: Option<PathBuf>,
    /// Segment each kept photo with this SegFormer (config.json + model.safetensors) instead
    /// of reading --semantics; see `nrw-etl segment --help`
    #[arg(long, conflicts_with = "semantics")]
    pub segment_weights: Option<PathBuf>,
    /// With --segment-weights: how a photo is fed to the network
    #[arg(long, value_parser = super::names(&nrw_segment::ModeKind::ALL, nrw_segment::ModeKind::name, nrw_segment::ModeKind::summary), default_value = "resize")]
    pub segment_mode: nrw_segment::ModeKind,
    /// With --segment-weights: network input size in pixels
    #[arg(long, default_value_t = 512)]
    pub segment_size: u32,
    /// Store every view undistorted, as COLMAP's image_undistorter does: the PINHOLE camera
    /// it computes (no blank pixels, scale clipped to 0.2–2) and the photo resampled to it
    /// through the exact camera model, so photo and render align pixel for pixel with a
    /// pinhole camera (what NeRF-W, nerfstudio and Gaussian-splatting loaders expect)
    #[arg(long, conflicts_with = "semantics")]
    pub undistort: bool,
    /// With --undistort: 0 keeps only pixels that see the photo (COLMAP's default), 1 keeps
    /// every photo pixel (black corners), values between interpolate
    #[arg(long, default_value_t = 0.0, requires = "undistort")]
    pub blank_pixels: f64,
    /// With --undistort: longest side of the undistorted camera, as COLMAP's
    /// --max_image_size [default: no limit]
    #[arg(long, requires = "undistort")]
    pub undistort_max_size: Option<u64>,
    /// Remove floating points before rendering (off by default: the paper renders the raw
    /// cloud): "K,SIGMA" drops a point when its mean distance to its K nearest neighbours
    /// exceeds the cloud's mean by SIGMA standard deviations (Open3D's
    /// remove_statistical_outlier; e.g. 16,2). The count removed goes into the manifest
    #[arg(long, value_name = "K,SIGMA", value_parser = parse_denoise)]
    pub denoise: Option<(usize, f64)>,
    /// Estimate normals for a cloud without them (the sparse points, most PLYs from other
    /// tools) by PCA of each point's K nearest neighbours, oriented toward the cameras that
    /// see it; gives the deep buffer its normal channel (e.g. 16)
    #[arg(long, value_name = "K")]
    pub estimate_normals: Option<usize>,
    /// Render so the shorter side has this many pixels (the paper: 600)
    #[arg(long, default_value_t = 600)]
    pub min_dim: u32,
    /// Splat radius in render pixels: a point covers the pixels whose centres lie within it (0: its own pixel)
    #[arg(long, default_value_t = 1.0)]
    pub radius: f32,
    /// Drop views whose render has more than this fraction of empty pixels (the paper: 0.85)
    #[arg(long, default_value_t = Filters::default().max_empty_ratio)]
    pub max_empty: f64,
    /// Drop photos whose shorter side is under this many pixels (the paper: 450)
    #[arg(long, default_value_t = Filters::default().min_photo_side)]
    pub min_photo_side: u32,
    /// Images per shard (one shard per group of this many images, in id order; the unit of
    /// resumption and of --unit work units)
    #[arg(long, default_value_t = 64)]
    pub rows_per_shard: usize,
    /// Stop with an error (exit 1, naming the file) at the first photo or label map that
    /// cannot be decoded whole, instead of dropping its view as `unreadable` and going on
    #[arg(long)]
    pub strict: bool,
    /// Read photos that are symbolic links out of the images folder (refused by default: a
    /// model's image names cannot make the tool read files you did not put there)
    #[arg(long)]
    pub follow_outside_links: bool,
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

/// `--denoise K,SIGMA`: k ≥ 2 neighbours (the point itself counts), σ > 0.
fn parse_denoise(s: &str) -> std::result::Result<(usize, f64), String> {
    let (k, sigma) = s
        .split_once(',')
        .ok_or_else(|| format!("`{s}`: give K,SIGMA, e.g. 16,2"))?;
    let k: usize = k
        .trim()
        .parse()
        .map_err(|_| format!("`{k}` is not a whole number of neighbours"))?;
    let sigma: f64 = sigma
        .trim()
        .parse()
        .map_err(|_| format!("`{sigma}` is not a number of standard deviations"))?;
    if k < 2 || !(sigma.is_finite() && sigma > 0.0) {
        return Err(format!(
            "K = {k}, SIGMA = {sigma}: K must be at least 2 (the point itself is one) and SIGMA positive"
        ));
    }
    Ok((k, sigma))
}

impl IngestArgs {
    /// The stage's configuration.
    pub fn config(&self) -> Result<IngestConfig> {
        let segment = match &self.segment_weights {
            Some(w) => Some(nrw_pipeline::ingest::InlineSegment {
                weights: w.clone(),
                mode: super::segment::mode(self.segment_mode, self.segment_size)?,
            }),
            None => None,
        };
        let undistort = self.undistort.then_some(nrw_colmap::UndistortOptions {
            blank_pixels: self.blank_pixels,
            max_image_size: self.undistort_max_size,
            ..Default::default()
        });
        Ok(IngestConfig {
            segment,
            undistort,
            denoise: self.denoise,
            estimate_normals: self.estimate_normals,
            images: self.images.clone(),
            format: self.format,
            points: self.points.clone(),
            semantics: self.semantics.clone(),
            min_dim: self.min_dim,
            radius: self.radius,
            filters: Filters {
                max_empty_ratio: self.max_empty,
                min_photo_side: self.min_photo_side,
            },
            rows_per_shard: self.rows_per_shard,
            strict: self.strict,
            follow_outside_links: self.follow_outside_links,
            stop_after_groups: self.stop_after_groups,
            pause_after_group: self
                .pause_after_group_ms
                .map(std::time::Duration::from_millis),
            ..IngestConfig::new(&self.scene, &self.out)
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
