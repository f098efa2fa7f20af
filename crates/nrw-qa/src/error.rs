//! Errors of the QA report, naming the table or file that failed.

use nrw_dataset::Location;

/// What went wrong while reading a dataset for QA or writing the report.
#[derive(Debug, thiserror::Error)]
pub enum QaError {
    #[error("{path}: {source}")]
    Polars {
        path: Location,
        source: polars::error::PolarsError,
    },
    #[error("{path}: column `{column}`: {problem}")]
    Column {
        path: Location,
        column: String,
        problem: String,
    },
    #[error(transparent)]
    Dataset(#[from] nrw_dataset::DatasetError),
    #[error("{path}: {source}")]
    Io {
        path: Location,
        source: std::io::Error,
    },
    #[error("chart {chart}: {problem}")]
    Chart { chart: String, problem: String },
}

pub type Result<T> = std::result::Result<T, QaError>;
