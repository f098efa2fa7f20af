//! Export: a dataset as files other tools read (the layouts and their bytes live in
//! `nrw_export`); this supplies what the layouts need from other stages (the style distance
//! matrix, the scene's points) and the default name.

use std::path::Path;

use nrw_export::{ExportConfig, ExportSummary};

use crate::error::Result;
use crate::Progress;

/// The export's default name: the dataset folder's.
pub fn default_name(dataset: &Path) -> String {
    std::fs::canonicalize(dataset)
        .ok()
        .and_then(|p| p.file_name().map(|n| n.to_string_lossy().into_owned()))
        .or_else(|| {
            dataset
                .file_name()
                .map(|n| n.to_string_lossy().into_owned())
        })
        .unwrap_or_else(|| "dataset".into())
}

/// The official export of a dataset into `out` with the defaults (name, linear depth, one
/// shard, semantics when present).
pub fn official(dataset: &Path, out: &Path) -> ExportConfig {
    ExportConfig::official(out.into(), default_name(dataset))
}

/// Export `dataset` as `cfg` says.
pub fn export(
    dataset: &Path,
    cfg: &ExportConfig,
    progress: &dyn Progress,
) -> Result<ExportSummary> {
    let store = &nrw_dataset::Store::open_path(dataset)?;
    crate::timing::timed(store, "export", || {
        let ds = crate::triplets::require_views(store)?;
        let total: usize = ds.splits().iter().map(|(_, n)| n).sum();
        let points = if cfg.layout.needs_points() {
            Some(scene_points(store)?)
        } else {
            None
        };
        let dist = |ids: &[u32]| crate::triplets::official_distance_matrix(store, ids, cfg.crop);
        let inputs = nrw_export::Inputs {
            dist: Some(&dist),
            points: points.as_deref(),
        };
        progress.start("export", total as u64, "views");
        let summary = nrw_export::export(&ds, cfg, &inputs, &|| progress.inc(1))?;
        progress.finish();
        Ok(summary)
    })
}

/// The 3D points of the model the dataset was ingested from (named in its manifest), after
/// checking that the model files are the ones ingest read.
pub fn scene_points(store: &nrw_dataset::Store) -> Result<Vec<nrw_export::ScenePoint>> {
    let m = nrw_dataset::Manifest::read(store)?;
    let (rec, changed) = crate::model::reread_model(&m.scene, &m.inputs)?;
    if let Some(f) = changed {
        return Err(crate::error::PipelineError::input(
            &f,
            "changed since this dataset was ingested from it (its SHA-256 differs from the \
             manifest's): the exported points would not belong to the dataset's poses",
        ));
    }
    Ok(rec
        .points
        .values()
        .map(|p| nrw_export::ScenePoint {
            id: p.id,
            xyz: p.xyz.to_array(),
            rgb: p.rgb,
            error: p.error,
        })
        .collect())
}
