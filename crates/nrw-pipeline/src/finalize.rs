//! Finalize: merge the work units of ingest and style into the scene tables, descriptors and
//! manifest — the same bytes one process writes — refusing, by name, units that are missing or
//! ran with other parameters. Running it again changes nothing.

use nrw_dataset::units;
use nrw_dataset::{Manifest, Store};

use crate::error::{PipelineError, Result};
pub use crate::ingest::{finalize_ingest, IngestMerge};
pub use crate::style::{finalize_style, StyleMerge};
use crate::units::units_error;
/// What `finalize` did; both `None` when there was nothing to merge.
#[derive(Debug, Clone, serde::Serialize)]
pub struct FinalizeSummary {
    pub dataset: String,
    pub ingest: Option<IngestMerge>,
    pub style: Option<StyleMerge>,
}

/// Merge whatever units wait in the dataset (ingest first, then style).
pub fn finalize(dataset: &Store) -> Result<FinalizeSummary> {
    let has = |stage| units::unit_records(dataset, stage).map(|r| !r.is_empty());
    for stage in [units::INGEST, units::STYLE] {
        if !dataset.list(&units::stage_dir(stage))?.is_empty() && !has(stage)? {
            return Err(units_error(dataset, format!(
                "{stage} units have started here but none has finished: run every unit (again; each resumes), then finalize"
            )));
        }
    }
    let ingest = if has(units::INGEST)? {
        Some(finalize_ingest(dataset)?)
    } else {
        None
    };
    let style = if has(units::STYLE)? {
        Some(finalize_style(dataset)?)
    } else {
        None
    };
    if ingest.is_none() && style.is_none() && !dataset.exists(Manifest::FILE)? {
        return Err(PipelineError::Units {
            dataset: dataset.root(),
            problem: "no unit has run here (no .units/ records and no manifest.json): run `nrw-etl ingest SCENE --out DATASET --shard I/N` first".into(),
        });
    }
    Ok(FinalizeSummary {
        dataset: dataset.root().display().to_string(),
        ingest,
        style,
    })
}
