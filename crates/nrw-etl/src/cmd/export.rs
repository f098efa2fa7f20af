//! `nrw-etl export`: a dataset as files other tools read. `official` and `tfrecord` are what
//! the paper's published TensorFlow code reads; `files` is one folder per photo for ordinary
//! viewers. The layouts and their bytes live in `nrw_dataset::export`; this parses arguments,
//! supplies the style distance matrix, draws the bar and prints.

use clap::Args;
use nrw_export::official::DepthMapping;
use nrw_export::{ExportConfig, Layout};

use crate::error::Result;

/// `--crop` values: a side in pixels, or `none`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Crop {
    Side(u32),
    None,
}

fn parse_crop(s: &str) -> std::result::Result<Crop, String> {
    match s {
        "none" => Ok(Crop::None),
        n => n
            .parse::<u32>()
            .map(Crop::Side)
            .map_err(|_| format!("{n:?} is neither a side in pixels (e.g. 512) nor `none`")),
    }
}

/// `--metres-per-unit` values: a finite length above zero.
fn parse_scale(s: &str) -> std::result::Result<f64, String> {
    match s.parse::<f64>() {
        Ok(x) if x.is_finite() && x > 0.0 => Ok(x),
        _ => Err(format!(
            "{s:?} is not a length in metres above zero (e.g. 0.0254)"
        )),
    }
}

/// Arguments of `export`.
#[derive(Debug, Args)]
#[command(after_help = "Examples:
  nrw-etl export DATASET --out trevi_official --name trevi
  nrw-etl export DATASET --layout tfrecord --tfrecord-files 8 --out tfrecords --name trevi
  nrw-etl export DATASET --crop 256 --out trevi256   # for --train_resolution=256
  nrw-etl export DATASET --no-semantics --out official   # then train with --use_semantic=False
  nrw-etl export DATASET --layout nerfw --out trevi_nerfw --name trevi   # nerf_pl / Ha-NeRF (ingest with --undistort)
  nrw-etl export DATASET --layout nerfstudio --out trevi_ns   # ns-train nerfacto --data trevi_ns
  nrw-etl export DATASET --layout gsplat --out trevi_gs   # 3DGS: train.py -s trevi_gs -d depths; gsplat --data_factor 4
  nrw-etl export DATASET --layout megadepth --name trevi --out md   # D2-Net: preprocess_scene.py --base_path md --scene_id trevi
  nrw-etl export DATASET --layout megadepth --name trevi --metres-per-unit 0.37 --out md   # with IMC 2022's scaling_factors.csv

The official and tfrecord layouts follow google/neural_rerendering_in_the_wild: every channel
is scaled by its loaders as x * 2/255 - 1, so depth is written as levels 1-255 (0 = empty) by
the mapping --depth names; export.json records the mapping, its near and far, and the formula
that recovers depth. The gsplat and megadepth layouts need PINHOLE cameras (ingest with
--undistort); see docs/gsplat-export.md and docs/megadepth-export.md for what each file holds and
which value means \"ignore\". Where a known loader would misread an export, a warning names the
loader and the rule (export.json lists them). Writing into an earlier export replaces it whole.")]
pub struct ExportArgs {
    /// Dataset folder written by `ingest` (and `split`)
    pub dataset: nrw_dataset::Location,
    /// Which layout to write
    #[arg(long, value_parser = super::names(&Layout::ALL, Layout::name, Layout::summary), default_value = "official")]
    pub layout: Layout,
    /// Folder to write into (created; an earlier export there is replaced whole)
    #[arg(long)]
    pub out: nrw_dataset::Location,
    /// Dataset name the published code is run with (--dataset_name): NAME_train.tfrecord, dist_NAME.pckl [default: the dataset folder's name]
    #[arg(long)]
    pub name: Option<String>,
    /// Centre crop of every channel, official and tfrecord layouts [default: 512, the published
    /// pipeline's: its segmentation writes *_seg_rgb.png as the 512 centre crop, so its
    /// pretraining, which crops every channel but that one, reads only crops of the training
    /// resolution]. Use the resolution you train at (e.g. 256 for --train_resolution=256);
    /// views smaller than the crop are skipped and listed. `none` keeps the stored size, which
    /// dataset_utils.py converts but pretrain_appearance.py cannot read
    #[arg(long, value_parser = parse_crop)]
    pub crop: Option<Crop>,
    /// Export without semantics (no *_seg_rgb.png; empty `seg` in TFRecords): train with --use_semantic=False
    #[arg(long)]
    pub no_semantics: bool,
    /// How depth becomes the levels 1-255 the published loaders expect
    #[arg(long, value_parser = super::names(&DepthMapping::ALL, DepthMapping::name, DepthMapping::summary), default_value = "linear")]
    pub depth: DepthMapping,
    /// TFRecord files per split (`NAME-0000i-of-0000N_SPLIT.tfrecord`; `--shards` is its old
    /// name, still taken)
    #[arg(long, alias = "shards", default_value_t = 1)]
    pub tfrecord_files: usize,
    /// Metres a model unit, megadepth layout: IMC 2022's scaling_factors.csv, which its pose
    /// evaluation multiplies translations by (SfM does not know it: measure a known length)
    #[arg(long, value_parser = parse_scale)]
    pub metres_per_unit: Option<f64>,
    /// No progress bar
    #[arg(long)]
    pub quiet: bool,
}

/// Run `export`.
pub fn run(args: &ExportArgs) -> Result<()> {
    let layout = args.layout;
    let cfg = ExportConfig {
        layout,
        name: args
            .name
            .clone()
            .unwrap_or_else(|| nrw_pipeline::export::default_name(&args.dataset)),
        crop: match args.crop {
            Some(Crop::Side(n)) => Some(n),
            Some(Crop::None) => None,
            None => layout.default_crop(),
        },
        semantics: !args.no_semantics,
        depth: args.depth,
        tfrecord_files: args.tfrecord_files,
        metres_per_unit: args.metres_per_unit,
        ..nrw_pipeline::export::official(&args.dataset, &args.out)
    };
    let summary = nrw_pipeline::export::export(&args.dataset, &cfg, &super::Bars::new(args.quiet))?;
    if !args.quiet {
        super::print_report(&nrw_pipeline::report::export(
            &args.dataset,
            &args.out,
            &summary,
        ));
    }
    Ok(())
}
