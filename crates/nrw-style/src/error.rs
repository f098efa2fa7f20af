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
    #[error("a {width}×{height} photo is too small for tier {tier}: the network needs at least 16×16 pixels (fixed-size tiers such as vgg16-256 crop and resize, so they take any photo)")]
    TooSmall {
        width: u32,
        height: u32,
        tier: String,
    },
    #[error("a {width}×{height} photo is smaller than the {crop}×{crop} centre crop of the official tier (the published code asserts the same); use --tier official-N with N ≤ {}", width.min(height))]
    SmallerThanCrop { width: u32, height: u32, crop: u32 },
    #[error("network input {index} of the batch: {problem}")]
    Input { index: usize, problem: String },
    #[error("style backend on {device}: {problem}")]
    Backend { device: String, problem: String },
}

/// Result alias for this crate.
pub type Result<T, E = StyleError> = std::result::Result<T, E>;
