//! Errors of reading and writing dataset files, each naming the file.

use std::path::PathBuf;

/// Every way a dataset read or write can fail.
#[derive(Debug, thiserror::Error)]
pub enum DatasetError {
    #[error("{}: {source}", path.display())]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{}: Parquet: {source}", path.display())]
    Parquet {
        path: PathBuf,
        #[source]
        source: parquet::errors::ParquetError,
    },
    #[error("{table}: Arrow: {source}")]
    Arrow {
        table: String,
        #[source]
        source: arrow_schema::ArrowError,
    },
    #[error("{}: {problem}", path.display())]
    Schema { path: PathBuf, problem: String },
    /// A split the dataset does not have (readers map it to a missing key).
    #[error("{}: no split {split:?}; the dataset has {have:?}", path.display())]
    NoSplit {
        path: PathBuf,
        split: String,
        have: Vec<String>,
    },
    /// An image id that is not a kept view (never registered, or dropped by the filters).
    #[error("{}: image {image_id} is not a kept view of this dataset", path.display())]
    NotKept { path: PathBuf, image_id: u32 },
    /// An object-store URL that cannot be opened (scheme, bucket, options).
    #[error("{url}: cannot open this object-store location: {problem}")]
    Location { url: String, problem: String },
    #[error("{}: record {record}: field `{field}`: {problem}", path.display())]
    Value {
        path: PathBuf,
        record: String,
        field: String,
        problem: String,
    },
    /// A photo or label map whose bytes cannot be decoded whole (truncated, corrupt, not an
    /// image): ingest records the view as `unreadable` instead of storing filled-in pixels.
    #[error("{}: unreadable: {problem}", path.display())]
    Unreadable { path: PathBuf, problem: String },
    #[error("{}: JSON: {source}", path.display())]
    Json {
        path: PathBuf,
        #[source]
        source: serde_json::Error,
    },
}

impl DatasetError {
    /// Wrap an I/O error with its file.
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        DatasetError::Io {
            path: path.into(),
            source,
        }
    }
}

/// Result alias for this crate.
pub type Result<T, E = DatasetError> = std::result::Result<T, E>;
