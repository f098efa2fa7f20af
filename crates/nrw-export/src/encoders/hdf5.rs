//! The smallest HDF5 file MegaDepth's depth maps need: one float32 2-D dataset under one name
//! in the root group, stored contiguous and uncompressed, as `h5py.File(p)["depth"]` reads it.
//!
//! Written in HDF5's version-2 structures (file format specification 3.0): a version-2
//! superblock, version-2 object headers with Jenkins lookup3 checksums, and the root group's
//! link stored compactly in its header (Link Info, Group Info and Link messages), so no
//! B-tree, heap or symbol table is needed. h5py in the tests is the oracle.

/// HDF5's "undefined address".
const UNDEF: u64 = u64::MAX;
/// The file signature.
const SIGNATURE: &[u8; 8] = b"\x89HDF\r\n\x1a\n";
/// Bytes of the version-2 superblock, checksum included.
const SUPERBLOCK_LEN: usize = 48;

/// One HDF5 file holding the `h × w` float32 array `data` (row-major) as dataset `name`.
pub fn float32_2d(name: &str, h: u64, w: u64, data: &[f32]) -> Vec<u8> {
    assert_eq!(data.len() as u64, h * w, "data is h × w");
    assert!(name.len() < 256 && !name.is_empty(), "a short dataset name");
    let root = object_header(&root_messages(name, 0));
    let root_addr = SUPERBLOCK_LEN as u64;
    let dataset_addr = root_addr + root.len() as u64;
    let dataset_len = object_header(&dataset_messages(h, w, 0)).len() as u64;
    // Raw data starts 8-byte aligned after the dataset's header.
    let data_addr = (dataset_addr + dataset_len).div_ceil(8) * 8;
    let eof = data_addr + data.len() as u64 * 4;
    let mut out = superblock(root_addr, eof);
    out.extend(object_header(&root_messages(name, dataset_addr)));
    out.extend(object_header(&dataset_messages(h, w, data_addr)));
    out.resize(data_addr as usize, 0);
    for v in data {
        out.extend_from_slice(&v.to_le_bytes());
    }
    debug_assert_eq!(out.len() as u64, eof);
    out
}

/// The version-2 superblock: offsets and lengths of 8 bytes, no extension.
fn superblock(root_addr: u64, eof: u64) -> Vec<u8> {
    let mut s = Vec::with_capacity(SUPERBLOCK_LEN);
    s.extend_from_slice(SIGNATURE);
    s.extend_from_slice(&[2, 8, 8, 0]); // version, size of offsets, of lengths, flags
    for v in [0, UNDEF, eof, root_addr] {
        s.extend_from_slice(&v.to_le_bytes()); // base, extension, end of file, root header
    }
    let sum = lookup3(&s);
    s.extend_from_slice(&sum.to_le_bytes());
    s
}

/// One header message: (type, flags, body).
type Message = (u8, u8, Vec<u8>);

/// A version-2 object header holding `messages` in one chunk.
fn object_header(messages: &[Message]) -> Vec<u8> {
    let mut body = Vec::new();
    for (kind, flags, data) in messages {
        body.push(*kind);
        body.extend_from_slice(&(data.len() as u16).to_le_bytes());
        body.push(*flags);
        body.extend_from_slice(data);
    }
    let mut h = b"OHDR".to_vec();
    h.push(2); // version
    h.push(0x02); // flags: the size of chunk 0 takes 4 bytes; no times, no attribute order
    h.extend_from_slice(&(body.len() as u32).to_le_bytes());
    h.extend(body);
    let sum = lookup3(&h);
    h.extend_from_slice(&sum.to_le_bytes());
    h
}

/// The root group's messages: a new-style group (Link Info, Group Info) with one hard link.
fn root_messages(name: &str, target: u64) -> Vec<Message> {
    let mut link_info = vec![0, 0]; // version 0, no creation order
    link_info.extend_from_slice(&UNDEF.to_le_bytes()); // no fractal heap: links are compact
    link_info.extend_from_slice(&UNDEF.to_le_bytes()); // no name index
    let group_info = vec![0, 0]; // version 0, default phase changes
    let mut link = vec![1, 0, name.len() as u8]; // version 1, hard link, 1-byte name length
    link.extend_from_slice(name.as_bytes());
    link.extend_from_slice(&target.to_le_bytes());
    vec![(0x02, 0, link_info), (0x0A, 0, group_info), (0x06, 0, link)]
}

