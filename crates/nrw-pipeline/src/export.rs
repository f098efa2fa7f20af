//! Export: a dataset as files other tools read (the layouts and their bytes live in
//! `nrw_dataset::export`); this supplies the style distance matrix and the default name.

use std::path::Path;

use nrw_dataset::export::{ExportConfig, ExportSummary};

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
    ExportConfig {
        layout: nrw_dataset::export::Layout::Official,
        out: out.into(),
        name: default_name(dataset),
        crop: None,
        semantics: true,
        depth: nrw_dataset::export::official::DepthMapping::Linear,
        shards: 1,
    }
}

/// Export `dataset` as `cfg` says.
pub fn export(
    dataset: &Path,
    cfg: &ExportConfig,
    progress: &dyn Progress,
) -> Result<ExportSummary> {
    let store = &nrw_dataset::Store::open_path(dataset)?;
    crate::qa::timed(store, "export", || {
        let ds = crate::triplets::require_views(store)?;
        let total: usize = ds.splits().iter().map(|(_, n)| n).sum();
        progress.start("export", total as u64, "views");
        let dist = |ids: &[u32]| crate::triplets::official_distance_matrix(store, ids, cfg.crop);
        let summary = nrw_dataset::export::export(&ds, cfg, &dist, &|| progress.inc(1))?;
        progress.finish();
        Ok(summary)
    })
}
