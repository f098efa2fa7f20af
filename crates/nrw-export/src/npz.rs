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
        let dims: Vec<String> = self.shape.iter().map(|d| d.to_string()).collect();
        let shape = match dims.len() {
            1 => format!("({},)", dims[0]),
            _ => format!("({})", dims.join(", ")),
        };
        let dict = format!(
            "{{'descr': {}, 'fortran_order': False, 'shape': {shape}, }}",
            self.descr
        );
        // Magic (6) + version (2) + length (2) + dict + padding + '\n' ≡ 0 (mod 64).
        let pad = (64 - (10 + dict.len() + 1) % 64) % 64;
        let header = format!("{dict}{}\n", " ".repeat(pad));
        let mut out = Vec::with_capacity(10 + header.len() + self.body.len());
        out.extend_from_slice(b"\x93NUMPY\x01\x00");
        out.extend_from_slice(&(header.len() as u16).to_le_bytes());
        out.extend_from_slice(header.as_bytes());
        out.extend_from_slice(&self.body);
        out
    }
}

/// An `.npz` of `members` (name without `.npy`, bytes of an `.npy`), stored uncompressed as
/// `np.savez` does; None when it would need ZIP64 (a member or the archive over 4 GiB).
pub fn npz(members: &[(&str, Vec<u8>)]) -> Option<Vec<u8>> {
    let mut out = Vec::new();
    let mut central = Vec::new();
    for (name, data) in members {
        let name = format!("{name}.npy");
        let offset = u32::try_from(out.len()).ok()?;
        let size = u32::try_from(data.len()).ok()?;
        let crc = crc32fast::hash(data);
        // Version 2.0, no flags, stored, 1980-01-01 00:00.
        let fixed = |sig: u32, central: bool| {
            let mut h = sig.to_le_bytes().to_vec();
            if central {
                h.extend_from_slice(&20u16.to_le_bytes()); // made by
            }
            for v in [20u16, 0, 0, 0, 0x21] {
                h.extend_from_slice(&v.to_le_bytes()); // needed, flags, method, time, date
            }
            for v in [crc, size, size] {
                h.extend_from_slice(&v.to_le_bytes());
            }
            h.extend_from_slice(&(name.len() as u16).to_le_bytes());
            h.extend_from_slice(&0u16.to_le_bytes()); // extra
            h
        };
        out.extend(fixed(0x0403_4b50, false));
        out.extend_from_slice(name.as_bytes());
        out.extend_from_slice(data);
        central.extend(fixed(0x0201_4b50, true));
        for v in [0u16, 0, 0] {
            central.extend_from_slice(&v.to_le_bytes()); // comment, disk, internal attributes
        }
        central.extend_from_slice(&0u32.to_le_bytes()); // external attributes
        central.extend_from_slice(&offset.to_le_bytes());
        central.extend_from_slice(name.as_bytes());
    }
    let cd_offset = u32::try_from(out.len()).ok()?;
    let cd_len = u32::try_from(central.len()).ok()?;
    out.extend(central);
    out.extend_from_slice(&0x0605_4b50u32.to_le_bytes());
    let n = u16::try_from(members.len()).ok()?;
    for v in [0u16, 0, n, n] {
        out.extend_from_slice(&v.to_le_bytes()); // disk, cd disk, entries here, entries
    }
    out.extend_from_slice(&cd_len.to_le_bytes());
    out.extend_from_slice(&cd_offset.to_le_bytes());
    out.extend_from_slice(&0u16.to_le_bytes()); // comment
    u32::try_from(out.len()).ok()?;
    Some(out)
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
        let z = npz(&[("a", Array::i64(&[1, 2]).npy())]).unwrap();
        let end = z.len() - 22;
        assert_eq!(&z[end..end + 4], &0x0605_4b50u32.to_le_bytes());
        assert_eq!(&z[..4], &0x0403_4b50u32.to_le_bytes());
    }
}
