//! The TFRecord wire format of `tf.train.Example`s, written without TensorFlow: the protobuf encoding of
//! the few message types an Example uses, and TFRecord framing (length, masked CRC-32C of the
//! length, data, masked CRC-32C of the data), as `tf.io.TFRecordWriter` writes them.

use std::io::Write;

/// CRC-32C (Castagnoli, reflected polynomial 0x82F63B78), the checksum TFRecord frames carry:
/// the CPU's CRC32 instruction where it has one (SSE4.2), else a table.
pub fn crc32c(data: &[u8]) -> u32 {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("sse4.2") {
        // SAFETY: the CPU has SSE4.2 (checked above).
        return unsafe { crc32c_sse42(data) };
    }
    crc32c_table_driven(data)
}

/// CRC-32C with the SSE4.2 `crc32` instruction, 8 bytes at a time.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "sse4.2")]
unsafe fn crc32c_sse42(data: &[u8]) -> u32 {
    use std::arch::x86_64::{_mm_crc32_u64, _mm_crc32_u8};
    let mut crc = !0u64;
    let mut chunks = data.chunks_exact(8);
    for c in &mut chunks {
        crc = _mm_crc32_u64(crc, u64::from_le_bytes(c.try_into().expect("8 bytes")));
    }
    let mut crc = crc as u32;
    for &b in chunks.remainder() {
        crc = _mm_crc32_u8(crc, b);
    }
    !crc
}

/// CRC-32C by table look-ups (slicing by 8), for CPUs without the instruction.
pub fn crc32c_table_driven(data: &[u8]) -> u32 {
    let table = crc32c_table();
    let mut crc = !0u32;
    // Slicing by 8: eight table look-ups per 8 bytes instead of one per byte.
    let mut chunks = data.chunks_exact(8);
    for c in &mut chunks {
        let lo = crc ^ u32::from_le_bytes([c[0], c[1], c[2], c[3]]);
        crc = table[7][(lo & 0xff) as usize]
            ^ table[6][((lo >> 8) & 0xff) as usize]
            ^ table[5][((lo >> 16) & 0xff) as usize]
            ^ table[4][(lo >> 24) as usize]
            ^ table[3][c[4] as usize]
            ^ table[2][c[5] as usize]
            ^ table[1][c[6] as usize]
            ^ table[0][c[7] as usize];
    }
    for &b in chunks.remainder() {
        crc = table[0][((crc ^ b as u32) & 0xff) as usize] ^ (crc >> 8);
    }
    !crc
}

fn crc32c_table() -> &'static [[u32; 256]; 8] {
    static TABLE: std::sync::OnceLock<Box<[[u32; 256]; 8]>> = std::sync::OnceLock::new();
    TABLE.get_or_init(|| {
        let mut t = Box::new([[0u32; 256]; 8]);
        for i in 0..256u32 {
            let mut c = i;
            for _ in 0..8 {
                c = if c & 1 != 0 {
                    (c >> 1) ^ 0x82F6_3B78
                } else {
                    c >> 1
                };
            }
            t[0][i as usize] = c;
        }
        for i in 0..256 {
            for k in 1..8 {
                let prev = t[k - 1][i];
                t[k][i] = (prev >> 8) ^ t[0][(prev & 0xff) as usize];
            }
        }
        t
    })
}

/// TFRecord's masking of a CRC (a rotation plus a constant), so CRCs of CRCs stay strong.
pub fn masked_crc32c(data: &[u8]) -> u32 {
    let c = crc32c(data);
    (c.rotate_right(15)).wrapping_add(0xa282_ead8)
}

/// One feature value of an Example.
#[derive(Debug, Clone, PartialEq)]
pub enum Feature<'a> {
    /// `int64_list` with one value.
    Int64(i64),
    /// `bytes_list` with one value.
    Bytes(&'a [u8]),
}

