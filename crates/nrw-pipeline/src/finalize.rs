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
#[derive(Debug, Clone, Default, serde::Serialize)]
pub struct FinalizeSummary {
    pub dataset: String,
    pub ingest: Option<IngestMerge>,
    pub style: Option<StyleMerge>,
}

impl FinalizeSummary {
    /// Whether no stage had units to merge.
    pub fn merged_nothing(&self) -> bool {
        self.ingest.is_none() && self.style.is_none()
    }
}

/// A group stage as finalize drives it.
struct Step {
    /// The stage's name in the unit records.
    stage: &'static str,
    /// Whether its units started here without any finishing (merging would be premature).
    started_unfinished: fn(&Store) -> Result<bool>,
    /// Its merge, when any of its units ran, into its field of the summary.
    merge: fn(&Store, &mut FinalizeSummary) -> Result<()>,
}

/// The group stages in pipeline order: the one list finalize checks, then merges.
const STEPS: [Step; 2] = [
    Step {
        stage: units::INGEST,
        started_unfinished: crate::ingest::started_unfinished,
        merge: |d, s| {
            s.ingest = crate::ingest::merge(d)?;
            Ok(())
        },
    },
    Step {
        stage: units::STYLE,
        started_unfinished: crate::style::started_unfinished,
        merge: |d, s| {
            s.style = crate::style::merge(d)?;
            Ok(())
        },
    },
];

/// Merge whatever units wait in the dataset: each group stage of [`STEPS`] in pipeline
/// order, through its own merge, once none has started without finishing.
pub fn finalize(dataset: &Store) -> Result<FinalizeSummary> {
    for step in &STEPS {
        if (step.started_unfinished)(dataset)? {
            return Err(units_error(dataset, format!(
                "{} units have started here but none has finished: run every unit (again; each resumes), then finalize",
                step.stage
            )));
        }
    }
    let mut summary = FinalizeSummary {
        dataset: dataset.root().to_string(),
        ..FinalizeSummary::default()
    };
    for step in &STEPS {
        (step.merge)(dataset, &mut summary)?;
    }
    if summary.merged_nothing() && !dataset.exists(Manifest::FILE)? {
        return Err(PipelineError::Units {
            dataset: dataset.root(),
            problem: "no unit has run here (no .units/ records and no manifest.json): run ingest's work units into it first".into(),
        });
    }
    Ok(summary)
}
