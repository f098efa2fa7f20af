//! Depth maps as single-channel f32 OpenEXR ("Z"), ZIP-compressed: lossless, and what the
//! trainer and ordinary viewers read. Depth is camera-space z; 0 marks a pixel with no surface.

use std::io::Cursor;
use std::path::Path;

use exr::prelude::*;

use crate::atomic::write_bytes_atomic;
use crate::error::{DatasetError, Result};

/// A depth map in row-major order, width × height values.
#[derive(Debug, Clone, PartialEq)]
pub struct DepthMap {
    pub width: usize,
    pub height: usize,
    pub data: Vec<f32>,
}

/// Encode a depth map as EXR bytes (ZIP, f32: lossless; never PXR24, which is lossy for f32).
pub fn encode_exr(depth: &DepthMap) -> Result<Vec<u8>> {
    encode_exr_channel(depth, "Z")
}

/// [`encode_exr`] with the channel named `channel`: OpenCV's reader (which DUSt3R's loaders
/// use) takes a single channel only when it is named "Y".
pub fn encode_exr_channel(depth: &DepthMap, channel: &str) -> Result<Vec<u8>> {
    assert_eq!(
        depth.data.len(),
        depth.width * depth.height,
        "depth buffer size"
    );
    let channels = SpecificChannels::build()
        .with_channel(channel)
        .with_pixel_fn(|p: Vec2<usize>| (depth.data[p.y() * depth.width + p.x()],));
    let layer = Layer::new(
        (depth.width, depth.height),
        LayerAttributes::named("depth"),
        Encoding {
            compression: Compression::ZIP16,
            ..Encoding::default()
        },
        channels,
    );
    let mut out = Cursor::new(Vec::new());
    Image::from_layer(layer)
        .write()
        .to_buffered(&mut out)
        .map_err(|e| DatasetError::Schema {
            path: "depth.exr".into(),
            problem: e.to_string(),
        })?;
    Ok(out.into_inner())
}

/// Decode EXR bytes written by [`encode_exr`] (or any EXR with one f32 "Z" channel).
pub fn decode_exr(bytes: &[u8], name: &Path) -> Result<DepthMap> {
    check_exr_size(bytes, name)?;
    let image = read()
        .no_deep_data()
        .largest_resolution_level()
        .specific_channels()
        .required("Z")
        .collect_pixels(
            |size: Vec2<usize>, _| DepthMap {
                width: size.x(),
                height: size.y(),
                data: vec![0.0; size.area()],
            },
            |m: &mut DepthMap, p: Vec2<usize>, (z,): (f32,)| m.data[p.y() * m.width + p.x()] = z,
        )
        .first_valid_layer()
        .all_attributes()
        .from_buffered(Cursor::new(bytes))
        .map_err(|e| DatasetError::Schema {
            path: name.into(),
            problem: format!("not a depth EXR: {e}"),
        })?;
    Ok(image.layer_data.channel_data.pixels)
}

/// Largest depth map decoded, in pixels (256 MB of f32): a header that claims more is refused
/// before the pixel buffer is allocated, so damaged bytes cannot abort a run.
pub const MAX_DEPTH_PIXELS: usize = 1 << 26;

/// Largest EXR block (scan-line group or tile) decoded, in bytes: ours are a few tens of KB.
pub const MAX_EXR_BLOCK_BYTES: usize = 64 << 20;

/// Refuse an EXR whose header claims a layer larger than [`MAX_DEPTH_PIXELS`] or blocks
/// larger than [`MAX_EXR_BLOCK_BYTES`].
fn check_exr_size(bytes: &[u8], name: &Path) -> Result<()> {
    let meta = exr::meta::MetaData::read_from_buffered(Cursor::new(bytes), false).map_err(|e| {
        DatasetError::Schema {
            path: name.into(),
            problem: format!("not a depth EXR: {e}"),
        }
    })?;
    for h in &meta.headers {
        // The reader allocates a block's claimed size before reading it.
        if h.max_block_byte_size() > MAX_EXR_BLOCK_BYTES {
            return Err(DatasetError::Schema {
                path: name.into(),
                problem: format!(
                    "the depth EXR's blocks would take {} bytes each, more than the {MAX_EXR_BLOCK_BYTES}-byte limit",
                    h.max_block_byte_size()
                ),
            });
        }
        let size = h.layer_size;
        if size.area() > MAX_DEPTH_PIXELS {
            return Err(DatasetError::Schema {
                path: name.into(),
                problem: format!(
                    "the depth EXR claims {}x{} pixels, more than the {MAX_DEPTH_PIXELS}-pixel limit",
                    size.x(),
                    size.y()
                ),
            });
        }
    }
    Ok(())
}

/// Write a depth map to an EXR file atomically.
pub fn write_exr(path: &Path, depth: &DepthMap) -> Result<()> {
    write_bytes_atomic(path, &encode_exr(depth)?)
}

/// Read a depth EXR file.
pub fn read_exr(path: &Path) -> Result<DepthMap> {
    let bytes = std::fs::read(path).map_err(|e| DatasetError::io(path, e))?;
    decode_exr(&bytes, path)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip_is_bit_exact() {
        let d = DepthMap {
            width: 7,
            height: 5,
            data: (0..35)
                .map(|i| {
                    if i % 6 == 0 {
                        0.0
                    } else {
                        1.0 + i as f32 * 0.123_456_7
                    }
                })
                .collect(),
        };
        let bytes = encode_exr(&d).unwrap();
        let back = decode_exr(&bytes, Path::new("t.exr")).unwrap();
        assert_eq!(back, d);
    }

    #[test]
    fn garbage_is_an_error_naming_the_file() {
        let e = decode_exr(b"not an exr", Path::new("x/depth.exr"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("x/depth.exr"), "{e}");
    }
}
