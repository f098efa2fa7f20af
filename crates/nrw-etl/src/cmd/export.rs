//! `nrw-etl export`: a dataset as files other tools read. `official` and `tfrecord` are what
//! the paper's published TensorFlow code reads; `files` is one folder per photo for ordinary
//! viewers. The layouts and their bytes live in `nrw_dataset::export`; this parses arguments,
//! supplies the style distance matrix, draws the bar and prints.

use std::path::PathBuf;

use clap::{Args, ValueEnum};
use nrw_dataset::export::official::DepthMapping;
use nrw_dataset::export::{ExportConfig, ExportSummary, Layout as DsLayout};

use crate::error::Result;

/// `--layout` values.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum Layout {
    /// train/ and val/ with NNNN_reference.png, NNNN_color.png (RGBA), NNNN_depth.png (levels 0-255), NNNN_seg_rgb.png (the published colour coding), dist_NAME.pckl with official descriptors
    Official,
    /// NAME_train.tfrecord / NAME_val.tfrecord (or NAME-0000i-of-0000N_SPLIT.tfrecord with --shards N): the Examples the published data.py parses
    Tfrecord,
    /// SPLIT/NAME/{photo.png, color.png, depth.exr, normal.png, semantics.png, labels.png, transient.png, meta.json}
    Files,
    /// NeRF-W's Phototourism layout for nerf_pl / Ha-NeRF loaders: NAME.tsv (filename, id, split, dataset), dense/images/, dense/sparse/ (one PINHOLE camera per image, the scene's points); needs a dataset ingested with --undistort (or pinhole cameras)
    Nerfw,
    /// nerfstudio's transforms.json (each frame's exact camera model, OpenGL camera-to-world poses with nerfstudio's applied_transform, depth/*.npy, masks/*.png from the transient mask, train/val/test_filenames) with images/ and sparse_pc.ply; refuses camera models nerfstudio cannot represent exactly (FOV, FULL_OPENCV, thin-prism fisheyes)
    Nerfstudio,
}

/// `--depth` values.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum Depth {
    /// Levels even in depth between the dataset's nearest and farthest depth (more levels on the landmark in docs/bench/official_export.md)
    Linear,
    /// Levels even in inverse depth between the dataset's nearest and farthest depth (finer near the camera)
    Inverse,
}

/// Arguments of `export`.
#[derive(Debug, Args)]
#[command(after_help = "Examples:
  nrw-etl export DATASET --out trevi_official --name trevi
  nrw-etl export DATASET --layout tfrecord --crop 512 --shards 8 --out tfrecords --name trevi
  nrw-etl export DATASET --no-semantics --out official   # then train with --use_semantic=False
  nrw-etl export DATASET --layout nerfw --out trevi_nerfw --name trevi   # nerf_pl / Ha-NeRF (ingest with --undistort)
  nrw-etl export DATASET --layout nerfstudio --out trevi_ns   # ns-train nerfacto --data trevi_ns

The official and tfrecord layouts follow google/neural_rerendering_in_the_wild: every channel
is scaled by its loaders as x * 2/255 - 1, so depth is written as levels 1-255 (0 = empty) by
the mapping --depth names; export.json records the mapping, its near and far, and the formula
that recovers depth. Writing into an earlier export replaces it whole.")]
pub struct ExportArgs {
    /// Dataset folder written by `ingest` (and `split`)
    pub dataset: PathBuf,
    /// Which layout to write
    #[arg(long, value_enum, default_value = "official")]
    pub layout: Layout,
    /// Folder to write into (created; an earlier export there is replaced whole)
    #[arg(long)]
    pub out: PathBuf,
    /// Dataset name the published code is run with (--dataset_name): NAME_train.tfrecord, dist_NAME.pckl [default: the dataset folder's name]
    #[arg(long)]
    pub name: Option<String>,
    /// Centre crop of every channel, as the published code's 512 × 512 (official, tfrecord); smaller views are skipped and listed
    #[arg(long)]
    pub crop: Option<u32>,
    /// Export without semantics (no *_seg_rgb.png; empty `seg` in TFRecords): train with --use_semantic=False
    #[arg(long)]
    pub no_semantics: bool,
    /// How depth becomes the levels 1-255 the published loaders expect
    #[arg(long, value_enum, default_value = "linear")]
    pub depth: Depth,
    /// TFRecord files per split
    #[arg(long, default_value_t = 1)]
    pub shards: usize,
    /// No progress bar
    #[arg(long)]
    pub quiet: bool,
}

/// Run `export`.
pub fn run(args: &ExportArgs) -> Result<()> {
    let cfg = ExportConfig {
        layout: match args.layout {
            Layout::Official => DsLayout::Official,
            Layout::Tfrecord => DsLayout::Tfrecord,
            Layout::Files => DsLayout::Files,
            Layout::Nerfw => DsLayout::Nerfw,
            Layout::Nerfstudio => DsLayout::Nerfstudio,
        },
        name: args
            .name
            .clone()
            .unwrap_or_else(|| nrw_pipeline::export::default_name(&args.dataset)),
        crop: args.crop,
        semantics: !args.no_semantics,
        depth: match args.depth {
            Depth::Inverse => DepthMapping::Inverse,
            Depth::Linear => DepthMapping::Linear,
        },
        shards: args.shards,
        ..nrw_pipeline::export::official(&args.dataset, &args.out)
    };
    let summary = nrw_pipeline::export::export(&args.dataset, &cfg, &super::Bars::new(args.quiet))?;
    if !args.quiet {
        print_summary(&args.dataset, &args.out, &summary);
    }
    Ok(())
}

/// What was exported, what was skipped, and the style distances.
pub fn print_summary(dataset: &std::path::Path, out: &std::path::Path, s: &ExportSummary) {
    let per: Vec<String> = s
        .splits
        .iter()
        .map(|p| format!("{} {}", p.split, p.image_ids.len()))
        .collect();
    println!(
        "exported {} views ({}) of {} to {} ({:?} layout)",
        s.views(),
        per.join(", "),
        dataset.display(),
        out.display(),
        s.layout
    );
    for k in &s.skipped {
        eprintln!(
            "skipped {} (image {}, {} split): {}×{} is {}",
            k.name, k.image_id, k.split, k.width, k.height, k.reason
        );
    }
    for e in &s.empty_splits {
        eprintln!(
            "split {e} has no view: not written (the published code's {e} glob will find nothing; `nrw-etl split DATASET --val N` holds out N photos)"
        );
    }
    match &s.dist_pickle {
        Some(p) => println!("style distances: {} (pretrain_appearance loads it)", out.join(p).display()),
        None if s.layout == DsLayout::Official => eprintln!(
            "no dist_NAME.pckl: the dataset has no official style descriptors (`nrw-etl style DATASET --tier official --weights VGG16`)"
        ),
        None => {}
    }
}
