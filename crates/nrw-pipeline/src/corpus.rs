//! The corpus index of a many-scene run: one row per scene from its dataset's QA figures
//! (`qa/qa.json`), or from the error its pipeline ended with.

use nrw_dataset::corpus::{write_corpus, CorpusRow, STATUS_FAILED, STATUS_OK};
use nrw_dataset::Store;

use crate::error::{PipelineError, Result, Setting};

/// One scene as the driver ran it.
#[derive(Debug, Clone, serde::Deserialize)]
pub struct CorpusEntry {
    /// The scene folder as given.
    pub scene: String,
    /// The dataset's name under the corpus prefix.
    pub name: String,
    /// Where the dataset was written (folder or URL).
    pub dataset: String,
    /// Why the scene's pipeline failed; absent when it finished.
    #[serde(default)]
    pub error: Option<String>,
}

/// Parse the driver's entries (a JSON array of [`CorpusEntry`]), naming the bad one.
pub fn parse_entries(json: &str) -> Result<Vec<CorpusEntry>> {
    serde_json::from_str(json).map_err(|e| {
        PipelineError::config(
            Setting::Entries,
            format!(
                "is not a JSON array of {{scene, name, dataset, error}}: {e} (line {}, column {})",
                e.line(),
                e.column()
            ),
        )
    })
}

/// A count of the QA figures, when present.
fn count(v: &serde_json::Value, key: &str) -> Option<u64> {
    v["counts"][key].as_u64()
}

/// The row of a scene whose pipeline finished: its dataset's QA figures, or a failed row
/// naming the figures that could not be read.
fn finished(e: &CorpusEntry, base: CorpusRow) -> CorpusRow {
    let figures = Store::open(&nrw_dataset::Location::parse(&e.dataset))
        .and_then(|s| s.sub(nrw_dataset::QA_DIR))
        .and_then(|qa| qa.read(nrw_qa::QA_JSON).map(|b| (qa, b)));
    let (qa, bytes) = match figures {
        Ok(f) => f,
        Err(err) => {
            return CorpusRow {
                status: STATUS_FAILED.into(),
                error: Some(format!("no QA figures: {err}")),
                ..base
            }
        }
    };
    let v: serde_json::Value = match serde_json::from_slice(&bytes) {
        Ok(v) => v,
        Err(err) => {
            return CorpusRow {
                status: STATUS_FAILED.into(),
                error: Some(format!("{}: {err}", qa.name(nrw_qa::QA_JSON))),
                ..base
            }
        }
    };
    CorpusRow {
        report: Some(qa.name(nrw_qa::REPORT_FILE).to_string()),
        status: STATUS_OK.into(),
        registered: count(&v, "registered"),
        kept: count(&v, "kept"),
        dropped: count(&v, "dropped"),
        train: count(&v, "train"),
        val: count(&v, "val"),
        descriptors: count(&v, "descriptors"),
        warnings: v["warnings"].as_array().map(|w| w.len() as u64),
        drops: Some(v["drops"].to_string()),
        ..base
    }
}

/// Write `corpus.parquet` under `out` (a folder or URL) for these scenes; returns its rows.
pub fn index(out: &str, entries: &[CorpusEntry]) -> Result<Vec<CorpusRow>> {
    let rows: Vec<CorpusRow> = entries
        .iter()
        .map(|e| {
            let base = CorpusRow {
                scene: e.scene.clone(),
                name: e.name.clone(),
                dataset: e.dataset.clone(),
                ..Default::default()
            };
            match &e.error {
                Some(err) => CorpusRow {
                    status: STATUS_FAILED.into(),
                    error: Some(err.clone()),
                    ..base
                },
                None => finished(e, base),
            }
        })
        .collect();
    write_corpus(&Store::open(&nrw_dataset::Location::parse(out))?, &rows)?;
    Ok(rows)
}
