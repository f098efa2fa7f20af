//! NumPy's `.npy` (format 1.0) and `.npz` (a zip of `.npy` members, stored, as `np.savez`
//! writes it) for the arrays exports carry: float64, int64, float32 and fixed-width unicode.

/// One array: its numpy `descr` as a Python literal (`'<f8'`, or a list of fields for a
/// structured array), shape and little-endian body.
pub struct Array {
    pub descr: String,
    pub shape: Vec<usize>,
    pub body: Vec<u8>,
}

impl Array {
    /// A float64 array of `shape` (row-major).
    pub fn f64(shape: &[usize], v: &[f64]) -> Array {
        Array::of(
            "<f8",
            shape,
            v.iter().flat_map(|x| x.to_le_bytes()).collect(),
        )
    }

    /// A float32 array of `shape` (row-major).
    pub fn f32(shape: &[usize], v: &[f32]) -> Array {
        Array::of(
            "<f4",
            shape,
            v.iter().flat_map(|x| x.to_le_bytes()).collect(),
        )
    }

    /// An int64 vector.
    pub fn i64(v: &[i64]) -> Array {
        Array::of(
            "<i8",
            &[v.len()],
            v.iter().flat_map(|x| x.to_le_bytes()).collect(),
        )
    }

    /// A vector of strings as numpy stores a list of `str`: `<U{longest}`, UTF-32, zero-padded.
    pub fn unicode(v: &[String]) -> Array {
        let width = v
            .iter()
            .map(|s| s.chars().count())
            .max()
            .unwrap_or(0)
            .max(1);
        let mut body = Vec::with_capacity(v.len() * width * 4);
        for s in v {
            let n = s.chars().count();
            body.extend(s.chars().flat_map(|c| (c as u32).to_le_bytes()));
            body.extend(std::iter::repeat_n(0u8, (width - n) * 4));
        }
        Array::of(&format!("<U{width}"), &[v.len()], body)
    }

    /// A 1-D structured array of `rows` records, each `fields` (name, descr) packed in order
    /// as `body` holds them.
    pub fn records(fields: &[(&str, &str)], rows: usize, body: Vec<u8>) -> Array {
        let list: Vec<String> = fields
            .iter()
            .map(|(n, d)| format!("('{n}', '{d}')"))
            .collect();
        Array {
            descr: format!("[{}]", list.join(", ")),
            shape: vec![rows],
            body,
        }
    }

    /// A 1-D object array whose `.npy` body is numpy's pickle of it.
    pub fn objects(rows: usize, pickle: Vec<u8>) -> Array {
        Array {
            descr: "'|O'".into(),
            shape: vec![rows],
            body: pickle,
        }
    }

    fn of(descr: &str, shape: &[usize], body: Vec<u8>) -> Array {
        Array {
            descr: format!("'{descr}'"),
            shape: shape.to_vec(),
            body,
        }
    }

    /// The `.npy` bytes.
    pub fn npy(&self) -> Vec<u8> {
        let mut out = npy_header(&self.descr, &self.shape);
        out.extend_from_slice(&self.body);
        out
    }
}

/// The `.npy` header (format 1.0, padded to 64 bytes) of an array of `descr` (a Python
/// literal) and `shape`, for a body written after it.
pub fn npy_header(descr: &str, shape: &[usize]) -> Vec<u8> {
    let dims: Vec<String> = shape.iter().map(|d| d.to_string()).collect();
    let shape = match dims.len() {
        1 => format!("({},)", dims[0]),
        _ => format!("({})", dims.join(", ")),
    };
    let dict = format!("{{'descr': {descr}, 'fortran_order': False, 'shape': {shape}, }}");
    // Magic (6) + version (2) + length (2) + dict + padding + '\n' ≡ 0 (mod 64).
    let pad = (64 - (10 + dict.len() + 1) % 64) % 64;
    let header = format!("{dict}{}\n", " ".repeat(pad));
    let mut out = Vec::with_capacity(10 + header.len());
    out.extend_from_slice(b"\x93NUMPY\x01\x00");
    out.extend_from_slice(&(header.len() as u16).to_le_bytes());
    out.extend_from_slice(header.as_bytes());
    out
}

/// An `.npz` of `members` (name without `.npy`, bytes of an `.npy`), stored uncompressed as
/// `np.savez` does (ZIP64 records where a member or the archive passes 4 GiB).
pub fn npz(members: &[(&str, Vec<u8>)]) -> Vec<u8> {
    let mut z = NpzWriter::new(std::io::Cursor::new(Vec::new()));
    for (name, data) in members {
        z.member(name, data).expect("writing to memory");
    }
    z.finish().expect("writing to memory").into_inner()
}

