//! Errors of an export, each naming the file or folder and, for a value, the record and field.

/// Every way an export can fail.
#[derive(Debug, thiserror::Error)]
pub enum ExportError {
    /// Reading the dataset failed (the dataset crate names the file).
    #[error(transparent)]
    Dataset(#[from] nrw_dataset::DatasetError),
    /// The export cannot be made as asked: the folder, the settings or the dataset.
    #[error("{path}: {problem}")]
    Refused {
        path: nrw_dataset::Location,
        problem: String,
    },
    /// One value of one record cannot be exported (a name, a camera, a pose).
    #[error("{path}: record {record}: field `{field}`: {problem}")]
    Value {
        path: nrw_dataset::Location,
        record: String,
        field: String,
        problem: String,
    },
    #[error("{path}: {source}")]
    Io {
        path: nrw_dataset::Location,
        #[source]
        source: std::io::Error,
    },
}

impl ExportError {
    /// Wrap an I/O error with its file.
    pub fn io(path: impl Into<nrw_dataset::Location>, source: std::io::Error) -> Self {
        ExportError::Io {
            path: path.into(),
            source,
        }
    }

    /// The export refused, naming `path`.
    pub fn refused(path: impl Into<nrw_dataset::Location>, problem: impl Into<String>) -> Self {
        ExportError::Refused {
            path: path.into(),
            problem: problem.into(),
        }
    }
}

/// Result alias for this crate.
pub type Result<T, E = ExportError> = std::result::Result<T, E>;
