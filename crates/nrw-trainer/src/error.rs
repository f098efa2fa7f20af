//! Errors of the trainer, naming the dataset, checkpoint or setting at fault.

use std::path::PathBuf;

/// What went wrong while loading data or training.
#[derive(Debug, thiserror::Error)]
pub enum TrainError {
    #[error(transparent)]
    Dataset(#[from] nrw_dataset::DatasetError),
    #[error("{0}")]
    Usage(String),
    #[error("tensor computation: {0}")]
    Tensor(#[from] candle_core::Error),
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{path}: {problem}")]
    Checkpoint { path: PathBuf, problem: String },
}

pub type Result<T> = std::result::Result<T, TrainError>;
