//! QA: the dataset report (report.html, qa.json) beside the dataset or where asked.

use nrw_dataset::Store;

use crate::error::Result;

/// Where the report goes [default: DATASET/qa].
#[derive(Debug, Clone)]
pub struct QaConfig {
    pub dataset: nrw_dataset::Location,
    pub out: Option<nrw_dataset::Location>,
}

/// Write report.html and qa.json; returns where they went and the figures. The report goes
/// to `out` when given (a folder or a URL), else beside the dataset in DATASET/qa/ (on object
/// storage too): always through the store, never a temporary copy.
pub fn qa(cfg: &QaConfig) -> Result<nrw_qa::Written> {
    let store = Store::open(&cfg.dataset)?;
    let out = match &cfg.out {
        Some(out) => Store::open(out)?,
        None => store.sub(nrw_dataset::QA_DIR)?,
    };
    Ok(nrw_qa::build(&store, &out)?)
}
