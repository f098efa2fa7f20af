//! Parquet writing and reading with the dataset's settings (zstd, deterministic bytes),
//! through the dataset's [`Store`].

use crate::location::Location;

use arrow_array::RecordBatch;
use parquet::arrow::ArrowWriter;
use parquet::basic::{Compression, ZstdLevel};
use parquet::file::properties::WriterProperties;

use crate::error::{DatasetError, Result};
use crate::manifest::FileEntry;
use crate::store::Store;

/// Writer settings shared by every table: zstd level 3, statistics on, no timestamps.
pub fn writer_properties(max_row_group_rows: usize) -> WriterProperties {
    writer_properties_builder(max_row_group_rows).build()
}

/// [`writer_properties`] before `build`, for tables that set some columns apart.
pub fn writer_properties_builder(
    max_row_group_rows: usize,
) -> parquet::file::properties::WriterPropertiesBuilder {
    WriterProperties::builder()
        .set_compression(Compression::ZSTD(
            ZstdLevel::try_new(3).expect("valid zstd level"),
        ))
        .set_max_row_group_row_count(Some(max_row_group_rows.max(1)))
        .set_created_by(format!("nrw-etl {}", env!("CARGO_PKG_VERSION")))
}

/// Encode one batch as Parquet bytes with `props`.
pub fn encode_batch(
    name: &Location,
    batch: &RecordBatch,
    props: WriterProperties,
) -> Result<Vec<u8>> {
    let perr = |e| DatasetError::Parquet {
        path: name.into(),
        source: e,
    };
    let mut out = Vec::new();
    let mut w = ArrowWriter::try_new(&mut out, batch.schema(), Some(props)).map_err(perr)?;
    w.write(batch).map_err(perr)?;
    w.close().map_err(perr)?;
    Ok(out)
}

/// Write one batch as the Parquet file `rel` of the dataset with `props`, atomically, and
/// describe it for the manifest.
pub fn write_batch(
    store: &Store,
    rel: &str,
    batch: &RecordBatch,
    props: WriterProperties,
) -> Result<FileEntry> {
    let bytes = encode_batch(&store.name(rel), batch, props)?;
    let mut entry = FileEntry::of_bytes(rel, &bytes);
    entry.rows = Some(batch.num_rows() as u64);
    store.write(rel, bytes)?;
    Ok(entry)
}

/// Write one batch as a table with the dataset's default settings.
pub fn write_table(store: &Store, rel: &str, batch: &RecordBatch) -> Result<FileEntry> {
    write_batch(store, rel, batch, writer_properties(65_536))
}

/// Every batch of a dataset's Parquet file, optionally only some columns.
pub fn read_batches(
    store: &Store,
    rel: &str,
    columns: Option<&[&str]>,
) -> Result<Vec<RecordBatch>> {
    batches(store, rel, columns, 1024)?.collect()
}

/// The batches of a dataset's Parquet file one at a time (`batch_rows` rows each at most),
/// optionally only some columns: memory stays at one batch whatever the file's size.
pub fn batches(
    store: &Store,
    rel: &str,
    columns: Option<&[&str]>,
    batch_rows: usize,
) -> Result<impl Iterator<Item = Result<RecordBatch>>> {
    batches_from(store.chunks(rel)?, store.name(rel), columns, batch_rows)
}

/// [`batches`] of Parquet bytes already at hand (`path` names them in errors).
pub fn batches_from<R: parquet::file::reader::ChunkReader + 'static>(
    f: R,
    path: Location,
    columns: Option<&[&str]>,
    batch_rows: usize,
) -> Result<impl Iterator<Item = Result<RecordBatch>>> {
    let perr = |e| DatasetError::Parquet {
        path: path.clone(),
        source: e,
    };
    let mut b = checked_builder(f, &path, None, columns)?;
    if let Some(cols) = columns {
        let mask =
            parquet::arrow::ProjectionMask::columns(b.parquet_schema(), cols.iter().copied());
        b = b.with_projection(mask);
    }
    let reader = b.with_batch_size(batch_rows.max(1)).build().map_err(perr)?;
    Ok(guarded(reader, &path))
}

/// A built reader's batches as results: the parquet crate's errors, and its panics on
/// damaged pages (see [`crate::panic_guard`]), both become errors naming `path`; iteration
/// stops at the first.
pub fn guarded(
    mut reader: parquet::arrow::arrow_reader::ParquetRecordBatchReader,
    path: &Location,
) -> impl Iterator<Item = Result<RecordBatch>> {
    let path = path.clone();
    let mut failed = false;
    std::iter::from_fn(move || {
        if failed {
            return None;
        }
        let next = match crate::panic_guard::contained(|| reader.next()) {
            Ok(None) => return None,
            Ok(Some(Ok(b))) => return Some(Ok(b)),
            Ok(Some(Err(e))) => DatasetError::Arrow {
                table: path.to_string(),
                source: e,
            },
            Err(panic) => DatasetError::Schema {
                path: path.clone(),
                problem: format!("damaged Parquet data (the parquet crate failed: {panic})"),
            },
        };
        failed = true;
        Some(Err(next))
    })
}

