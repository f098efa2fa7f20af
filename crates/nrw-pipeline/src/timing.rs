//! Each stage's wall time, recorded in the dataset's timings file (the QA report shows them).

use nrw_dataset::Store;

use crate::error::Result;

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
