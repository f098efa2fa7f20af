//! QA: the dataset report, and the per-stage timings the report shows.

use std::path::{Path, PathBuf};

use crate::error::Result;

/// Where the report goes [default: DATASET/qa].
#[derive(Debug, Clone)]
pub struct QaConfig {
    pub dataset: PathBuf,
    pub out: Option<PathBuf>,
}

/// Write report.html and qa.json; returns where they went and the figures.
pub fn qa(cfg: &QaConfig) -> Result<nrw_qa::Written> {
    let out = cfg
        .out
        .clone()
        .unwrap_or_else(|| cfg.dataset.join(nrw_dataset::QA_DIR));
    Ok(nrw_qa::build(&cfg.dataset, &out)?)
}

/// Record a stage's time; a dataset that cannot take it (read-only copy) loses only the timing.
pub(crate) fn record_timing(dataset: &Path, stage: &str, seconds: f64) {
    let _ = nrw_dataset::timings::record(dataset, stage, seconds);
}

/// Run a stage and, when it succeeds, record its duration in the dataset's timings.
pub(crate) fn timed<T>(dataset: &Path, stage: &str, run: impl FnOnce() -> Result<T>) -> Result<T> {
    let started = std::time::Instant::now();
    let r = run()?;
    record_timing(dataset, stage, started.elapsed().as_secs_f64());
    Ok(r)
}
