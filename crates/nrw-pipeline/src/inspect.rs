//! Inspect: what a location holds — a COLMAP model (counts, camera models, how well it agrees
//! with itself) or a dataset (verdicts, views, splits) — as values any front end can print.

use std::collections::BTreeMap;
use std::path::Path;

use nrw_colmap::{Format, Reconstruction};
use serde::Serialize;

use crate::error::Result;

/// A COLMAP model's summary. Serialised, it is `inspect --json`'s object.
#[derive(Debug, Clone, Serialize)]
pub struct ModelSummary {
    pub model_dir: String,
    /// `bin` or `txt`.
    pub encoding: &'static str,
    /// `colmap3`, or `colmap4` (rigs and frames).
    pub layout: &'static str,
    pub cameras: usize,
    pub images: usize,
    pub points: usize,
    pub observations: usize,
    pub camera_models: Vec<&'static str>,
    pub mean_reprojection_error_px: Option<f64>,
    pub max_reprojection_error_px: Option<f64>,
    /// Observations whose point projected into its image (the ones averaged).
    #[serde(skip)]
    pub observations_projected: usize,
    pub not_visible_observations: usize,
    pub rigs: usize,
    pub frames: usize,
    pub warnings: Vec<String>,
    /// Every numbered sub-model of the scene (`sparse/N`) when it has two or more; which one
    /// the rest of this summary describes, and why, is `chosen`.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub sub_models: Vec<SubModelSummary>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub chosen: Option<String>,
}

/// One sub-model `sparse/N` of a scene, as `inspect` lists them side by side.
#[derive(Debug, Clone, Serialize)]
pub struct SubModelSummary {
    /// N of `sparse/N`.
    pub index: u32,
    pub images: usize,
    pub points: usize,
    pub mean_reprojection_error_px: Option<f64>,
}

impl ModelSummary {
    /// Observations per point (0 without points).
    pub fn mean_track_length(&self) -> f64 {
        if self.points == 0 {
            0.0
        } else {
            self.observations as f64 / self.points as f64
        }
    }
}

/// A dataset's summary. Serialised, it is `inspect --json`'s object.
#[derive(Debug, Clone, Serialize)]
pub struct DatasetSummary {
    pub dataset: String,
    pub schema_version: u32,
    /// Images the model registered (one verdict each).
    pub registered: usize,
    /// How many images got each verdict, by the verdict's name.
    pub verdicts: BTreeMap<String, usize>,
    pub views: usize,
    #[serde(skip)]
    pub shards: usize,
    pub splits: BTreeMap<String, usize>,
    pub parameters: serde_json::Map<String, serde_json::Value>,
    /// Registered photos by licence (`unknown`: nobody gave one), from `--photo-info`.
    pub licences: BTreeMap<String, usize>,
    /// Registered photos whose EXIF orientation is not 1 (pixels are read as stored).
    pub rotated_by_exif: Vec<String>,
    /// Groups of kept photos that are one picture (scene/duplicates.parquet), by name.
    pub near_duplicates: Vec<Vec<String>>,
}

/// What [`inspect`] found.
#[derive(Debug, Clone)]
pub enum Inspected {
    Model(ModelSummary),
    Dataset(DatasetSummary),
}

/// Summarise `location`: a dataset when it is a URL or holds a manifest, else the COLMAP
/// model of a scene folder (or a model folder itself), read as `format` when given.
/// `pick` chooses a sub-model `sparse/N` (default: the one with the most registered images).
pub fn inspect(
    location: &nrw_dataset::Location,
    format: Option<Format>,
    pick: Option<u32>,
) -> Result<Inspected> {
    let folder = match location {
        nrw_dataset::Location::Local(f) if !f.join(nrw_dataset::Manifest::FILE).is_file() => f,
        _ => return Ok(Inspected::Dataset(dataset_summary(location)?)),
    };
    Ok(Inspected::Model(model_summary(folder, format, pick)?))
}

fn dataset_summary(location: &nrw_dataset::Location) -> Result<DatasetSummary> {
    let ds = nrw_dataset::reader::Dataset::open(nrw_dataset::Store::open(location)?)?;
    let verdicts = nrw_dataset::scene::read_verdicts(&ds.store)?;
    let mut counts = BTreeMap::new();
    for (_, _, v) in &verdicts {
        *counts.entry(v.clone()).or_insert(0usize) += 1;
    }
    let attributions = nrw_dataset::photo_info::read_attributions(&ds.store)?;
    let tally = nrw_dataset::photo_info::tally(
        verdicts.iter().map(|(id, name, _)| (*id, name.as_str())),
        &attributions,
    );
    Ok(DatasetSummary {
        licences: tally.licences,
        rotated_by_exif: tally.rotated_by_exif,
        near_duplicates: nrw_dataset::duplicates::names_by_group(
            &nrw_dataset::duplicates::read_duplicates(&ds.store)?,
        ),
        dataset: location.to_string(),
        schema_version: ds.manifest.schema_version,
        registered: verdicts.len(),
        verdicts: counts,
        views: ds.len(),
        shards: ds.shard_count(),
        splits: ds.splits().into_iter().collect(),
        parameters: ds.manifest.parameters.clone(),
    })
}

/// Each sub-model of a scene with two or more (counts and reprojection error): `chosen`, the
/// one already read, and the others read whole.
fn sub_model_summaries(
    chosen: &Reconstruction,
    scene: &nrw_colmap::Scene,
    format: Option<Format>,
) -> Result<Vec<SubModelSummary>> {
    let (nrw_colmap::ModelChoice::Largest(of) | nrw_colmap::ModelChoice::Given(of)) = &scene.choice
    else {
        return Ok(Vec::new());
    };
    of.iter()
        .map(|m| {
            let other;
            let rec = if m.dir == scene.model_dir {
                chosen
            } else {
                other = nrw_colmap::read_model(&m.dir, format)?;
                &other
            };
            Ok(SubModelSummary {
                index: m.index,
                images: rec.images.len(),
                points: rec.points.len(),
                mean_reprojection_error_px: nrw_colmap::reprojection_stats(rec).mean_px,
            })
        })
        .collect()
}

fn model_summary(
    location: &Path,
    format: Option<Format>,
    pick: Option<u32>,
) -> Result<ModelSummary> {
    let (scene, rec) = crate::model::load_model(location, format, pick)?;
    let sub_models = sub_model_summaries(&rec, &scene, format)?;
    let chosen = scene.choice.explain(&scene.model_dir);
    let dir = scene.model_dir;
    let stats = nrw_colmap::reprojection_stats(&rec);
    let (encoding, layout) = crate::model::encoding_and_layout(&rec);
    Ok(ModelSummary {
        model_dir: dir.display().to_string(),
        encoding,
        layout,
        cameras: rec.cameras.len(),
        images: rec.images.len(),
        points: rec.points.len(),
        observations: rec.num_observations(),
        camera_models: rec.camera_model_names(),
        mean_reprojection_error_px: stats.mean_px,
        max_reprojection_error_px: stats.max_px,
        observations_projected: stats.observations,
        not_visible_observations: stats.not_visible,
        rigs: rec.rigs.len(),
        frames: rec.frames.len(),
        warnings: rec.warnings.iter().map(|w| w.to_string()).collect(),
        sub_models,
        chosen,
    })
}