/// An `.npz` written member by member, a member's bytes streamed in pieces (its CRC patched
/// into its header after), so an array larger than memory can be written a row at a time.
pub struct NpzWriter<W: std::io::Write + std::io::Seek> {
    w: W,
    central: Vec<u8>,
    count: u64,
    offset: u64,
    zip64_from: u64,
}

/// Where a ZIP local header keeps its CRC-32.
const CRC_AT: u64 = 14;

/// The 32-bit field value that says "the value is in the ZIP64 extra field" (APPNOTE 4.4.8).
const IN_ZIP64: u32 = u32::MAX;

/// The version a reader needs: 2.0, or 4.5 for ZIP64 records (APPNOTE 4.4.3).
fn version(zip64: bool) -> u16 {
    if zip64 {
        45
    } else {
        20
    }
}

/// A ZIP64 extended-information extra field (tag 0x0001) holding `values` (APPNOTE 4.5.3).
fn zip64_extra(values: &[u64]) -> Vec<u8> {
    if values.is_empty() {
        return Vec::new();
    }
    let mut e = 1u16.to_le_bytes().to_vec();
    e.extend_from_slice(&((values.len() * 8) as u16).to_le_bytes());
    for v in values {
        e.extend_from_slice(&v.to_le_bytes());
    }
    e
}

/// The ZIP64 end of central directory record (APPNOTE 4.3.14) and its locator (4.3.15), for a
/// directory of `count` entries and `len` bytes at `offset`, written right after it.
fn zip64_end(count: u64, len: u64, offset: u64) -> Vec<u8> {
    let mut z = 0x0606_4b50u32.to_le_bytes().to_vec();
    z.extend_from_slice(&44u64.to_le_bytes()); // the record's size after this field
    z.extend_from_slice(&45u16.to_le_bytes()); // made by
    z.extend_from_slice(&45u16.to_le_bytes()); // needed
    z.extend_from_slice(&0u32.to_le_bytes()); // this disk
    z.extend_from_slice(&0u32.to_le_bytes()); // the directory's disk
    for v in [count, count, len, offset] {
        z.extend_from_slice(&v.to_le_bytes());
    }
    z.extend_from_slice(&0x0706_4b50u32.to_le_bytes());
    z.extend_from_slice(&0u32.to_le_bytes()); // the record's disk
    z.extend_from_slice(&(offset + len).to_le_bytes()); // where the record starts
    z.extend_from_slice(&1u32.to_le_bytes()); // disks
    z
}

impl<W: std::io::Write + std::io::Seek> NpzWriter<W> {
    /// An empty archive written into `w` from its current position 0.
    pub fn new(w: W) -> Self {
        NpzWriter {
            w,
            central: Vec::new(),
            count: 0,
            offset: 0,
            zip64_from: IN_ZIP64 as u64,
        }
    }

    /// Write ZIP64 records for every size, offset or count from `limit` up (4 GiB − 1, where a
    /// 32-bit field ends, unless lowered to test a reader on small archives).
    pub fn zip64_from(mut self, limit: u64) -> Self {
        self.zip64_from = limit;
        self
    }

    /// The 32-bit field for `v`, and whether it overflows into the ZIP64 extra field.
    fn field(&self, v: u64) -> (u32, bool) {
        if v >= self.zip64_from {
            (IN_ZIP64, true)
        } else {
            (v as u32, false)
        }
    }

    /// One member of known bytes.
    pub fn member(&mut self, name: &str, data: &[u8]) -> std::io::Result<()> {
        self.streamed(name, data.len() as u64, |put| put(data))
    }

