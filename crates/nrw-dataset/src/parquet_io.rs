//! Parquet writing with the dataset's settings (zstd, deterministic bytes, atomic rename).

use std::path::Path;

use arrow_array::RecordBatch;
use parquet::arrow::ArrowWriter;
use parquet::basic::{Compression, ZstdLevel};
use parquet::file::properties::WriterProperties;

use crate::atomic::write_atomic;
use crate::error::{DatasetError, Result};
use crate::manifest::FileEntry;

/// Writer settings shared by every table: zstd level 3, statistics on, no timestamps.
pub fn writer_properties(max_row_group_rows: usize) -> WriterProperties {
    WriterProperties::builder()
        .set_compression(Compression::ZSTD(
            ZstdLevel::try_new(3).expect("valid zstd level"),
        ))
        .set_max_row_group_row_count(Some(max_row_group_rows.max(1)))
        .set_created_by(format!("nrw-etl {}", env!("CARGO_PKG_VERSION")))
        .build()
}

/// Write one batch as a Parquet file at `dir/rel`, atomically, and describe it for the manifest.
pub fn write_table(dir: &Path, rel: &str, batch: &RecordBatch) -> Result<FileEntry> {
    let path = dir.join(rel);
    write_atomic(&path, |f| {
        let mut w = ArrowWriter::try_new(f, batch.schema(), Some(writer_properties(65_536)))
            .map_err(|e| DatasetError::Parquet {
                path: path.clone(),
                source: e,
            })?;
        w.write(batch).map_err(|e| DatasetError::Parquet {
            path: path.clone(),
            source: e,
        })?;
        w.close().map_err(|e| DatasetError::Parquet {
            path: path.clone(),
            source: e,
        })?;
        Ok(())
    })?;
    let mut entry = FileEntry::of(dir, rel)?;
    entry.rows = Some(batch.num_rows() as u64);
    Ok(entry)
}
