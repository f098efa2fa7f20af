//! What to export (`ExportConfig`) and what an export wrote (`ExportSummary`, which is also
//! `export.json`).

use serde::Serialize;

use crate::imc::ImcOptions;
use crate::published::{DepthScale, PaperOptions};

/// What to export and how.
#[derive(Debug, Clone)]
pub struct ExportConfig {
    /// Destination: a folder (created, or replaced whole when it holds an earlier export) or
    /// an `s3://`, `gs://` or `az://` URL (the same files, uploaded).
    pub out: nrw_dataset::Location,
    /// The dataset name the published code is run with (`--dataset_name`): TFRecord and
    /// distance-matrix file names.
    pub name: String,
    /// What the paper's layouts (official, tfrecord) write: crop, semantics, depth levels,
    /// TFRecord files.
    pub paper: PaperOptions,
    /// What the megadepth layout's IMC 2022 files need that a model does not hold.
    pub imc: ImcOptions,
    /// Export only photos under these licences (SPDX ids, `unknown` for photos nobody gave
    /// one for; [`nrw_dataset::photo_info`]); `None` exports every view.
    pub licences: Option<Vec<String>>,
}

impl ExportConfig {
    /// The settings the published code runs with (for the paper's layouts).
    pub fn official(out: nrw_dataset::Location, name: String) -> Self {
        ExportConfig {
            out,
            name,
            paper: PaperOptions::published(),
            imc: ImcOptions::default(),
            licences: None,
        }
    }
}

/// A view an export left out, and why.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Skipped {
    pub split: String,
    pub image_id: u32,
    pub name: String,
    pub width: u32,
    pub height: u32,
    pub reason: String,
}

/// One split of an export: its views in file order.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SplitExport {
    pub split: String,
    /// Image ids in index order: view k is file k (`NNNN_*` or record k).
    pub image_ids: Vec<u32>,
    pub names: Vec<String>,
    /// Files written for the split, relative to the export folder.
    pub files: Vec<String>,
}

impl SplitExport {
    /// A split with nothing written yet.
    pub fn new(split: &str) -> SplitExport {
        SplitExport {
            split: split.into(),
            image_ids: Vec::new(),
            names: Vec::new(),
            files: Vec::new(),
        }
    }
}

/// What an export wrote: also the content of `export.json`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ExportSummary {
    pub tool: String,
    pub dataset: String,
    /// The layout's name ([`crate::Layout::name`]).
    pub layout: &'static str,
    pub name: String,
    pub crop: Option<u32>,
    /// Depth levels in the official and tfrecord layouts, with the formula to recover depth.
    pub depth: Option<DepthRecord>,
    /// `official` (schemas/official_colors.csv), `ade20k` (ids and colour150), or null.
    pub semantics: Option<String>,
    pub splits: Vec<SplitExport>,
    pub skipped: Vec<Skipped>,
    /// Splits the dataset has with no view, not written (the published code's glob would fail).
    pub empty_splits: Vec<String>,
    /// `dist_<name>.pckl` when the dataset has official style descriptors.
    pub dist_pickle: Option<String>,
    /// Where the depth the layout writes comes from (layouts with depth priors).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub depth_source: Option<String>,
    /// Where a known consumer's loader would misread this export, naming the loader and rule.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub warnings: Vec<String>,
    /// With `--licences`: the licences exported and how many views the others left out.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub licences: Option<LicenceFilter>,
}

/// What `--licences` kept and left out.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct LicenceFilter {
    pub kept: Vec<String>,
    /// Views whose photo is under another licence (or none known), not exported.
    pub left_out: usize,
}

impl ExportSummary {
    /// The summary before a layout fills in what it wrote: tool, dataset, layout and name.
    pub(crate) fn begin(dataset: &str, layout: &'static str, cfg: &ExportConfig) -> ExportSummary {
        ExportSummary {
            tool: format!("nrw-etl {}", env!("CARGO_PKG_VERSION")),
            dataset: dataset.into(),
            layout,
            name: cfg.name.clone(),
            crop: None,
            depth: None,
            semantics: None,
            splits: Vec::new(),
            skipped: Vec::new(),
            empty_splits: Vec::new(),
            dist_pickle: None,
            depth_source: None,
            warnings: Vec::new(),
            licences: None,
        }
    }

    /// Views written over all splits.
    pub fn views(&self) -> usize {
        self.splits.iter().map(|s| s.image_ids.len()).sum()
    }
}

/// The depth mapping as recorded in `export.json`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct DepthRecord {
    #[serde(flatten)]
    pub scale: DepthScale,
    pub formula: String,
    /// What the published loaders do with a level: `level * 2/255 - 1`, so 0 (empty) → −1.
    pub loader_scaling: String,
}

impl DepthRecord {
    /// The record of `scale`, with the published loaders' scaling spelled out.
    pub(crate) fn of(scale: &DepthScale) -> DepthRecord {
        DepthRecord {
            scale: *scale,
            formula: scale.formula().into(),
            loader_scaling: "x = level * 2/255 - 1 (data._parser_rendered_dataset, pretrain_appearance._load_and_concatenate_image_channels): empty = -1, near = -0.992, far = 1".into(),
        }
    }
}
