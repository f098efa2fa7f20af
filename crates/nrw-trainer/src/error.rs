//! Errors of the trainer, naming the dataset, checkpoint or setting at fault.

use std::path::PathBuf;

/// What went wrong while loading data or training.
#[derive(Debug, thiserror::Error)]
pub enum TrainError {
    #[error(transparent)]
    Dataset(#[from] nrw_dataset::DatasetError),
    /// A split with no view to load.
    #[error("{dataset}: split {split:?} holds no views")]
    EmptySplit {
        dataset: nrw_dataset::Location,
        split: String,
    },
    /// A setting out of its range, named as the config field (`pos_k`); the binary names its
    /// own flag for it.
    #[error("{setting}: {problem}")]
    Setting {
        setting: &'static str,
        problem: String,
    },
    /// The dataset has no triplet table yet.
    #[error("{dataset}: no triplets.parquet; run `nrw-etl style` and `nrw-etl triplets` first")]
    NoTripletTable { dataset: nrw_dataset::Location },
    /// Holding photos out left no triplet to train on.
    #[error("no training triplets: {anchors} anchors, {held_out} held out")]
    NoTriplets { anchors: usize, held_out: usize },
    /// The checkpoint folder holds a run of other settings.
    #[error("{}: holds a checkpoint of other settings; use another checkpoint folder or the same settings", out.display())]
    OtherSettings { out: PathBuf },
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

impl From<nrw_dataset::sampling::SamplingError> for TrainError {
    /// Keeps the sampler's settings named as this crate's, so the binary maps them to flags.
    fn from(e: nrw_dataset::sampling::SamplingError) -> Self {
        use nrw_dataset::sampling::SamplingError as S;
        match e {
            S::Setting { setting, problem } => TrainError::Setting { setting, problem },
            S::NoTriplets { anchors, held_out } => TrainError::NoTriplets { anchors, held_out },
        }
    }
}
