//! Random access to a dataset file for the Parquet reader: the file itself locally, ranged
//! GETs through a read-ahead window on object storage.

use std::sync::Arc;

use bytes::Bytes;

use super::remote::Remote;

/// A file opened for random access (see [`super::Store::chunks`]).
pub enum Chunks {
    File(std::fs::File),
    Remote(Arc<RemoteFile>),
}

/// An object read by ranges through a read-ahead window: the Parquet reader asks for page
/// headers and column chunks in many small reads, and one GET per window serves them.
pub struct RemoteFile {
    pub(super) remote: Remote,
    pub(super) key: object_store::path::Path,
    pub(super) size: u64,
    pub(super) window: std::sync::Mutex<Option<(u64, Bytes)>>,
}

/// Bytes fetched ahead of a read (a row group's column chunks are contiguous).
const READ_AHEAD: u64 = 8 << 20;
/// Bytes fetched at the end of a file when any of them is read (the Parquet footer).
const TAIL: u64 = 64 << 10;

impl RemoteFile {
    /// `len` bytes from `start` (fewer at the end), from the window or one GET that refills it.
    fn bytes(&self, start: u64, len: u64) -> std::io::Result<Bytes> {
        let end = (start + len).min(self.size);
        if start >= end {
            return Ok(Bytes::new());
        }
        let mut window = self.window.lock().expect("window lock");
        if let Some((at, b)) = window.as_ref() {
            if *at <= start && end <= *at + b.len() as u64 {
                return Ok(b.slice((start - at) as usize..(end - at) as usize));
            }
        }
        let (from, to) = if end + TAIL >= self.size {
            (start.min(self.size.saturating_sub(TAIL)), self.size)
        } else {
            (start, (start + len.max(READ_AHEAD)).min(self.size))
        };
        let b = self.remote.get_range(&self.key, from..to)?;
        *window = Some((from, b.clone()));
        Ok(b.slice((start - from) as usize..(end - from) as usize))
    }
}

/// A reader from an offset of a remote file, fetching through its window as it goes.
pub struct RemoteRead {
    file: Arc<RemoteFile>,
    pos: u64,
}

impl std::io::Read for RemoteRead {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let b = self.file.bytes(self.pos, buf.len() as u64)?;
        buf[..b.len()].copy_from_slice(&b);
        self.pos += b.len() as u64;
        Ok(b.len())
    }
}

impl parquet::file::reader::Length for Chunks {
    fn len(&self) -> u64 {
        match self {
            Chunks::File(f) => parquet::file::reader::Length::len(f),
            Chunks::Remote(r) => r.size,
        }
    }
}

impl parquet::file::reader::ChunkReader for Chunks {
    type T = Box<dyn std::io::Read + Send>;

    fn get_read(&self, start: u64) -> parquet::errors::Result<Self::T> {
        match self {
            Chunks::File(f) => Ok(Box::new(f.get_read(start)?)),
            Chunks::Remote(r) => Ok(Box::new(RemoteRead {
                file: r.clone(),
                pos: start,
            })),
        }
    }

    fn get_bytes(&self, start: u64, length: usize) -> parquet::errors::Result<Bytes> {
        match self {
            Chunks::File(f) => f.get_bytes(start, length),
            Chunks::Remote(r) => {
                let b = r
                    .bytes(start, length as u64)
                    .map_err(|e| parquet::errors::ParquetError::External(Box::new(e)))?;
                if b.len() < length {
                    return Err(parquet::errors::ParquetError::EOF(format!(
                        "{}: {length} bytes at {start} run past the end ({} bytes)",
                        r.remote.url, r.size
                    )));
                }
                Ok(b)
            }
        }
    }
}
