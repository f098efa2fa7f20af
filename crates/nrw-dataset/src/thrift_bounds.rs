//! Bounds checks of a Parquet file's Thrift headers before the parquet crate parses them. It
//! allocates what they claim before it reads the items — a schema node's `num_children` and
//! list lengths in the footer; a page's uncompressed size and a dictionary's value count in
//! page headers — so a damaged file could ask for gigabytes (fuzzing found all four). These
//! walks read no values: every count must fit in the bytes that remain, every page in its
//! column chunk, and a page's claims within [`MAX_PAGE_BYTES`] and its own size.

use crate::location::Location;

use crate::error::{DatasetError, Result};

/// Deepest nesting of Thrift structs and lists accepted (Parquet's own footers nest a few
/// levels; a damaged one could recurse without end).
const MAX_DEPTH: usize = 64;

struct Walk<'a> {
    b: &'a [u8],
    at: usize,
}

type Check<T> = std::result::Result<T, String>;

impl Walk<'_> {
    fn byte(&mut self) -> Check<u8> {
        let v = *self.b.get(self.at).ok_or("ends inside a value")?;
        self.at += 1;
        Ok(v)
    }

    fn varint(&mut self) -> Check<u64> {
        let mut v = 0u64;
        for shift in (0..64).step_by(7) {
            let b = self.byte()?;
            v |= u64::from(b & 0x7f) << shift;
            if b & 0x80 == 0 {
                return Ok(v);
            }
        }
        Err("a varint longer than 10 bytes".into())
    }

    fn zigzag(&mut self) -> Check<i64> {
        let v = self.varint()?;
        Ok((v >> 1) as i64 ^ -((v & 1) as i64))
    }

    /// A count of items each at least `min_bytes` long, checked against what remains.
    fn count(&mut self, n: u64, min_bytes: u64, what: &str) -> Check<usize> {
        let left = (self.b.len() - self.at) as u64;
        if n.saturating_mul(min_bytes) > left {
            return Err(format!("a {what} of {n} items in {left} remaining bytes"));
        }
        Ok(n as usize)
    }

    fn skip(&mut self, n: usize) -> Check<()> {
        if self.b.len() - self.at < n {
            return Err(format!(
                "a {n}-byte value in {} remaining bytes",
                self.b.len() - self.at
            ));
        }
        self.at += n;
        Ok(())
    }

    /// Skip one value of compact type `t`.
    fn value(&mut self, t: u8, depth: usize) -> Check<()> {
        if depth > MAX_DEPTH {
            return Err("nested deeper than 64 levels".into());
        }
        match t {
            1 | 2 => Ok(()), // bool in a field header
            3 => self.skip(1),
            4..=6 => self.varint().map(|_| ()),
            7 => self.skip(8),
            8 => {
                let n = self.varint()?;
                let n = self.count(n, 1, "string")?;
                self.skip(n)
            }
            9 | 10 => self.list(depth).map(|_| ()),
            11 => {
                let n = self.varint()?;
                if n == 0 {
                    return Ok(());
                }
                let kv = self.byte()?;
                let n = self.count(n, 2, "map")?;
                for _ in 0..n {
                    self.value(kv >> 4, depth + 1)?;
                    self.value(kv & 0x0f, depth + 1)?;
                }
                Ok(())
            }
            12 => self.fields(depth + 1, |_, _, _| Ok(false)),
            t => Err(format!("unknown Thrift type {t}")),
        }
    }

    /// A list's header and items; returns (item type, length) after skipping its items.
    fn list(&mut self, depth: usize) -> Check<(u8, usize)> {
        let h = self.byte()?;
        let n = match h >> 4 {
            15 => self.varint()?,
            n => u64::from(n),
        };
        let t = h & 0x0f;
        let n = self.count(n, 1, "list")?;
        for _ in 0..n {
            // Booleans in lists are a byte each.
            if t == 1 || t == 2 {
                self.skip(1)?;
            } else {
                self.value(t, depth + 1)?;
            }
        }
        Ok((t, n))
    }

    /// A struct's fields up to its stop byte; `on(id, type, walk)` may consume a field
    /// itself (returning true) or leave it to be skipped.
    fn fields(
        &mut self,
        depth: usize,
        mut on: impl FnMut(i16, u8, &mut Self) -> Check<bool>,
    ) -> Check<()> {
        let mut id: i16 = 0;
        loop {
            let h = self.byte()?;
            if h == 0 {
                return Ok(());
            }
            let t = h & 0x0f;
            id = match h >> 4 {
                0 => i16::try_from(self.zigzag()?).map_err(|_| "a field id beyond i16")?,
                d => id.wrapping_add(i16::from(d)),
            };
            if !on(id, t, self)? {
                self.value(t, depth)?;
            }
        }
    }
}

/// Largest page accepted, uncompressed (ours hold at most a row group's payloads, a few tens
/// of MB).
pub const MAX_PAGE_BYTES: i64 = 256 << 20;

