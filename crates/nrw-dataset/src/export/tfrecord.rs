//! TFRecord files of `tf.train.Example`s, written without TensorFlow: the protobuf encoding of
//! the few message types an Example uses, and TFRecord framing (length, masked CRC-32C of the
//! length, data, masked CRC-32C of the data), as `tf.io.TFRecordWriter` writes them.

use std::io::Write;

/// CRC-32C (Castagnoli, reflected polynomial 0x82F63B78), the checksum TFRecord frames carry.
pub fn crc32c(data: &[u8]) -> u32 {
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

/// A length-delimited field (wire type 2).
fn field_bytes(number: u32, bytes: &[u8], out: &mut Vec<u8>) {
    varint(((number as u64) << 3) | 2, out);
    varint(bytes.len() as u64, out);
    out.extend_from_slice(bytes);
}

/// The `Feature` message: oneof bytes_list = 1, int64_list = 3 (BytesList.value = 1;
/// Int64List.value = 1, packed).
fn encode_feature(f: &Feature, out: &mut Vec<u8>) {
    let mut list = Vec::new();
    match f {
        Feature::Bytes(b) => {
            field_bytes(1, b, &mut list);
            field_bytes(1, &list, out);
        }
        Feature::Int64(v) => {
            let mut packed = Vec::new();
            varint(*v as u64, &mut packed); // negative int64 are 10-byte two's complement
            field_bytes(1, &packed, &mut list);
            field_bytes(3, &list, out);
        }
    }
}

/// A serialised `tf.train.Example` whose `features.feature` map holds `features` in the
/// given order (Example.features = 1; Features.feature = 1, map entries key = 1, value = 2).
pub fn encode_example(features: &[(&str, Feature)]) -> Vec<u8> {
    let mut map = Vec::new();
    for (key, value) in features {
        let mut entry = Vec::new();
        field_bytes(1, key.as_bytes(), &mut entry);
        let mut v = Vec::new();
        encode_feature(value, &mut v);
        field_bytes(2, &v, &mut entry);
        field_bytes(1, &entry, &mut map);
    }
    let mut example = Vec::with_capacity(map.len() + 8);
    field_bytes(1, &map, &mut example);
    example
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
