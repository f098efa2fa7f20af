//! Errors of style descriptor computation, naming the weights file, tensor or photo.

use std::path::PathBuf;

/// Every way computing a descriptor can fail.
#[derive(Debug, thiserror::Error)]
pub enum StyleError {
    #[error("{}: {source}", path.display())]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{}: weights: {problem}", path.display())]
    Weights { path: PathBuf, problem: String },
    #[error("{}: {problem}", path.display())]
    Image { path: PathBuf, problem: String },
}

/// Result alias for this crate.
pub type Result<T, E = StyleError> = std::result::Result<T, E>;
