//! QA: the dataset report, and the per-stage timings the report shows.

use std::path::PathBuf;

use nrw_dataset::Store;

use crate::error::Result;

/// Where the report goes [default: DATASET/qa].
#[derive(Debug, Clone)]
pub struct QaConfig {
    pub dataset: PathBuf,
    pub out: Option<PathBuf>,
}

/// Write report.html and qa.json; returns where they went and the figures. The report goes
/// to `out` when given (a folder or a URL), else beside the dataset in DATASET/qa/ (on object
/// storage too): always through the store, never a temporary copy.
pub fn qa(cfg: &QaConfig) -> Result<nrw_qa::Written> {
    let store = Store::open_path(&cfg.dataset)?;
    let out = match &cfg.out {
        Some(out) => Store::open_path(out)?,
        None => store.sub(nrw_dataset::QA_DIR)?,
    };
    Ok(nrw_qa::build(&store, &out)?)
}

/// Record a stage's time; a dataset that cannot take it (read-only copy) loses only the timing.
pub(crate) fn record_timing(dataset: &Store, stage: &str, seconds: f64) {
    let _ = nrw_dataset::timings::record(dataset, stage, seconds);
}

/// Run a stage and, when it succeeds, record its duration in the dataset's timings.
pub(crate) fn timed<T>(dataset: &Store, stage: &str, run: impl FnOnce() -> Result<T>) -> Result<T> {
    let started = std::time::Instant::now();
    let r = run()?;
    record_timing(dataset, stage, started.elapsed().as_secs_f64());
    Ok(r)
}
