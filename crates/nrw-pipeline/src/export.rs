//! Export: a dataset as files other tools read (the layouts and their bytes live in
//! `nrw_export`); this supplies what the layouts need from other stages (the style distance
//! matrix, the scene's points) and the default name.

use nrw_export::{ExportConfig, ExportSummary};

use crate::error::Result;
use crate::Progress;

/// The export's default name: the dataset folder's.
pub fn default_name(dataset: &nrw_dataset::Location) -> String {
    let folder = match dataset {
        nrw_dataset::Location::Local(d) => std::fs::canonicalize(d)
            .ok()
            .and_then(|p| p.file_name().map(|n| n.to_string_lossy().into_owned()))
            .or_else(|| d.file_name().map(|n| n.to_string_lossy().into_owned())),
        nrw_dataset::Location::Url(u) => u.rsplit('/').next().map(str::to_string),
    };
    folder
        .filter(|n| !n.is_empty())
        .unwrap_or_else(|| "dataset".into())
}

pub fn official(dataset: &nrw_dataset::Location, out: &nrw_dataset::Location) -> ExportConfig {
    ExportConfig::official(out.clone(), default_name(dataset))
}

/// Export `dataset` as `cfg` says.
pub fn export(
    dataset: &nrw_dataset::Location,
    cfg: &ExportConfig,
    progress: &dyn Progress,
) -> Result<ExportSummary> {
    let store = &nrw_dataset::Store::open(dataset)?;
    crate::timing::timed(store, "export", || {
        let ds = crate::triplets::require_views(store)?;
        let total: usize = ds.splits().iter().map(|(_, n)| n).sum();
        let model = if cfg.layout.needs_points() {
            Some(scene_model(store)?)
        } else {
            None
        };
        let points = model.as_ref().map(points_of);
        let mvs = if cfg.layout.writes_depth_priors() {
            crate::mvs_prior::MvsPriors::of_dataset(store)?
        } else {
            None
        };
        let mvs_depth = |v: &nrw_dataset::ViewRow| match &mvs {
            Some(m) => m.depth(v).map_err(|e| e.to_string()),
            None => Ok(None),
        };
        let prior = mvs.as_ref().map(|m| nrw_export::DepthPrior {
            source: m.source(),
            depth: &mvs_depth,
        });
        let dist = |ids: &[u32]| crate::triplets::official_distance_matrix(store, ids, cfg.crop);
        let inputs = nrw_export::Inputs {
            dist: Some(&dist),
            points: points.as_deref(),
            model: model.as_ref(),
            depth_prior: prior.as_ref(),
        };
        progress.start("export", total as u64, "views");
        let summary = nrw_export::export(&ds, cfg, &inputs, &|| progress.inc(1))?;
        progress.finish();
        Ok(summary)
    })
}

/// The model the dataset was ingested from (named in its manifest), after checking that the
/// model files are the ones ingest read.
pub fn scene_model(store: &nrw_dataset::Store) -> Result<nrw_colmap::Reconstruction> {
    let m = nrw_dataset::Manifest::read(store)?;
    let (rec, changed) = crate::model::reread_model(&m.scene, &m.inputs)?;
    if let Some(f) = changed {
        return Err(crate::error::PipelineError::input(
            &f,
            "changed since this dataset was ingested from it (its SHA-256 differs from the \
             manifest's): the exported points would not belong to the dataset's poses",
        ));
    }
    Ok(rec)
}

/// A model's 3D points as the layouts carry them.
pub fn points_of(rec: &nrw_colmap::Reconstruction) -> Vec<nrw_export::ScenePoint> {
    rec.points
        .values()
        .map(|p| nrw_export::ScenePoint {
            id: p.id,
            xyz: p.xyz.to_array(),
            rgb: p.rgb,
            error: p.error,
        })
        .collect()
}
