//! Ingest: read and validate a scene, render every registered photo's view of the cloud,
//! apply the paper's filters, and write shards; [`merge`] then writes the scene tables and the
//! manifest (at the end of a whole run, or by `finalize` once every unit has run).
//!
//! Modules: `photos` (paths and headers), `cloud` (the points to render), `view` (one view
//! and one group of them), `merge` (the units into the dataset); the model itself is read by
//! [`crate::model`].
//!
//! Work goes in groups of `rows_per_shard` images in id order; each group becomes one shard,
//! written atomically, then recorded in `.units/ingest/group-NNNNN.json`. A rerun (or unit)
//! skips groups whose record matches its inputs and parameters, so an interrupted run resumes,
//! and the result is byte-identical on any thread count and any number of units.

use std::path::PathBuf;
use std::time::Instant;

use nrw_dataset::units::{self, UnitRecord};
use nrw_dataset::{FileEntry, SceneSource, Store};

use crate::error::{PipelineError, Result, Setting};
use crate::model::{
    encoding_and_layout, images_dir, load_model, undistort_model, undistort_record,
};
use crate::stage::GroupStage;
use crate::units::fingerprint;
use crate::{Progress, Unit};
use nrw_dataset::provenance::IngestParameters;

mod cloud;
mod config;
pub mod duplicates;
mod merge;
mod photos;
pub mod signals;
mod view;

use config::Prepared;
pub use config::{IngestConfig, InlineSegment, MAX_RADIUS};
pub use merge::{finalize_ingest, IngestMerge};

use cloud::*;
use photos::*;
use view::*;

/// What a unit of ingest did.
#[derive(Debug, Clone, serde::Serialize)]
pub struct UnitSummary {
    pub dataset: String,
    /// The work unit, `I/N`.
    pub unit: crate::Unit,
    /// Groups (shards) this unit owns, of all groups.
    pub groups_owned: usize,
    pub groups_total: usize,
    /// Groups found done from an earlier (interrupted) run.
    pub resumed_groups: usize,
    pub views: usize,
    pub point_source: String,
    pub points: usize,
    pub warnings: Vec<String>,
    pub seconds: f64,
}

fn check_config(cfg: &IngestConfig) -> Result<()> {
    if cfg.settings.rows_per_shard == 0 {
        return Err(PipelineError::config(
            Setting::Key("ingest.rows_per_shard"),
            "must be at least 1",
        ));
    }
    if !(0.0..=MAX_RADIUS).contains(&cfg.settings.radius) {
        return Err(PipelineError::config(
            Setting::Key("ingest.radius"),
            format!(
                "{} is outside 0..={MAX_RADIUS} render pixels (the paper uses 1)",
                cfg.settings.radius
            ),
        ));
    }
    if !(0.0..=1.0).contains(&cfg.settings.max_empty) {
        return Err(PipelineError::config(
            Setting::Key("ingest.max_empty"),
            format!(
                "{} is not a fraction in 0..=1 (the paper drops views above 0.85)",
                cfg.settings.max_empty
            ),
        ));
    }
    if let Some(s) = cfg
        .settings
        .min_sharpness
        .filter(|s| !(s.is_finite() && *s >= 0.0))
    {
        return Err(PipelineError::config(
            Setting::Key("ingest.min_sharpness"),
            format!("{s} is not a variance (a number ≥ 0; colmap2nerf's sharp photos score in the hundreds)"),
        ));
    }
    if cfg.settings.estimate_normals.is_some_and(|k| k < 3) {
        return Err(PipelineError::config(
            Setting::Key("ingest.estimate_normals"),
            "K needs K ≥ 3 neighbours (a plane needs three points)",
        ));
    }
    if let Some(d) = cfg.settings.semantics.as_ref().filter(|d| !d.is_dir()) {
        return Err(PipelineError::input(
            d,
            format!("{} is not a folder", Setting::Key("ingest.semantics")),
        ));
    }
    if cfg.settings.semantics.is_some() && cfg.segment.is_some() {
        return Err(PipelineError::config(
            Setting::SegmentWeights,
            format!(
                "and {} both give label maps: use one",
                Setting::Key("ingest.semantics")
            ),
        ));
    }
    Ok(())
}

