//! Finalize: merge the work units of ingest and style into the scene tables, descriptors and
//! manifest — the same bytes one process writes — refusing, by name, units that are missing or
//! ran with other parameters. Running it again changes nothing.

use nrw_dataset::units;
use nrw_dataset::{Manifest, Store};

use crate::error::{PipelineError, Result};
pub use crate::ingest::{finalize_ingest, IngestMerge};
pub use crate::style::{finalize_style, StyleMerge};
use crate::units::units_error;
/// Whether a stage's units started in a dataset without any finishing.
type StartedUnfinished = fn(&Store) -> Result<bool>;

/// What `finalize` did; both `None` when there was nothing to merge.
#[derive(Debug, Clone, serde::Serialize)]
pub struct FinalizeSummary {
    pub dataset: String,
    pub ingest: Option<IngestMerge>,
    pub style: Option<StyleMerge>,
}

/// Merge whatever units wait in the dataset: each sharded stage in pipeline order (ingest,
/// then style), through its own merge.
pub fn finalize(dataset: &Store) -> Result<FinalizeSummary> {
    let stages: [(&str, StartedUnfinished); 2] = [
        (units::INGEST, crate::ingest::started_unfinished),
        (units::STYLE, crate::style::started_unfinished),
    ];
    for (stage, started_unfinished) in stages {
        if started_unfinished(dataset)? {
            return Err(units_error(dataset, format!(
                "{stage} units have started here but none has finished: run every unit (again; each resumes), then finalize"
            )));
        }
    }
    let ingest = crate::ingest::merge(dataset)?;
    let style = crate::style::merge(dataset)?;
    if ingest.is_none() && style.is_none() && !dataset.exists(Manifest::FILE)? {
        return Err(PipelineError::Units {
            dataset: dataset.root(),
            problem: "no unit has run here (no .units/ records and no manifest.json): run ingest's work units into it first".into(),
        });
    }
    Ok(FinalizeSummary {
        dataset: dataset.root().display().to_string(),
        ingest,
        style,
    })
}
