//! `nrw-etl export`: a dataset as files other tools read. `official` and `tfrecord` are what
//! the paper's published TensorFlow code reads; `files` is one folder per photo for ordinary
//! viewers. The layouts and their bytes live in nrw-export, the settings (flags and the `[export]`
//! table alike) in `nrw_pipeline::settings::export`; this parses arguments,
//! supplies the style distance matrix, draws the bar and prints.

use clap::Args;
use nrw_pipeline::settings::export::ExportSettings;

use crate::error::Result;

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
    /// Folder to write into (created; an earlier export there is replaced whole)
    #[arg(long)]
    pub out: nrw_dataset::Location,
    #[command(flatten)]
    pub settings: ExportSettings,
    /// No progress bar
    #[arg(long)]
    pub quiet: bool,
}

/// Run `export`.
pub fn run(args: &ExportArgs) -> Result<()> {
    let cfg = args.settings.config(&args.dataset, &args.out)?;
    let summary = nrw_pipeline::export::export(
        &args.dataset,
        args.settings.layout,
        &cfg,
        &super::Bars::new(args.quiet),
    )?;
    if !args.quiet {
        super::print_report(&nrw_pipeline::report::export(
            &args.dataset,
            &args.out,
            &summary,
        ));
    }
    Ok(())
}