/// Inputs with their hashes, sorted by path.
fn hashed_inputs(files: impl Iterator<Item = PathBuf>) -> Result<Vec<FileEntry>> {
    let mut inputs = files
        .map(|p| {
            let (bytes, sha256) = nrw_dataset::manifest::sha256_file(&p)?;
            Ok(FileEntry {
                path: p.display().to_string(),
                bytes,
                sha256,
                rows: None,
            })
        })
        .collect::<Result<Vec<_>>>()?;
    inputs.sort_by(|a, b| a.path.cmp(&b.path));
    Ok(inputs)
}

/// Read `--photo-info` (so a malformed file stops ingest before any rendering) and say which
/// of its names are not images of the model: a warning each time, never a silent drop.
fn photo_info_names(cfg: &IngestConfig, rec: &nrw_colmap::Reconstruction) -> Result<Vec<String>> {
    let Some(path) = &cfg.photo_info else {
        return Ok(Vec::new());
    };
    let info = nrw_dataset::photo_info::read_photo_info(path)?;
    let names: std::collections::HashSet<&str> =
        rec.images.values().map(|i| i.name.as_str()).collect();
    let strangers: Vec<String> = info
        .iter()
        .filter(|(name, _)| !names.contains(name.as_str()))
        .map(|(name, (line, _))| format!("{name} (line {line})"))
        .collect();
    let missing = names.iter().filter(|n| !info.contains_key(**n)).count();
    let mut warnings = Vec::new();
    if !strangers.is_empty() {
        warnings.push(format!(
            "{}: {} names are not images of the model, not used: {}",
            path.display(),
            strangers.len(),
            strangers
                .iter()
                .take(10)
                .cloned()
                .collect::<Vec<_>>()
                .join(", ")
                + if strangers.len() > 10 { ", …" } else { "" }
        ));
    }
    if missing > 0 {
        warnings.push(format!(
            "{}: {missing} of {} registered images have no row: their licence is unknown",
            path.display(),
            names.len()
        ));
    }
    Ok(warnings)
}

/// What a unit records of how it ran: the settings (each in its field of
/// [`IngestParameters`], or under its own key) with what it found (the model's encoding, the
/// cloud, the outlier removal, the SegFormer).
fn recorded(
    cfg: &IngestConfig,
    (enc, source, points): (&str, &str, usize),
    cleaned: &cloud::Cleaned,
    segmenter: Option<&(nrw_segment::Segformer, nrw_segment::Mode)>,
) -> nrw_dataset::provenance::Parameters {
    let mut parameters = nrw_dataset::provenance::to_parameters(&IngestParameters {
        format: enc.into(),
        point_source: source.into(),
        points,
        min_dim: cfg.settings.min_dim,
        // f32 → f64 is exact: the record holds the radius the renderer used.
        radius: cfg.settings.radius as f64,
        max_empty: cfg.settings.max_empty,
        min_photo_side: cfg.settings.min_photo_side,
        rows_per_shard: cfg.settings.rows_per_shard,
        semantics: cfg
            .settings
            .semantics
            .as_ref()
            .map(|d| d.display().to_string()),
        undistort: cfg
            .settings
            .undistort_options()
            .as_ref()
            .map(undistort_record),
        denoise: cleaned.denoise,
        estimated_normals_k: cleaned.estimated_normals_k,
        segment_model_sha256: segmenter.map(|(m, _)| m.sha256.clone()),
        segment_mode: segmenter.map(|(_, mode)| mode.to_string()),
        photo_info: cfg.photo_info.as_ref().map(|p| p.display().to_string()),
        min_sharpness: cfg.settings.min_sharpness,
    });
    parameters.extend(cfg.settings.unrecorded());
    parameters
}

