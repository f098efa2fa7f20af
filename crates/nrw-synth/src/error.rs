//! Errors of scene generation, naming the spec file or the output file involved.

use std::path::PathBuf;

/// Every way generating a scene can fail.
#[derive(Debug, thiserror::Error)]
pub enum SynthError {
    #[error("{file}: {problem}")]
    Spec { file: String, problem: String },
    #[error("{}: {source}", path.display())]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{}: cannot encode image: {source}", path.display())]
    Image {
        path: PathBuf,
        #[source]
        source: image::ImageError,
    },
    #[error(transparent)]
    Dataset(#[from] nrw_dataset::DatasetError),
}

/// Result alias for this crate.
pub type Result<T, E = SynthError> = std::result::Result<T, E>;