/// The page headers of the column chunks about to be read, checked ([`crate::thrift_bounds::check_pages`])
/// before the parquet crate allocates what they claim: row groups `groups` (all when `None`)
/// and the top-level columns `columns` (all when `None`). Costs one more read of those
/// chunks' bytes (from memory or the page cache; on object storage, the read-ahead).
pub fn check_pages<R: parquet::file::reader::ChunkReader>(
    f: &R,
    meta: &parquet::file::metadata::ParquetMetaData,
    groups: Option<&[usize]>,
    columns: Option<&[&str]>,
    path: &Location,
) -> Result<()> {
    use parquet::basic::Type as Physical;
    for (g, rg) in meta.row_groups().iter().enumerate() {
        if groups.is_some_and(|gs| !gs.contains(&g)) {
            continue;
        }
        for c in rg.columns() {
            let top = c.column_path().parts().first().map(String::as_str);
            if columns.is_some_and(|cols| !top.is_some_and(|t| cols.contains(&t))) {
                continue;
            }
            let (start, len) = c.byte_range(); // in the file: reader_builder checked it
            let bytes = f
                .get_bytes(start, len as usize)
                .map_err(|e| DatasetError::Parquet {
                    path: path.into(),
                    source: e,
                })?;
            let min_value_bytes = match c.column_type() {
                Physical::BOOLEAN => 0,
                Physical::INT32 | Physical::FLOAT | Physical::BYTE_ARRAY => 4,
                Physical::INT64 | Physical::DOUBLE => 8,
                Physical::INT96 => 12,
                Physical::FIXED_LEN_BYTE_ARRAY => 1,
            };
            crate::thrift_bounds::check_pages(&bytes, min_value_bytes).map_err(|problem| {
                DatasetError::Schema {
                    path: path.into(),
                    problem: format!(
                        "damaged Parquet page: row group {g}, column `{}`: {problem}",
                        c.column_path()
                    ),
                }
            })?;
        }
    }
    Ok(())
}

/// The footer's counts checked against its bytes ([`crate::thrift_bounds`]) before the parquet
/// crate allocates what they claim. Files too short for a footer are left to the parquet
/// crate's own error.
fn check_footer_of<R: parquet::file::reader::ChunkReader>(
    f: &R,
    len: u64,
    path: &Location,
) -> Result<()> {
    let io = |e: parquet::errors::ParquetError| DatasetError::Parquet {
        path: path.into(),
        source: e,
    };
    if len < 12 {
        return Ok(());
    }
    let tail = f.get_bytes(len - 8, 8).map_err(io)?;
    let meta = u64::from(u32::from_le_bytes([tail[0], tail[1], tail[2], tail[3]]));
    if &tail[4..] != b"PAR1" || meta + 8 > len {
        return Ok(());
    }
    let footer = f.get_bytes(len - 8 - meta, meta as usize).map_err(io)?;
    crate::thrift_bounds::check_footer(&footer, path)
}

/// A Parquet reader over `f` whose footer has been checked for what the parquet crate
/// asserts instead of checking (a column chunk at a negative offset or of negative length
/// panics deep in the reader): such a file is an error naming `path`.
pub fn reader_builder<R: parquet::file::reader::ChunkReader + 'static>(
    f: R,
    path: &Location,
) -> Result<parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder<R>> {
    checked_builder(f, path, Some(&[]), None)
}

/// [`reader_builder`] that also checks the page headers of the row groups `groups` (all when
/// `None`) in the top-level columns `columns` (all when `None`): what a reader about to
/// decode them uses.
pub fn checked_builder<R: parquet::file::reader::ChunkReader + 'static>(
    f: R,
    path: &Location,
    groups: Option<&[usize]>,
    columns: Option<&[&str]>,
) -> Result<parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder<R>> {
    let meta = checked_metadata(&f, path)?;
    check_pages(&f, &meta, groups, columns, path)?;
    builder_with(f, meta, path)
}

