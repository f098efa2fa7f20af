//! Errors of reading and writing dataset files, each naming the file.

use crate::location::Location;

/// Every way a dataset read or write can fail.
#[derive(Debug, thiserror::Error)]
pub enum DatasetError {
    #[error("{path}: {source}")]
    Io {
        path: Location,
        #[source]
        source: std::io::Error,
    },
    #[error("{path}: Parquet: {source}")]
    Parquet {
        path: Location,
        #[source]
        source: parquet::errors::ParquetError,
    },
    #[error("{table}: Arrow: {source}")]
    Arrow {
        table: String,
        #[source]
        source: arrow_schema::ArrowError,
    },
    #[error("{path}: {problem}")]
    Schema { path: Location, problem: String },
    /// A split the dataset does not have (readers map it to a missing key).
    #[error("{path}: no split {split:?}; the dataset has {have:?}")]
    NoSplit {
        path: Location,
        split: String,
        have: Vec<String>,
    },
    /// An image id that is not a kept view (never registered, or dropped by the filters).
    #[error("{path}: image {image_id} is not a kept view of this dataset")]
    NotKept { path: Location, image_id: u32 },
    /// An object-store URL that cannot be opened (scheme, bucket, options).
    #[error("{url}: cannot open this object-store location: {problem}")]
    Location { url: String, problem: String },
    #[error("{path}: record {record}: field `{field}`: {problem}")]
    Value {
        path: Location,
        record: String,
        field: String,
        problem: String,
    },
    /// A photo or label map whose bytes cannot be decoded whole (truncated, corrupt, not an
    /// image): ingest records the view as `unreadable` instead of storing filled-in pixels.
    #[error("{path}: unreadable: {problem}")]
    Unreadable { path: Location, problem: String },
    #[error("{path}: JSON: {source}")]
    Json {
        path: Location,
        #[source]
        source: serde_json::Error,
    },
}

impl DatasetError {
    /// Wrap an I/O error with its file.
    pub fn io(path: impl Into<Location>, source: std::io::Error) -> Self {
        DatasetError::Io {
            path: path.into(),
            source,
        }
    }
}

/// Result alias for this crate.
pub type Result<T, E = DatasetError> = std::result::Result<T, E>;