    /// One member of `len` bytes that `fill` gives in pieces through `put`.
    pub fn streamed(
        &mut self,
        name: &str,
        len: u64,
        fill: impl FnOnce(&mut dyn FnMut(&[u8]) -> std::io::Result<()>) -> std::io::Result<()>,
    ) -> std::io::Result<()> {
        let name = format!("{name}.npy");
        let (size, size64) = self.field(len);
        let (offset, offset64) = self.field(self.offset);
        // The local header: both sizes in the extra field when they overflow (APPNOTE 4.5.3).
        let sizes = [len, len];
        let local_extra = zip64_extra(if size64 { &sizes[..] } else { &[] });
        // The central header: the overflowing ones of (size, size, offset), in that order.
        let mut central_values = Vec::new();
        if size64 {
            central_values.extend([len, len]);
        }
        if offset64 {
            central_values.push(self.offset);
        }
        let central_extra = zip64_extra(&central_values);
        let header = |crc: u32, central: bool, extra: &[u8]| {
            let zip64 = !extra.is_empty();
            let mut h = if central { 0x0201_4b50u32 } else { 0x0403_4b50 }
                .to_le_bytes()
                .to_vec();
            if central {
                h.extend_from_slice(&version(zip64).to_le_bytes()); // made by
            }
            // No flags, stored, 1980-01-01 00:00.
            for v in [version(zip64), 0, 0, 0, 0x21] {
                h.extend_from_slice(&v.to_le_bytes());
            }
            for v in [crc, size, size] {
                h.extend_from_slice(&v.to_le_bytes());
            }
            h.extend_from_slice(&(name.len() as u16).to_le_bytes());
            h.extend_from_slice(&(extra.len() as u16).to_le_bytes());
            h
        };
        let local = header(0, false, &local_extra);
        self.w.write_all(&local)?;
        self.w.write_all(name.as_bytes())?;
        self.w.write_all(&local_extra)?;
        let mut crc = crc32fast::Hasher::new();
        let mut written = 0u64;
        {
            let w = &mut self.w;
            let mut put = |b: &[u8]| {
                crc.update(b);
                written += b.len() as u64;
                w.write_all(b)
            };
            fill(&mut put)?;
        }
        assert_eq!(
            written, len,
            "a streamed member gives the bytes it announced"
        );
        let crc = crc.finalize();
        let end = self.offset + (local.len() + name.len() + local_extra.len()) as u64 + len;
        self.w
            .seek(std::io::SeekFrom::Start(self.offset + CRC_AT))?;
        self.w.write_all(&crc.to_le_bytes())?;
        self.w.seek(std::io::SeekFrom::Start(end))?;
        self.central.extend(header(crc, true, &central_extra));
        for v in [0u16, 0, 0] {
            self.central.extend_from_slice(&v.to_le_bytes()); // comment, disk, internal
        }
        self.central.extend_from_slice(&0u32.to_le_bytes()); // external attributes
        self.central.extend_from_slice(&offset.to_le_bytes());
        self.central.extend_from_slice(name.as_bytes());
        self.central.extend_from_slice(&central_extra);
        self.offset = end;
        self.count += 1;
        Ok(())
    }

    /// Write the central directory (after it the ZIP64 end records, where a count, size or
    /// offset overflows the classic one); the writer back.
    pub fn finish(mut self) -> std::io::Result<W> {
        let cd_offset = self.offset;
        let cd_len = self.central.len() as u64;
        self.w.write_all(&self.central)?;
        let (len32, len64) = self.field(cd_len);
        let (offset32, offset64) = self.field(cd_offset);
        let count64 = self.count >= (u16::MAX as u64).min(self.zip64_from);
        let count16 = if count64 { u16::MAX } else { self.count as u16 };
        if len64 || offset64 || count64 {
            let records = zip64_end(self.count, cd_len, cd_offset);
            self.w.write_all(&records)?;
        }
        let mut end = 0x0605_4b50u32.to_le_bytes().to_vec();
        for v in [0u16, 0, count16, count16] {
            end.extend_from_slice(&v.to_le_bytes()); // disk, cd disk, entries here, entries
        }
        end.extend_from_slice(&len32.to_le_bytes());
        end.extend_from_slice(&offset32.to_le_bytes());
        end.extend_from_slice(&0u16.to_le_bytes()); // comment
        self.w.write_all(&end)?;
        self.w.flush()?;
        Ok(self.w)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn headers_pad_to_64_bytes_and_unicode_is_utf32() {
        let a = Array::unicode(&["ab".into(), "é".into()]);
        assert_eq!(a.descr, "'<U2'");
        assert_eq!(a.body.len(), 16);
        assert_eq!(&a.body[8..12], &0xe9u32.to_le_bytes());
        let npy = a.npy();
        let header_len = u16::from_le_bytes([npy[8], npy[9]]) as usize;
        assert_eq!((10 + header_len) % 64, 0);
        assert!(std::str::from_utf8(&npy[10..10 + header_len])
            .unwrap()
            .contains("'shape': (2,)"));
    }

    #[test]
    fn the_archive_ends_with_its_directory() {
        let z = npz(&[("a", Array::i64(&[1, 2]).npy())]);
        let end = z.len() - 22;
        assert_eq!(&z[end..end + 4], &0x0605_4b50u32.to_le_bytes());
        assert_eq!(&z[..4], &0x0403_4b50u32.to_le_bytes());
    }
}