fn varint(mut v: u64, out: &mut Vec<u8>) {
    while v >= 0x80 {
        out.push((v as u8) | 0x80);
        v >>= 7;
    }
    out.push(v as u8);
}

fn varint_len(v: u64) -> usize {
    (64 - (v | 1).leading_zeros() as usize).div_ceil(7)
}

/// Bytes of a length-delimited field (wire type 2) of field number < 16 holding `len` bytes.
fn field_len(len: usize) -> usize {
    1 + varint_len(len as u64) + len
}

/// The tag and length of a length-delimited field (wire type 2, field number < 16).
fn field_head(number: u32, len: usize, out: &mut Vec<u8>) {
    out.push(((number << 3) | 2) as u8);
    varint(len as u64, out);
}

/// Sizes of a `Feature` message: (its list message, the feature).
fn feature_lens(f: &Feature) -> (usize, usize) {
    let list = match f {
        Feature::Bytes(b) => field_len(b.len()), // BytesList.value = 1
        Feature::Int64(v) => field_len(varint_len(*v as u64)), // Int64List.value = 1, packed
    };
    (list, field_len(list)) // Feature.bytes_list = 1 / Feature.int64_list = 3
}

fn entry_len(key: &str, f: &Feature) -> usize {
    field_len(key.len()) + field_len(feature_lens(f).1)
}

/// Size of the serialised Example of `features`.
fn example_len(features: &[(&str, Feature)]) -> usize {
    field_len(
        features
            .iter()
            .map(|(k, f)| field_len(entry_len(k, f)))
            .sum(),
    )
}

/// Append the serialised `tf.train.Example` whose `features.feature` map holds `features` in
/// the given order (Example.features = 1; Features.feature = 1, map entries key = 1,
/// value = 2; Feature.bytes_list = 1 or int64_list = 3; each list's value = 1, int64s
/// packed). Sizes are computed first, so each payload is copied once.
fn write_example(features: &[(&str, Feature)], out: &mut Vec<u8>) {
    let map: usize = features
        .iter()
        .map(|(k, f)| field_len(entry_len(k, f)))
        .sum();
    field_head(1, map, out);
    for (key, f) in features {
        field_head(1, entry_len(key, f), out);
        field_head(1, key.len(), out);
        out.extend_from_slice(key.as_bytes());
        let (list, feature) = feature_lens(f);
        field_head(2, feature, out);
        match f {
            Feature::Bytes(b) => {
                field_head(1, list, out);
                field_head(1, b.len(), out);
                out.extend_from_slice(b);
            }
            Feature::Int64(v) => {
                field_head(3, list, out);
                field_head(1, varint_len(*v as u64), out);
                varint(*v as u64, out); // negative int64 are 10-byte two's complement
            }
        }
    }
}

/// A serialised `tf.train.Example` (see `write_example`).
pub fn encode_example(features: &[(&str, Feature)]) -> Vec<u8> {
    let mut out = Vec::with_capacity(example_len(features));
    write_example(features, &mut out);
    out
}

/// One whole TFRecord frame (length, masked CRC of it, the Example, masked CRC of that) in
/// one buffer, ready to append to a file: what `write_record` writes for `encode_example`.
pub fn encode_record(features: &[(&str, Feature)]) -> Vec<u8> {
    let n = example_len(features);
    let mut out = Vec::with_capacity(n + 16);
    let len = (n as u64).to_le_bytes();
    out.extend_from_slice(&len);
    out.extend_from_slice(&masked_crc32c(&len).to_le_bytes());
    write_example(features, &mut out);
    debug_assert_eq!(out.len(), n + 12);
    let crc = masked_crc32c(&out[12..]);
    out.extend_from_slice(&crc.to_le_bytes());
    out
}

