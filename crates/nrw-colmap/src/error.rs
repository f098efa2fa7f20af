//! One error type for every reader, so a message always names file, record and field.

use std::fmt;
use std::path::PathBuf;

/// Where in a file a problem sits; formatted only when an error is shown, so parsing never allocates for it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Record {
    /// The file as a whole (header, counts, layout).
    File,
    /// The n-th record of a binary file (0-based), with its id once read.
    Nth {
        kind: &'static str,
        index: u64,
        id: Option<u64>,
    },
    /// A line of a text file (1-based), with the record id once read.
    Line {
        kind: &'static str,
        line: usize,
        id: Option<u64>,
    },
    /// A record known by id only (cross-reference checks after reading).
    Id { kind: &'static str, id: u64 },
}

impl Record {
    /// The same record once its id is known.
    pub fn with_id(self, new_id: u64) -> Record {
        match self {
            Record::Nth { kind, index, .. } => Record::Nth {
                kind,
                index,
                id: Some(new_id),
            },
            Record::Line { kind, line, .. } => Record::Line {
                kind,
                line,
                id: Some(new_id),
            },
            Record::Id { kind, .. } => Record::Id { kind, id: new_id },
            Record::File => Record::File,
        }
    }
}

impl fmt::Display for Record {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Record::File => write!(f, "file header"),
            Record::Nth {
                kind,
                index,
                id: Some(id),
            } => write!(f, "{kind} #{index} (id {id})"),
            Record::Nth {
                kind,
                index,
                id: None,
            } => write!(f, "{kind} #{index}"),
            Record::Line {
                kind,
                line,
                id: Some(id),
            } => write!(f, "line {line} ({kind} id {id})"),
            Record::Line {
                kind,
                line,
                id: None,
            } => write!(f, "line {line} ({kind})"),
            Record::Id { kind, id } => write!(f, "{kind} id {id}"),
        }
    }
}

/// Every way reading a reconstruction can fail.
#[derive(Debug, thiserror::Error)]
pub enum ColmapError {
    /// The operating system refused a read.
    #[error("{}: {source}", path.display())]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// A value in a file is missing, malformed, out of range or inconsistent.
    #[error("{}: {record}: field `{field}`: {problem}", path.display())]
    Invalid {
        path: PathBuf,
        record: Record,
        field: String,
        problem: String,
    },
    /// The folder holds no model in a layout we know.
    #[error("{}: no COLMAP model found; looked for cameras/images/points3D .bin or .txt in {looked}", path.display())]
    NoModel { path: PathBuf, looked: String },
    /// `--model N` named a sub-model the scene does not have.
    #[error("{}: no such sub-model; the scene has {have}", path.display())]
    NoSubModel { path: PathBuf, have: String },
}

impl ColmapError {
    /// Shorthand used by every reader.
    pub fn invalid(
        path: impl Into<PathBuf>,
        record: Record,
        field: impl Into<String>,
        problem: impl Into<String>,
    ) -> Self {
        ColmapError::Invalid {
            path: path.into(),
            record,
            field: field.into(),
            problem: problem.into(),
        }
    }

    /// Wrap an I/O error with the file it came from.
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        ColmapError::Io {
            path: path.into(),
            source,
        }
    }
}

/// Result alias for this crate.
pub type Result<T, E = ColmapError> = std::result::Result<T, E>;
