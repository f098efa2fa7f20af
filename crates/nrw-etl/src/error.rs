//! The CLI's error: a stage's typed error, or a problem with what the user asked for.

use std::path::PathBuf;

/// Everything a command can fail with; each message names the file (and record) involved.
#[derive(Debug, thiserror::Error)]
pub enum EtlError {
    #[error(transparent)]
    Colmap(#[from] nrw_colmap::ColmapError),
    #[error(transparent)]
    Dataset(#[from] nrw_dataset::DatasetError),
    #[error("{}: cannot read the photo's size: {source}", path.display())]
    Photo {
        path: PathBuf,
        #[source]
        source: image::ImageError,
    },
    #[error(transparent)]
    Synth(#[from] nrw_synth::SynthError),
    #[error("{0}")]
    Usage(String),
    #[error("interrupted: {0}")]
    Interrupted(String),
}

/// Result alias for the CLI.
pub type Result<T, E = EtlError> = std::result::Result<T, E>;
