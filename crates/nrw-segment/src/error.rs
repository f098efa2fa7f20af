//! The segmentation crate's errors: each names the file (or input) and what was expected.

use std::path::PathBuf;

/// Why a model could not be loaded or a photo not segmented.
#[derive(Debug, thiserror::Error)]
pub enum SegmentError {
    /// A file could not be read.
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    /// The model files are not a SegFormer for the 150 ADE20K classes as the config says.
    #[error("{path}: {problem}")]
    Model { path: PathBuf, problem: String },
    /// A photo this mode cannot segment (too small for the crop, too small for the network).
    #[error("{what}: {problem}")]
    Input { what: String, problem: String },
}

/// Results of this crate.
pub type Result<T> = std::result::Result<T, SegmentError>;

impl SegmentError {
    /// A model problem in `path`.
    pub(crate) fn model(path: &std::path::Path, problem: impl Into<String>) -> SegmentError {
        SegmentError::Model {
            path: path.to_path_buf(),
            problem: problem.into(),
        }
    }
}
