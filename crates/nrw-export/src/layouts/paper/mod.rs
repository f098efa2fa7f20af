//! What the two layouts of the paper's published code (official PNG folders, TFRecords)
//! share: their checks, the depth levels, the centred crop, the published colour coding of
//! the labels, and the summary fields they fill in.

pub mod official;
pub mod published;
pub mod tfrecord;

use nrw_dataset::split::{TRAIN, VAL};
use std::path::PathBuf;

use image::imageops::crop_imm;
use image::{GrayImage, RgbImage, RgbaImage};
use nrw_dataset::ViewRow;

use crate::error::{ExportError, Result};
use crate::published::{crop_start, official_seg_rgb, DepthScale};
use crate::writer::Job;
use crate::{DepthRecord, ExportConfig, ExportSummary};

/// The settings of a paper layout's views: depth levels, crop, semantics.
pub struct Paper {
    pub scale: DepthScale,
    pub crop: Option<u32>,
    pub semantics: bool,
}

/// The channels of one view as the published code reads them, cropped if asked.
pub struct OfficialView {
    pub reference: RgbImage,
    pub color: RgbaImage,
    pub depth: GrayImage,
    pub seg: Option<RgbImage>,
}

/// Refuse what no paper layout can export: no train views, a crop or shard count of 0.
pub fn check(job: &Job) -> Result<()> {
    job.require_train(" (`split.val` 0 puts every photo in train)")?;
    check_counts(job.cfg)
}

/// Refuse a crop or a shard count of 0.
pub fn check_counts(cfg: &ExportConfig) -> Result<()> {
    if cfg.paper.crop.is_some_and(|c| c == 0) || cfg.paper.tfrecord_files == 0 {
        return Err(ExportError::refused(
            &cfg.out,
            "the crop and the TFRecord files per split must be at least 1",
        ));
    }
    Ok(())
}

impl Paper {
    /// The paper settings of `job`, with depth levels spanning the dataset's depth range.
    pub fn of(job: &Job) -> Result<Paper> {
        let (near, far) =
            nrw_dataset::scene::read_depth_range(&job.ds.store)?.unwrap_or((1.0, 1.0));
        Ok(Paper {
            scale: DepthScale {
                mapping: job.cfg.paper.depth,
                near,
                far,
            },
            crop: job.cfg.paper.crop,
            semantics: job.cfg.paper.semantics,
        })
    }

    /// Fill in what a paper layout records (crop, depth mapping, semantics), and list `val`
    /// as empty when the dataset has no such split: the published code validates on it.
    pub fn begin(&self, job: &Job, summary: &mut ExportSummary) {
        summary.crop = self.crop;
        summary.depth = Some(DepthRecord::of(&self.scale));
        summary.semantics = self.semantics.then(|| "official".into());
        if !job.splits.iter().any(|(s, _)| s == VAL) {
            summary.empty_splits.push(VAL.into());
        }
    }

    /// Refuse an export left with no train view (every one smaller than the crop).
    pub fn require_written_train(&self, job: &Job, summary: &ExportSummary) -> Result<()> {
        if summary.splits.iter().any(|s| s.split == TRAIN) {
            return Ok(());
        }
        Err(ExportError::refused(
            &job.ds.dir,
            format!(
                "no train view is left to export: {} skipped as smaller than the crop, e.g. {}; use a smaller `export.crop`",
                summary.skipped.len(),
                summary
                    .skipped
                    .first()
                    .map_or("none".into(), |s| format!("{} ({}×{})", s.name, s.width, s.height))
            ),
        ))
    }

    /// A view without labels is refused when semantics are asked for.
    pub fn check_view(&self, v: &ViewRow) -> Result<()> {
        if self.semantics && v.labels_png.is_none() {
            return Err(no_semantics(v));
        }
        Ok(())
    }

    /// Why a view smaller than the crop is left out.
    pub fn skip(&self, v: &ViewRow) -> Option<String> {
        let c = self.crop?;
        (v.width < c || v.height < c).then(|| format!("smaller than the {c}×{c} crop"))
    }

    /// The published colour coding of a view's labels, or None without semantics.
    pub fn seg(&self, v: &ViewRow) -> Result<Option<RgbImage>> {
        if !self.semantics {
            return Ok(None);
        }
        let labels = v.labels()?.ok_or_else(|| no_semantics(v))?;
        Ok(Some(official_seg_rgb(&labels)))
    }

    /// The view's channels decoded, depth as levels, cropped if asked.
    pub fn view(&self, v: &ViewRow) -> Result<OfficialView> {
        let depth = v.depth()?;
        let mut out = OfficialView {
            reference: v.photo()?,
            color: v.color()?,
            depth: self.scale.image(v.width, v.height, &depth.data),
            seg: self.seg(v)?,
        };
        if let Some(c) = self.crop {
            let (x, y) = (crop_start(v.width, c), crop_start(v.height, c));
            out.reference = crop_imm(&out.reference, x, y, c, c).to_image();
            out.color = crop_imm(&out.color, x, y, c, c).to_image();
            out.depth = crop_imm(&out.depth, x, y, c, c).to_image();
            out.seg = out.seg.map(|s| crop_imm(&s, x, y, c, c).to_image());
        }
        Ok(out)
    }
}

/// A view without labels, with the two ways forward.
fn no_semantics(v: &ViewRow) -> ExportError {
    ExportError::Value {
        path: PathBuf::from(&v.name).into(),
        record: format!("image {}", v.image_id),
        field: "labels_png".into(),
        problem: "the dataset has no semantic labels, and the published code reads *_seg_rgb.png by default: ingest with `ingest.semantics` LABELS_DIR, or export without labels (`export.semantics`) and train with --use_semantic=False --deep_buffer_nc=4 (RGB and depth)".into(),
    }
}