fn prepare(cfg: &IngestConfig, unit: Unit) -> Result<Prepared> {
    check_config(cfg)?;
    let (scene, mut rec) = load_model(&cfg.scene, cfg.format, cfg.model)?;
    crate::model::refuse_panoramas(&scene, &rec)?;
    let model_dir = scene.model_dir.clone();
    let photos_dir = images_dir(cfg.images.as_deref(), &scene)?;
    let mut warnings: Vec<String> = rec.warnings.iter().map(|w| w.to_string()).collect();
    warnings.extend(scene.choice.explain(&model_dir));
    let photos = photo_sizes(&rec, &photos_dir, cfg, &mut warnings)?;
    let distorted = match &cfg.settings.undistort_options() {
        Some(o) => Some(undistort_model(&mut rec, o, &model_dir)?),
        None => None,
    };
    let (raw, source, source_path) = point_source(cfg, &scene, &rec)?;
    let (cloud, cleaned) = render_cloud(cfg, raw, rec.scene_origin(), &mut warnings);
    warnings.extend(photo_info_names(cfg, &rec)?);
    let inputs = hashed_inputs(
        rec.files
            .iter()
            .cloned()
            .chain(source_path)
            .chain(cfg.photo_info.clone()),
    )?;
    let (enc, layout) = encoding_and_layout(&rec);
    let segmenter = match &cfg.segment {
        Some(s) => Some((crate::segment::load_segformer(&s.weights)?, s.mode)),
        None => None,
    };
    let parameters = recorded(
        cfg,
        (enc, &source, cloud.len()),
        &cleaned,
        segmenter.as_ref(),
    );
    let record = UnitRecord {
        stage: units::INGEST.into(),
        index: unit.index,
        count: unit.count,
        fingerprint: fingerprint(&inputs, &parameters),
        parameters,
        inputs,
        scene: Some(SceneSource {
            scene_dir: cfg.scene.display().to_string(),
            model_dir: model_dir.display().to_string(),
            images_dir: Some(photos_dir.display().to_string()),
            encoding: enc.into(),
            layout: layout.into(),
        }),
        warnings,
        groups: rec.images.len().div_ceil(cfg.settings.rows_per_shard),
        seconds: 0.0,
        // Renders go through no GEMM: the same bits on every instruction set.
        instruction_set: None,
    };
    Ok(Prepared {
        rec,
        photos_dir,
        photos: photos.sizes,
        unreadable: photos.unreadable,
        cloud,
        source,
        record,
        segmenter,
        distorted,
    })
}

/// Ingest as a group stage: one group of `rows_per_shard` images per shard.
struct IngestStage<'a> {
    cfg: &'a IngestConfig,
    store: &'a Store,
    p: &'a Prepared,
}

impl GroupStage for IngestStage<'_> {
    const STAGE: &'static str = units::INGEST;
    const ITEMS: &'static str = "views";
    type Merge = IngestMerge;

    fn done(&self, g: usize, _ids: &[u32]) -> Result<bool> {
        Ok(done_group(self.store, g, &self.p.record.fingerprint).is_some())
    }

    fn run(&self, g: usize, ids: &[u32], progress: &dyn Progress) -> Result<usize> {
        run_group(self.cfg, self.store, self.p, g, ids, progress)
    }

    fn merge(dataset: &Store) -> Result<IngestMerge> {
        finalize_ingest(dataset)
    }
}

/// Ingest's merge, as `finalize` runs it.
pub fn merge(dataset: &Store) -> Result<Option<IngestMerge>> {
    crate::stage::merge_stage::<IngestStage>(dataset)
}

/// Whether ingest units started here but none finished.
pub fn started_unfinished(dataset: &Store) -> Result<bool> {
    crate::stage::started_unfinished::<IngestStage>(dataset)
}

/// The test hooks of a unit: a pause after each group, a stop after some.
fn after_group(cfg: &IngestConfig, ran: usize, todo: usize) -> Result<()> {
    if let Some(d) = cfg.pause_after_group {
        std::thread::sleep(d);
    }
    if cfg.stop_after_groups.is_some_and(|n| ran >= n) && ran < todo {
        return Err(PipelineError::Interrupted(format!(
            "stopped after {ran} groups as asked; run the same command again to resume"
        )));
    }
    Ok(())
}