/// [`checked_builder`] for reading the row groups `groups` whole: their bytes are fetched
/// once, in one read (one request on object storage), and both the page-header check and the
/// decoder read them from memory.
pub fn prefetched_builder<R: parquet::file::reader::ChunkReader + 'static>(
    f: R,
    path: &Location,
    groups: &[usize],
) -> Result<parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder<Prefetched<R>>> {
    let meta = checked_metadata(&f, path)?;
    let span = meta
        .row_groups()
        .iter()
        .enumerate()
        .filter(|(g, _)| groups.contains(g))
        .flat_map(|(_, rg)| rg.columns().iter().map(|c| c.byte_range()))
        .fold(None, |s: Option<(u64, u64)>, (a, n)| {
            Some(s.map_or((a, a + n), |(lo, hi)| (lo.min(a), hi.max(a + n))))
        });
    let bytes = match span {
        Some((lo, hi)) => {
            f.get_bytes(lo, (hi - lo) as usize)
                .map_err(|e| DatasetError::Parquet {
                    path: path.into(),
                    source: e,
                })?
        }
        None => bytes::Bytes::new(),
    };
    let f = Prefetched {
        inner: f,
        start: span.map_or(0, |s| s.0),
        bytes,
    };
    check_pages(&f, &meta, Some(groups), None, path)?;
    builder_with(f, meta, path)
}

/// A file with one span of it held in memory: reads inside the span come from memory, others
/// from the file.
pub struct Prefetched<R> {
    inner: R,
    start: u64,
    bytes: bytes::Bytes,
}

impl<R: parquet::file::reader::Length> parquet::file::reader::Length for Prefetched<R> {
    fn len(&self) -> u64 {
        self.inner.len()
    }
}

/// A reader over a [`Prefetched`] span, or over the file outside it.
pub enum SpanRead<F> {
    Memory(bytes::buf::Reader<bytes::Bytes>),
    File(F),
}

impl<F: std::io::Read> std::io::Read for SpanRead<F> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        match self {
            SpanRead::Memory(m) => m.read(buf),
            SpanRead::File(f) => f.read(buf),
        }
    }
}

impl<R: parquet::file::reader::ChunkReader> parquet::file::reader::ChunkReader for Prefetched<R> {
    type T = SpanRead<R::T>;

    fn get_read(&self, start: u64) -> parquet::errors::Result<Self::T> {
        use bytes::Buf;
        let end = self.start + self.bytes.len() as u64;
        if (self.start..end).contains(&start) {
            let at = (start - self.start) as usize;
            return Ok(SpanRead::Memory(self.bytes.slice(at..).reader()));
        }
        self.inner.get_read(start).map(SpanRead::File)
    }

    fn get_bytes(&self, start: u64, length: usize) -> parquet::errors::Result<bytes::Bytes> {
        let end = start.saturating_add(length as u64);
        if start >= self.start && end <= self.start + self.bytes.len() as u64 {
            let at = (start - self.start) as usize;
            return Ok(self.bytes.slice(at..at + length));
        }
        self.inner.get_bytes(start, length)
    }
}

/// The footer of `f`, checked ([`check_footer_of`]) and parsed, with every column chunk
/// inside the file.
fn checked_metadata<R: parquet::file::reader::ChunkReader>(
    f: &R,
    path: &Location,
) -> Result<parquet::file::metadata::ParquetMetaData> {
    let len = f.len();
    check_footer_of(f, len, path)?;
    let meta = parquet::file::metadata::ParquetMetaDataReader::new()
        .parse_and_finish(f)
        .map_err(|e| DatasetError::Parquet {
            path: path.into(),
            source: e,
        })?;
    for (g, rg) in meta.row_groups().iter().enumerate() {
        for c in rg.columns() {
            let start = c.dictionary_page_offset().unwrap_or(c.data_page_offset());
            let size = c.compressed_size();
            let fits = start >= 0
                && size >= 0
                && (start as u64)
                    .checked_add(size as u64)
                    .is_some_and(|end| end <= len);
            if !fits {
                return Err(DatasetError::Schema {
                    path: path.into(),
                    problem: format!(
                        "damaged Parquet footer: row group {g}, column `{}` claims bytes {start}..+{size} of a {len}-byte file",
                        c.column_path()
                    ),
                });
            }
        }
    }
    Ok(meta)
}

/// A reader builder over `f` with its already checked metadata.
fn builder_with<R: parquet::file::reader::ChunkReader + 'static>(
    f: R,
    meta: parquet::file::metadata::ParquetMetaData,
    path: &Location,
) -> Result<parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder<R>> {
    use parquet::arrow::arrow_reader::{
        ArrowReaderMetadata, ArrowReaderOptions, ParquetRecordBatchReaderBuilder,
    };
    let meta =
        ArrowReaderMetadata::try_new(std::sync::Arc::new(meta), ArrowReaderOptions::default())
            .map_err(|e| DatasetError::Parquet {
                path: path.into(),
                source: e,
            })?;
    Ok(ParquetRecordBatchReaderBuilder::new_with_metadata(f, meta))
}

/// A column of a batch as its concrete Arrow type, or an error naming file and column.
pub fn column<'a, T: 'static>(b: &'a RecordBatch, name: &str, path: &Location) -> Result<&'a T> {
    b.column_by_name(name)
        .and_then(|c| c.as_any().downcast_ref::<T>())
        .ok_or_else(|| DatasetError::Schema {
            path: path.into(),
            problem: format!("column `{name}` is missing or of another type"),
        })
}
