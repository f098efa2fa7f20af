//! Verify: every file a dataset's manifest lists against what it records (size, SHA-256,
//! rows), every payload of shards and descriptor parts against its CRC-32, and files the
//! manifest does not list, on disk or on object storage.

use std::time::Instant;

use nrw_dataset::{Manifest, Store};

use crate::error::Result;
use crate::Progress;

/// One way the dataset differs from its manifest.
#[derive(Debug, Clone, serde::Serialize)]
pub struct Mismatch {
    /// The file (a path or URL).
    pub file: String,
    /// `missing`, `size`, `sha256`, `rows`, `parquet` (unreadable), or a payload as
    /// `<column> at row <r> (image <id>)` with its CRC-32s.
    pub field: String,
    pub expected: String,
    pub found: String,
}

/// What `verify` found.
#[derive(Debug, Clone, serde::Serialize)]
pub struct VerifyReport {
    pub dataset: String,
    pub files: usize,
    pub bytes: u64,
    pub mismatches: Vec<Mismatch>,
    /// Files in the dataset that the manifest does not list (left by unfinished units, or
    /// added by hand): readers ignore them.
    pub unlisted: Vec<String>,
    pub seconds: f64,
}

impl VerifyReport {
    /// Whether every listed file is as the manifest records it.
    pub fn ok(&self) -> bool {
        self.mismatches.is_empty()
    }

    /// Read throughput of the check.
    pub fn mb_per_s(&self) -> f64 {
        self.bytes as f64 / 1e6 / self.seconds.max(1e-9)
    }
}

/// Rows of a Parquet file from its footer (checked before it is parsed: a damaged footer
/// is what verify looks for).
fn parquet_rows(store: &Store, rel: &str) -> Option<u64> {
    let f = store.chunks(rel).ok()?;
    let b = nrw_dataset::parquet_io::reader_builder(f, &store.name(rel)).ok()?;
    Some(b.metadata().file_metadata().num_rows() as u64)
}

/// Every payload of a shard or descriptor part against its CRC-32 (other files have none).
fn payload_check(rel: &str, name: &str, data: bytes::Bytes) -> Vec<Mismatch> {
    let hex = |c: Option<u32>| c.map_or("none".into(), |c| format!("crc32 {c:08x}"));
    match nrw_dataset::checks::check_payloads(rel, &std::path::Path::new(name).into(), data) {
        Ok(found) => found
            .into_iter()
            .map(|m| Mismatch {
                file: name.into(),
                field: format!("{} at row {} (image {})", m.column, m.row, m.image_id),
                expected: hex(m.stored),
                found: hex(m.computed),
            })
            .collect(),
        Err(e) => vec![Mismatch {
            file: name.into(),
            field: "parquet".into(),
            expected: "a readable Parquet file".into(),
            found: e.to_string(),
        }],
    }
}

/// Check every listed file (in parallel, one file per task) and list the unlisted ones.
pub fn verify(store: &Store, progress: &dyn Progress) -> Result<VerifyReport> {
    use rayon::prelude::*;
    let t0 = Instant::now();
    let manifest = Manifest::read(store)?;
    progress.start("verify", manifest.tables.len() as u64, "files");
    let checked: Vec<(u64, Vec<Mismatch>)> = manifest
        .tables
        .par_iter()
        .map(|t| {
            let name = store.name(&t.path).to_string();
            let miss = |field: &str, expected: String, found: String| Mismatch {
                file: name.clone(),
                field: field.into(),
                expected,
                found,
            };
            let mut out = Vec::new();
            let bytes = match store.read_opt(&t.path) {
                Err(e) => {
                    out.push(miss("missing", "a readable file".into(), e.to_string()));
                    0
                }
                Ok(None) => {
                    out.push(miss(
                        "missing",
                        format!("{} bytes", t.bytes),
                        "no file".into(),
                    ));
                    0
                }
                Ok(Some(data)) => {
                    let found = nrw_dataset::FileEntry::of_bytes(&t.path, &data);
                    if found.bytes != t.bytes {
                        out.push(miss("size", t.bytes.to_string(), found.bytes.to_string()));
                    } else if found.sha256 != t.sha256 {
                        out.push(miss("sha256", t.sha256.clone(), found.sha256));
                    } else if let Some(rows) = t.rows {
                        match parquet_rows(store, &t.path) {
                            Some(r) if r == rows => {}
                            r => out.push(miss(
                                "rows",
                                rows.to_string(),
                                r.map_or("unreadable footer".into(), |r| r.to_string()),
                            )),
                        }
                    }
                    out.extend(payload_check(&t.path, &name, data.clone()));
                    data.len() as u64
                }
            };
            progress.inc(1);
            (bytes, out)
        })
        .collect();
    progress.finish();
    let listed: std::collections::BTreeSet<&str> = manifest
        .tables
        .iter()
        .map(|t| t.path.as_str())
        .chain([Manifest::FILE, nrw_dataset::timings::TIMINGS_FILE])
        .collect();
    let unlisted = store
        .list("")?
        .into_iter()
        .filter(|rel| {
            !listed.contains(rel.as_str())
                && !rel.starts_with(&format!("{}/", nrw_dataset::QA_DIR))
                && !rel.starts_with(&format!("{}/", nrw_dataset::EXPORT_DIR))
        })
        .collect();
    Ok(VerifyReport {
        dataset: store.root().to_string(),
        files: manifest.tables.len(),
        bytes: checked.iter().map(|c| c.0).sum(),
        mismatches: checked.into_iter().flat_map(|c| c.1).collect(),
        unlisted,
        seconds: t0.elapsed().as_secs_f64(),
    })
}