/// A contiguous float32 dataset's messages: dataspace, datatype, fill value, layout.
fn dataset_messages(h: u64, w: u64, data_addr: u64) -> Vec<Message> {
    let mut space = vec![2, 2, 0, 1]; // version 2, rank 2, no max dims, simple
    space.extend_from_slice(&h.to_le_bytes());
    space.extend_from_slice(&w.to_le_bytes());
    // Version 1, class 1 (floating point); little-endian, implied mantissa MSB, sign bit 31.
    let mut dtype = vec![0x11, 0x20, 0x1F, 0x00];
    dtype.extend_from_slice(&4u32.to_le_bytes()); // size
    dtype.extend_from_slice(&0u16.to_le_bytes()); // bit offset
    dtype.extend_from_slice(&32u16.to_le_bytes()); // bit precision
    dtype.extend_from_slice(&[23, 8, 0, 23]); // exponent at 23, 8 bits; mantissa at 0, 23 bits
    dtype.extend_from_slice(&127u32.to_le_bytes()); // exponent bias
                                                    // Version 3; space allocated early, fill written if set, no fill value defined.
    let fill = vec![3, 0x01 | (2 << 2)];
    let mut layout = vec![3, 1]; // version 3, contiguous
    layout.extend_from_slice(&data_addr.to_le_bytes());
    layout.extend_from_slice(&(h * w * 4).to_le_bytes());
    const CONSTANT: u8 = 0x01;
    vec![
        (0x01, 0, space),
        (0x03, CONSTANT, dtype),
        (0x05, CONSTANT, fill),
        (0x08, 0, layout),
    ]
}

/// Bob Jenkins' lookup3 `hashlittle` with initial value 0, as HDF5 checksums its metadata.
fn lookup3(data: &[u8]) -> u32 {
    let init = 0xdead_beefu32.wrapping_add(data.len() as u32);
    let (mut a, mut b, mut c) = (init, init, init);
    let word = |k: &[u8], i: usize| {
        let mut w = [0u8; 4];
        let end = (i + 4).min(k.len());
        if i < end {
            w[..end - i].copy_from_slice(&k[i..end]);
        }
        u32::from_le_bytes(w)
    };
    let mut k = data;
    while k.len() > 12 {
        a = a.wrapping_add(word(k, 0));
        b = b.wrapping_add(word(k, 4));
        c = c.wrapping_add(word(k, 8));
        mix(&mut a, &mut b, &mut c);
        k = &k[12..];
    }
    if k.is_empty() {
        return c;
    }
    a = a.wrapping_add(word(k, 0));
    b = b.wrapping_add(word(k, 4));
    c = c.wrapping_add(word(k, 8));
    finish(&mut a, &mut b, &mut c);
    c
}

/// lookup3's `mix`.
fn mix(a: &mut u32, b: &mut u32, c: &mut u32) {
    *a = a.wrapping_sub(*c) ^ c.rotate_left(4);
    *c = c.wrapping_add(*b);
    *b = b.wrapping_sub(*a) ^ a.rotate_left(6);
    *a = a.wrapping_add(*c);
    *c = c.wrapping_sub(*b) ^ b.rotate_left(8);
    *b = b.wrapping_add(*a);
    *a = a.wrapping_sub(*c) ^ c.rotate_left(16);
    *c = c.wrapping_add(*b);
    *b = b.wrapping_sub(*a) ^ a.rotate_left(19);
    *a = a.wrapping_add(*c);
    *c = c.wrapping_sub(*b) ^ b.rotate_left(4);
    *b = b.wrapping_add(*a);
}

/// lookup3's `final`.
fn finish(a: &mut u32, b: &mut u32, c: &mut u32) {
    *c = (*c ^ *b).wrapping_sub(b.rotate_left(14));
    *a = (*a ^ *c).wrapping_sub(c.rotate_left(11));
    *b = (*b ^ *a).wrapping_sub(a.rotate_left(25));
    *c = (*c ^ *b).wrapping_sub(b.rotate_left(16));
    *a = (*a ^ *c).wrapping_sub(c.rotate_left(4));
    *b = (*b ^ *a).wrapping_sub(a.rotate_left(14));
    *c = (*c ^ *b).wrapping_sub(b.rotate_left(24));
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lookup3_matches_the_published_values() {
        // lookup3.c's driver5: hashlittle("", 0, 0) and hashlittle("Four score and seven
        // years ago", 30, 0).
        assert_eq!(lookup3(b""), 0xdeadbeef);
        assert_eq!(lookup3(b"Four score and seven years ago"), 0x17770551);
    }

    #[test]
    fn the_file_is_as_long_as_its_superblock_says() {
        let f = float32_2d("depth", 2, 3, &[1.0, 2.0, 3.0, 4.0, 5.0, 6.0]);
        let eof = u64::from_le_bytes(f[28..36].try_into().unwrap());
        assert_eq!(eof as usize, f.len());
        assert_eq!(&f[f.len() - 4..], &6f32.to_le_bytes());
    }
}