/// Check every page header of one column chunk's bytes: sizes non-negative, each page inside
/// the chunk, its uncompressed size within [`MAX_PAGE_BYTES`], and a dictionary's value count
/// within what its uncompressed bytes can hold at `min_value_bytes` per value.
pub fn check_pages(chunk: &[u8], min_value_bytes: i64) -> std::result::Result<(), String> {
    let mut at = 0;
    let mut page = 0;
    while at < chunk.len() {
        let mut w = Walk { b: chunk, at };
        let (mut uncompressed, mut compressed, mut dictionary) = (-1i64, -1i64, None);
        w.fields(0, |id, t, w| match (id, t) {
            (2, 5) => {
                uncompressed = w.zigzag()?;
                Ok(true)
            }
            (3, 5) => {
                compressed = w.zigzag()?;
                Ok(true)
            }
            (7, 12) => {
                w.fields(1, |id, t, w| {
                    if id == 1 && t == 5 {
                        dictionary = Some(w.zigzag()?);
                        return Ok(true);
                    }
                    Ok(false)
                })?;
                Ok(true)
            }
            _ => Ok(false),
        })
        .map_err(|e| format!("page {page}: {e}"))?;
        if !(0..=MAX_PAGE_BYTES).contains(&uncompressed) || compressed < 0 {
            return Err(format!(
                "page {page} claims {uncompressed} bytes ({compressed} compressed); at most {MAX_PAGE_BYTES} are accepted"
            ));
        }
        if let Some(n) = dictionary {
            if n < 0 || n.saturating_mul(min_value_bytes) > uncompressed {
                return Err(format!(
                    "page {page}: a dictionary of {n} values in {uncompressed} bytes"
                ));
            }
        }
        let end = w.at.saturating_add(compressed as usize);
        if end > chunk.len() {
            return Err(format!(
                "page {page} ends at byte {end} of a {}-byte column chunk",
                chunk.len()
            ));
        }
        at = end;
        page += 1;
    }
    Ok(())
}

/// Check the footer (FileMetaData) of a Parquet file's last bytes: `footer` is the Thrift
/// metadata, without the length and magic that follow it.
pub fn check_footer(footer: &[u8], path: &Location) -> Result<()> {
    walk_file_metadata(footer).map_err(|problem| DatasetError::Schema {
        path: path.into(),
        problem: format!("damaged Parquet footer: {problem}"),
    })
}

fn walk_file_metadata(footer: &[u8]) -> Check<()> {
    let mut w = Walk { b: footer, at: 0 };
    let mut children: Vec<i64> = Vec::new();
    w.fields(0, |id, t, w| {
        if id != 2 || t != 9 {
            return Ok(false);
        }
        // FileMetaData.schema: a list of SchemaElement structs; field 5 is num_children.
        let h = w.byte()?;
        let n = match h >> 4 {
            15 => w.varint()?,
            n => u64::from(n),
        };
        if h & 0x0f != 12 {
            return Err("the schema is not a list of structs".into());
        }
        let n = w.count(n, 1, "schema")?;
        for _ in 0..n {
            let mut kids = 0;
            w.fields(1, |id, t, w| {
                if id == 5 && t == 5 {
                    kids = w.zigzag()?;
                    return Ok(true);
                }
                Ok(false)
            })?;
            children.push(kids);
        }
        Ok(true)
    })?;
    // The schema is a tree in depth-first order: every node's children come after it.
    let mut open: i64 = 1;
    for (i, &k) in children.iter().enumerate() {
        if !(0..=children.len() as i64).contains(&k) {
            return Err(format!("schema node {i} claims {k} children"));
        }
        open = open - 1 + k;
        if open < 0 || open > (children.len() - i - 1) as i64 {
            return Err(format!(
                "schema node {i}'s children do not fit in the {} nodes listed",
                children.len()
            ));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn footer(file: &[u8]) -> &[u8] {
        let n = file.len();
        let len = u32::from_le_bytes(file[n - 8..n - 4].try_into().unwrap()) as usize;
        &file[n - 8 - len..n - 8]
    }

    fn a_table() -> Vec<u8> {
        use arrow_array::{Int32Array, ListArray, RecordBatch, StringArray};
        let list = ListArray::from_iter_primitive::<arrow_array::types::Float64Type, _, _>(vec![
            Some(vec![Some(1.0), Some(2.0)]),
            Some(vec![]),
        ]);
        let b = RecordBatch::try_from_iter([
            (
                "a",
                std::sync::Arc::new(Int32Array::from(vec![1, 2])) as arrow_array::ArrayRef,
            ),
            (
                "b",
                std::sync::Arc::new(StringArray::from(vec!["x", "y"])) as _,
            ),
            ("c", std::sync::Arc::new(list) as _),
        ])
        .unwrap();
        crate::parquet_io::encode_batch(
            &crate::Location::parse("t"),
            &b,
            crate::parquet_io::writer_properties(8),
        )
        .unwrap()
    }

    #[test]
    fn a_written_footer_passes_and_a_lying_count_is_caught() {
        let file = a_table();
        let f = footer(&file);
        walk_file_metadata(f).unwrap();
        // Every single-byte change either passes (a value, not a count) or is refused:
        // none panics or asks for more than the footer holds.
        let mut refused = 0;
        for i in 0..f.len() {
            for v in [0x00, 0x0f, 0x7f, 0xff] {
                let mut g = f.to_vec();
                g[i] = v;
                refused += usize::from(walk_file_metadata(&g).is_err());
            }
        }
        assert!(refused > 0);
        // A schema root that claims 2^30 children.
        assert!(
            walk_file_metadata(&[0x29, 0x1c, 0x55, 0x80, 0x80, 0x80, 0x80, 0x08, 0x00, 0x00])
                .unwrap_err()
                .contains("children")
        );
    }
}
