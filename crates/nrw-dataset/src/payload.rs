//! Payload checksums: every PNG, EXR or descriptor stored in a table carries a CRC-32 written
//! with it, and every reader checks it before use. Shared by the view shards and the
//! descriptor parts.

use crate::location::Location;
use arrow_array::{RecordBatch, UInt32Array};

use crate::error::{DatasetError, Result};

/// The checksum column of a payload column.
pub fn crc_column(payload: &str) -> String {
    format!("{payload}_crc32")
}

/// A payload's checksum: CRC-32 (IEEE 802.3, as Python's `zlib.crc32`). It catches every
/// burst of up to 32 flipped bits, and any other change but one in 2^32, at memory speed.
pub fn crc32(bytes: &[u8]) -> u32 {
    crc32fast::hash(bytes)
}

/// A payload whose bytes no longer match the checksum written with them.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize)]
pub struct PayloadMismatch {
    /// Row inside the file (0-based).
    pub row: usize,
    pub image_id: u32,
    pub column: String,
    /// `None` when the payload and its checksum disagree on being present.
    pub stored: Option<u32>,
    pub computed: Option<u32>,
}

impl PayloadMismatch {
    /// The mismatch as the error every reader returns.
    pub fn error(&self, path: &Location) -> DatasetError {
        let hex = |c: Option<u32>| c.map_or("none".to_string(), |c| format!("{c:08x}"));
        DatasetError::Value {
            path: path.into(),
            record: format!("row {} (image {})", self.row, self.image_id),
            field: self.column.clone(),
            problem: format!(
                "CRC-32 of the bytes is {} but {} was written with them: the file changed after it was written (damaged on disk or in a copy); `nrw-etl verify` lists every damaged payload, and re-running the stage that wrote the file replaces it",
                hex(self.computed),
                hex(self.stored)
            ),
        }
    }
}

/// Check one payload column of a batch against its checksum column; `rows[i]` is batch row
/// i's row in the file. Columns absent from the batch (not read) are not checked.
pub fn payload_mismatches(
    b: &RecordBatch,
    rows: &[usize],
    column: &str,
    path: &Location,
) -> Result<Vec<PayloadMismatch>> {
    use arrow_array::{Array, BinaryArray};
    if b.column_by_name(column).is_none() {
        return Ok(Vec::new());
    }
    let data = crate::parquet_io::column::<BinaryArray>(b, column, path)?;
    let crcs = crate::parquet_io::column::<UInt32Array>(b, &crc_column(column), path)?;
    let ids = crate::parquet_io::column::<UInt32Array>(b, "image_id", path)?;
    let mut out = Vec::new();
    for i in 0..b.num_rows() {
        let computed = (!data.is_null(i)).then(|| crc32(data.value(i)));
        let stored = (!crcs.is_null(i)).then(|| crcs.value(i));
        if computed != stored {
            out.push(PayloadMismatch {
                row: rows.get(i).copied().unwrap_or(i),
                image_id: ids.value(i),
                column: column.into(),
                stored,
                computed,
            });
        }
    }
    Ok(out)
}
