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

/// Write one batch as a Parquet file at `dir/rel` with `props`, atomically, and describe it
/// for the manifest.
pub fn write_batch(
    dir: &Path,
    rel: &str,
    batch: &RecordBatch,
    props: WriterProperties,
) -> Result<FileEntry> {
    let path = dir.join(rel);
    let perr = |e| DatasetError::Parquet {
        path: path.clone(),
        source: e,
    };
    write_atomic(&path, |f| {
        let mut w = ArrowWriter::try_new(f, batch.schema(), Some(props)).map_err(perr)?;
        w.write(batch).map_err(perr)?;
        w.close().map_err(perr)?;
        Ok(())
    })?;
    let mut entry = FileEntry::of(dir, rel)?;
    entry.rows = Some(batch.num_rows() as u64);
    Ok(entry)
}

/// Write one batch as a table with the dataset's default settings.
pub fn write_table(dir: &Path, rel: &str, batch: &RecordBatch) -> Result<FileEntry> {
    write_batch(dir, rel, batch, writer_properties(65_536))
}

/// Every batch of a Parquet file, optionally only some columns.
pub fn read_batches(path: &Path, columns: Option<&[&str]>) -> Result<Vec<RecordBatch>> {
    use parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder;
    let f = std::fs::File::open(path).map_err(|e| DatasetError::io(path, e))?;
    let perr = |e| DatasetError::Parquet {
        path: path.to_path_buf(),
        source: e,
    };
    let mut b = ParquetRecordBatchReaderBuilder::try_new(f).map_err(perr)?;
    if let Some(cols) = columns {
        let mask =
            parquet::arrow::ProjectionMask::columns(b.parquet_schema(), cols.iter().copied());
        b = b.with_projection(mask);
    }
    let name = path.display().to_string();
    b.build()
        .map_err(perr)?
        .map(|r| {
            r.map_err(|e| DatasetError::Arrow {
                table: name.clone(),
                source: e,
            })
        })
        .collect()
}

/// A column of a batch as its concrete Arrow type, or an error naming file and column.
pub fn column<'a, T: 'static>(b: &'a RecordBatch, name: &str, path: &Path) -> Result<&'a T> {
    b.column_by_name(name)
        .and_then(|c| c.as_any().downcast_ref::<T>())
        .ok_or_else(|| DatasetError::Schema {
            path: path.to_path_buf(),
            problem: format!("column `{name}` is missing or of another type"),
        })
}
