//! `manifest.json`: what a dataset was made from, with which parameters, and what it holds.
//! Hashes let a later stage (or a person) tell whether inputs or tables changed.

use std::io::Read;
use std::path::Path;

use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};

use crate::error::{DatasetError, Result};
use crate::store::Store;

/// Bumped whenever a table's schema changes incompatibly.
pub const SCHEMA_VERSION: u32 = 3;

/// A file recorded in the manifest.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct FileEntry {
    /// Relative to the dataset (tables) or as given on the command line (inputs).
    pub path: String,
    pub bytes: u64,
    pub sha256: String,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rows: Option<u64>,
}

impl FileEntry {
    /// Size and SHA-256 of a dataset's file `rel`, recorded under the name `rel`.
    pub fn of(store: &Store, rel: &str) -> Result<FileEntry> {
        Ok(FileEntry::of_bytes(rel, &store.read(rel)?))
    }

    /// Size and SHA-256 of bytes about to be written as `rel`.
    pub fn of_bytes(rel: &str, data: &[u8]) -> FileEntry {
        FileEntry {
            path: rel.to_string(),
            bytes: data.len() as u64,
            sha256: sha256_hex(data),
            rows: None,
        }
    }
}

/// Streaming SHA-256 of a file: (size in bytes, lowercase hex digest).
pub fn sha256_file(path: &Path) -> Result<(u64, String)> {
    let mut f = std::fs::File::open(path).map_err(|e| DatasetError::io(path, e))?;
    let mut h = Sha256::new();
    let mut buf = vec![0u8; 1 << 20];
    let mut n = 0u64;
    loop {
        let k = f.read(&mut buf).map_err(|e| DatasetError::io(path, e))?;
        if k == 0 {
            break;
        }
        n += k as u64;
        h.update(&buf[..k]);
    }
    Ok((n, hex(&h.finalize())))
}

/// SHA-256 of bytes as lower-case hex: the form of every digest a manifest, a unit record or
/// a fingerprint holds.
pub fn sha256_hex(data: &[u8]) -> String {
    hex(&Sha256::digest(data))
}

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

/// Which tool wrote the dataset.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Tool {
    pub name: String,
    pub version: String,
}

/// Where the scene came from.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct SceneSource {
    pub scene_dir: String,
    pub model_dir: String,
    pub images_dir: Option<String>,
    /// `bin` or `txt`.
    pub encoding: String,
    /// `colmap3` or `colmap4` (rigs and frames).
    pub layout: String,
}

/// The dataset's table of contents.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Manifest {
    pub schema_version: u32,
    pub tool: Tool,
    pub scene: SceneSource,
    pub inputs: Vec<FileEntry>,
    /// Stage parameters as given (defaults filled in), so a run can be repeated.
    pub parameters: serde_json::Map<String, serde_json::Value>,
    pub tables: Vec<FileEntry>,
    pub warnings: Vec<String>,
}

impl Manifest {
    /// File name inside a dataset folder.
    pub const FILE: &'static str = "manifest.json";

    /// Write `manifest.json` atomically, pretty-printed for people.
    pub fn write(&self, store: &Store) -> Result<()> {
        let path = store.name(Self::FILE);
        let mut text = serde_json::to_string_pretty(self).map_err(|e| DatasetError::Json {
            path: path.clone(),
            source: e,
        })?;
        text.push('\n');
        store.write(Self::FILE, text.into_bytes())
    }

    /// List `entry` in place of any earlier entry with its path.
    pub fn replace_table(&mut self, entry: FileEntry) {
        self.tables.retain(|t| t.path != entry.path);
        self.tables.push(entry);
    }

    /// Drop every table whose path `gone` accepts (e.g. a stage's outputs made stale).
    pub fn remove_tables(&mut self, gone: impl Fn(&str) -> bool) {
        self.tables.retain(|t| !gone(&t.path));
    }

    /// A small table's bytes, checked against this manifest's size and SHA-256 when it lists
    /// the file: what a reader of a whole table (triplets, the scene tables in QA) uses so a
    /// changed byte is an error naming the file, never a silently different table.
    pub fn read_checked(&self, store: &Store, rel: &str) -> Result<bytes::Bytes> {
        let data = store.read(rel)?;
        if let Some(t) = self.tables.iter().find(|t| t.path == rel) {
            let found = FileEntry::of_bytes(rel, &data);
            if found.bytes != t.bytes || found.sha256 != t.sha256 {
                return Err(DatasetError::Value {
                    path: store.name(rel),
                    record: "the whole file".into(),
                    field: "sha256".into(),
                    problem: format!(
                        "{} bytes with SHA-256 {} but manifest.json records {} bytes with {}: the file changed after it was written (`nrw-etl verify` lists every damaged file; re-running the stage that wrote it replaces it)",
                        found.bytes, found.sha256, t.bytes, t.sha256
                    ),
                });
            }
        }
        Ok(data)
    }

    /// Read a dataset's manifest, refusing other schema versions.
    pub fn read(store: &Store) -> Result<Manifest> {
        Self::parse(&store.read(Self::FILE)?, store.name(Self::FILE))
    }

    /// Parse a manifest's bytes (`path` names them in errors), refusing other schema versions.
    pub fn parse(text: &[u8], path: crate::Location) -> Result<Manifest> {
        let m: Manifest = serde_json::from_slice(text).map_err(|e| DatasetError::Json {
            path: path.clone(),
            source: e,
        })?;
        if m.schema_version != SCHEMA_VERSION {
            return Err(DatasetError::Schema {
                path,
                problem: format!(
                    "dataset schema version {} is not the {SCHEMA_VERSION} this tool reads; re-run ingest",
                    m.schema_version
                ),
            });
        }
        Ok(m)
    }
}
