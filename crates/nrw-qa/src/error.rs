//! Errors of the QA report, naming the table or file that failed.

use std::path::PathBuf;

/// What went wrong while reading a dataset for QA or writing the report.
#[derive(Debug, thiserror::Error)]
pub enum QaError {
    #[error("{path}: {source}")]
    Polars {
        path: PathBuf,
        source: polars::error::PolarsError,
    },
    #[error("{path}: column `{column}`: {problem}")]
    Column {
        path: PathBuf,
        column: String,
        problem: String,
    },
    #[error(transparent)]
    Dataset(#[from] nrw_dataset::DatasetError),
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("chart {chart}: {problem}")]
    Chart { chart: String, problem: String },
}

pub type Result<T> = std::result::Result<T, QaError>;
