//! Split: a reproducible, incremental train/validation assignment of the kept photos.

use std::path::PathBuf;

use nrw_dataset::split::{assign, read_splits, write_splits};
use nrw_dataset::{Manifest, Store};

use crate::error::{PipelineError, Result};

/// Split's settings; `new` is the paper's (100 validation photos, seed 0).
#[derive(Debug, Clone)]
pub struct SplitConfig {
    pub dataset: PathBuf,
    /// Validation photos; 0 puts every photo in training.
    pub val: usize,
    /// Same seed, same split on any machine.
    pub seed: u64,
}

impl SplitConfig {
    /// The paper's split of a dataset.
    pub fn new(dataset: impl Into<PathBuf>) -> SplitConfig {
        SplitConfig {
            dataset: dataset.into(),
            val: 100,
            seed: 0,
        }
    }
}

/// What split assigned.
#[derive(Debug, Clone, serde::Serialize)]
pub struct SplitSummary {
    pub train: usize,
    pub val: usize,
    /// Photos that kept their earlier assignment.
    pub kept: usize,
    pub new: usize,
    /// Photos assigned earlier that are no longer kept (removed from the split).
    pub gone: Vec<String>,
}

/// Assign the kept photos and list the table in the manifest.
pub fn split(cfg: &SplitConfig) -> Result<SplitSummary> {
    let store = &Store::open_path(&cfg.dataset)?;
    crate::qa::timed(store, "split", || {
        let mut manifest = Manifest::read(store)?;
        let kept: Vec<(u32, String)> = nrw_dataset::scene::read_verdicts(store)?
            .into_iter()
            .filter(|(_, _, v)| v == nrw_dataset::scene::VERDICT_KEPT)
            .map(|(id, name, _)| (id, name))
            .collect();
        let previous = read_splits(store)?;
        let (rows, change) = assign(&kept, &previous, cfg.val, cfg.seed)
            .map_err(|e| PipelineError::dataset(&cfg.dataset, e.to_string()))?;
        manifest.replace_table(write_splits(store, &rows)?);
        manifest
            .parameters
            .insert("split_val".into(), cfg.val.into());
        manifest.write(store)?;
        let val = rows.iter().filter(|a| a.split == "val").count();
        Ok(SplitSummary {
            train: rows.len() - val,
            val,
            kept: change.kept_train + change.kept_val,
            new: change.new_train + change.new_val,
            gone: change.gone,
        })
    })
}
