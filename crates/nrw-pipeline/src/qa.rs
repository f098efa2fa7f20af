//! QA: the dataset report, and the per-stage timings the report shows.

use std::path::{Path, PathBuf};

use nrw_dataset::Store;

use crate::error::Result;

/// Where the report goes [default: DATASET/qa].
#[derive(Debug, Clone)]
pub struct QaConfig {
    pub dataset: PathBuf,
    pub out: Option<PathBuf>,
}

/// Write report.html and qa.json; returns where they went and the figures. A dataset on
/// object storage gets its report under DATASET/qa/ there unless `out` names a folder.
pub fn qa(cfg: &QaConfig) -> Result<nrw_qa::Written> {
    let store = Store::open_path(&cfg.dataset)?;
    if let Some(out) = &cfg.out {
        return Ok(nrw_qa::build(&store, out)?);
    }
    if let Some(dir) = store.local_dir() {
        return Ok(nrw_qa::build(&store, &dir.join(nrw_dataset::QA_DIR))?);
    }
    let tmp = std::env::temp_dir().join(format!("nrw-qa-{}", std::process::id()));
    let built = nrw_qa::build(&store, &tmp);
    let uploaded = built.and_then(|mut w| {
        let up = |local: &Path| -> Result<PathBuf, nrw_qa::QaError> {
            let name = local
                .file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_default();
            let rel = format!("{}/{name}", nrw_dataset::QA_DIR);
            let bytes = std::fs::read(local).map_err(|source| nrw_qa::QaError::Io {
                path: local.into(),
                source,
            })?;
            store.write(&rel, bytes)?;
            Ok(store.name(&rel))
        };
        w.report = up(&w.report)?;
        w.json = up(&w.json)?;
        Ok(w)
    });
    let _ = std::fs::remove_dir_all(&tmp);
    Ok(uploaded?)
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