/// Run one unit of ingest: render the groups `unit` owns (skipping those already done) and
/// record the unit as done. Writes only this unit's shards and records; deletes nothing.
pub fn ingest_unit(cfg: &IngestConfig, unit: Unit, progress: &dyn Progress) -> Result<UnitSummary> {
    let t0 = Instant::now();
    let mut p = prepare(cfg, unit)?;
    let store = &Store::open(&cfg.out)?;
    let ids: Vec<u32> = p.rec.images.keys().copied().collect();
    let stage = IngestStage { cfg, store, p: &p };
    let d = crate::stage::drive(
        &stage,
        unit,
        &ids,
        cfg.settings.rows_per_shard,
        "rendering",
        progress,
        &|ran, todo| after_group(cfg, ran, todo),
    )?;
    p.record.seconds = t0.elapsed().as_secs_f64();
    crate::stage::record_unit::<IngestStage>(store, unit, &p.record)?;
    Ok(UnitSummary {
        dataset: store.root().to_string(),
        unit,
        groups_owned: d.owned,
        groups_total: p.record.groups,
        resumed_groups: d.resumed,
        views: d.items,
        point_source: p.source,
        points: p.cloud.len(),
        warnings: p.record.warnings,
        seconds: p.record.seconds,
    })
}

/// What a whole ingest produced (printed with `--json`).
#[derive(Debug, Clone, serde::Serialize)]
pub struct IngestSummary {
    pub dataset: String,
    pub registered: usize,
    pub rendered: usize,
    pub kept: usize,
    pub too_small: usize,
    pub too_sparse: usize,
    /// Photos less sharp than `min_sharpness`.
    pub too_blurry: usize,
    /// Photos (or label maps) that could not be decoded whole, each named in `warnings`.
    pub unreadable: usize,
    /// Groups of kept photos that are one picture (split keeps each on one side), and the
    /// photos in them.
    pub duplicate_groups: usize,
    pub duplicate_photos: usize,
    pub shards: usize,
    pub point_source: String,
    pub points: usize,
    pub resumed_groups: usize,
    /// Empty ratio of the least empty render (what the filter would have to allow).
    pub least_empty: Option<f64>,
    /// The filters the verdicts came from: renders emptier than this fraction are too sparse,
    pub max_empty: f64,
    /// and photos with a shorter side under this many pixels too small,
    pub min_photo_side: u32,
    /// and photos less sharp than this too blurry (when given).
    pub min_sharpness: Option<f64>,
    pub warnings: Vec<String>,
    pub seconds: f64,
}

/// Ingest the whole scene in this process: one unit of one, then finalize. Unit records of
/// earlier unfinished unit runs are cleared first (this run owns the dataset); their group
/// records are reused when they match.
pub fn ingest(cfg: &IngestConfig, progress: &dyn Progress) -> Result<IngestSummary> {
    let t0 = Instant::now();
    check_config(cfg)?;
    let store = &Store::open(&cfg.out)?;
    let (u, f) =
        crate::stage::whole::<IngestStage, _>(store, || ingest_unit(cfg, Unit::WHOLE, progress))?;
    Ok(IngestSummary {
        dataset: u.dataset,
        registered: f.registered,
        rendered: f.kept + f.too_sparse + f.too_blurry,
        kept: f.kept,
        too_small: f.too_small,
        too_sparse: f.too_sparse,
        too_blurry: f.too_blurry,
        unreadable: f.unreadable,
        duplicate_groups: f.duplicate_groups,
        duplicate_photos: f.duplicate_photos,
        shards: f.shards,
        point_source: u.point_source,
        points: u.points,
        resumed_groups: u.resumed_groups,
        least_empty: f.least_empty,
        max_empty: cfg.settings.max_empty,
        min_photo_side: cfg.settings.min_photo_side,
        min_sharpness: cfg.settings.min_sharpness,
        warnings: f.warnings,
        seconds: t0.elapsed().as_secs_f64(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_setting_out_of_range_is_named_by_its_key_for_library_callers() {
        let tmp = std::env::temp_dir().join("nrw-no-such-scene");
        let mut cfg = IngestConfig::new(&tmp, tmp.join("out"));
        cfg.settings.radius = 40.0;
        let e = ingest(&cfg, &crate::Silent).unwrap_err();
        assert!(
            matches!(
                e,
                PipelineError::Config {
                    setting: Setting::Key("ingest.radius"),
                    ..
                }
            ),
            "{e:?}"
        );
        assert!(
            e.to_string().starts_with("`ingest.radius` 40 is outside"),
            "{e}"
        );
        assert!(!tmp.join("out").exists(), "nothing written");
    }
}