/// Append one TFRecord frame holding `data` to `w`.
pub fn write_record(w: &mut impl Write, data: &[u8]) -> std::io::Result<()> {
    let len = (data.len() as u64).to_le_bytes();
    w.write_all(&len)?;
    w.write_all(&masked_crc32c(&len).to_le_bytes())?;
    w.write_all(data)?;
    w.write_all(&masked_crc32c(data).to_le_bytes())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn crc32c_matches_the_standard_check_values() {
        // RFC 3720 B.4 and the catalogue's check value for "123456789".
        assert_eq!(crc32c(b"123456789"), 0xE306_9283);
        assert_eq!(crc32c(&[0u8; 32]), 0x8A91_36AA);
        assert_eq!(crc32c(&[0xffu8; 32]), 0x62A8_AB43);
        let inc: Vec<u8> = (0..32u8).collect();
        assert_eq!(crc32c(&inc), 0x46DD_794E);
        assert_eq!(crc32c(b""), 0);
        // Every length around the 8-byte stride gives what the byte-at-a-time loop gives.
        let data: Vec<u8> = (0..100u32).map(|i| (i * 37 + 11) as u8).collect();
        for n in 0..data.len() {
            let t = crc32c_table();
            let mut c = !0u32;
            for &b in &data[..n] {
                c = t[0][((c ^ b as u32) & 0xff) as usize] ^ (c >> 8);
            }
            assert_eq!(crc32c(&data[..n]), !c, "length {n}");
        }
    }

    #[test]
    fn an_example_encodes_as_protobuf_does() {
        // Bytes worked out by hand from example.proto and feature.proto.
        let e = encode_example(&[("h", Feature::Int64(300)), ("b", Feature::Bytes(b"xy"))]);
        #[rustfmt::skip]
        let want: Vec<u8> = vec![
            0x0a, 26, // Example.features
            0x0a, 11, // Features.feature map entry
            0x0a, 1, b'h', // key
            0x12, 6, 0x1a, 4, 0x0a, 2, 0xac, 0x02, // value: int64_list { value: [300] packed }
            0x0a, 11,
            0x0a, 1, b'b',
            0x12, 6, 0x0a, 4, 0x0a, 2, b'x', b'y', // value: bytes_list { value: ["xy"] }
        ];
        assert_eq!(e, want);
    }

    #[test]
    fn the_instruction_and_the_table_agree() {
        let data: Vec<u8> = (0..4099u32)
            .map(|i| (i.wrapping_mul(2_654_435_761) >> 13) as u8)
            .collect();
        for n in [0, 1, 7, 8, 9, 63, 64, 65, 1000, 4099] {
            assert_eq!(
                crc32c(&data[..n]),
                crc32c_table_driven(&data[..n]),
                "length {n}"
            );
        }
    }

    #[test]
    fn a_whole_record_is_the_frame_of_its_example() {
        let big = vec![7u8; 300];
        let f = [
            ("height", Feature::Int64(480)),
            ("width", Feature::Int64(-1)),
            ("rendered", Feature::Bytes(&big)),
            ("seg", Feature::Bytes(&[])),
        ];
        let mut framed = Vec::new();
        write_record(&mut framed, &encode_example(&f)).unwrap();
        assert_eq!(encode_record(&f), framed);
        assert_eq!(encode_example(&f).len(), example_len(&f));
        for v in [0u64, 1, 127, 128, 16383, 16384, u64::MAX] {
            let mut b = Vec::new();
            varint(v, &mut b);
            assert_eq!(b.len(), varint_len(v), "{v}");
        }
    }

    #[test]
    fn a_frame_is_length_crc_data_crc() {
        let mut out = Vec::new();
        write_record(&mut out, b"abc").unwrap();
        assert_eq!(out.len(), 8 + 4 + 3 + 4);
        assert_eq!(&out[..8], &3u64.to_le_bytes());
        assert_eq!(&out[12..15], b"abc");
        let m = u32::from_le_bytes(out[15..].try_into().unwrap());
        let unmasked = m.wrapping_sub(0xa282_ead8).rotate_left(15);
        assert_eq!(unmasked, crc32c(b"abc"));
    }
}
