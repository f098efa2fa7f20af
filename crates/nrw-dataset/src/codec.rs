//! Image payloads stored in shards: photos and renders as PNG (lossless), decoded photos
//! resized with a Lanczos filter so they align with renders pixel for pixel.

use std::io::Cursor;
use std::path::Path;

use image::{ImageEncoder, RgbImage};

use crate::error::{DatasetError, Result};

fn png(
    name: &str,
    w: u32,
    h: u32,
    data: &[u8],
    color: image::ExtendedColorType,
) -> Result<Vec<u8>> {
    let mut out = Vec::new();
    image::codecs::png::PngEncoder::new_with_quality(
        &mut out,
        image::codecs::png::CompressionType::Fast,
        image::codecs::png::FilterType::Adaptive,
    )
    .write_image(data, w, h, color)
    .map_err(|e| DatasetError::Schema {
        path: name.into(),
        problem: format!("cannot encode PNG: {e}"),
    })?;
    Ok(out)
}

/// Largest photo ingest decodes, in pixels (the RGB buffer alone is 805 MB): a header that
/// claims more is refused before any allocation, so a lying file cannot abort the run.
pub const MAX_PHOTO_PIXELS: u64 = 1 << 28;

/// Decode a photo file into RGB8, strictly: bytes that end before the image does or that the
/// decoder rejects are [`DatasetError::Unreadable`], never pixels filled in with grey.
/// EXIF orientation is ignored, as COLMAP ignores it.
pub fn load_photo(path: &Path) -> Result<RgbImage> {
    let bytes = std::fs::read(path).map_err(|e| DatasetError::io(path, e))?;
    decode_photo(&bytes, MAX_PHOTO_PIXELS).map_err(|problem| DatasetError::Unreadable {
        path: path.into(),
        problem,
    })
}

/// Decode photo bytes (JPEG or PNG) into RGB8, or say in a sentence why they cannot be.
pub fn decode_photo(bytes: &[u8], max_pixels: u64) -> std::result::Result<RgbImage, String> {
    match photo_format(bytes)? {
        image::ImageFormat::Jpeg => decode_jpeg(bytes, max_pixels),
        format => decode_lenient(bytes, format, max_pixels),
    }
}

/// JPEG through libjpeg-turbo's decoder ([`crate::jpeg`]), strictly: the pixels Pillow gives.
/// CMYK and YCCK photos, which libjpeg does not turn into RGB, go through zune-jpeg.
fn decode_jpeg(bytes: &[u8], max_pixels: u64) -> std::result::Result<RgbImage, String> {
    use crate::jpeg::Decoded;
    match crate::jpeg::decode(bytes, max_pixels, true)? {
        Decoded::Rgb {
            width,
            height,
            data,
        } => RgbImage::from_raw(width, height, data),
        Decoded::Grey {
            width,
            height,
            data,
        } => RgbImage::from_raw(
            width,
            height,
            data.iter().flat_map(|&g| [g, g, g]).collect(),
        ),
        Decoded::Unsupported(_) => return decode_jpeg_strict(bytes, max_pixels),
    }
    .ok_or_else(|| "JPEG decoder gave a buffer of another size than its header".into())
}

/// A photo's format from its first bytes (16 are enough): JPEG or PNG, or why it is neither.
pub fn photo_format(head: &[u8]) -> std::result::Result<image::ImageFormat, String> {
    if head.is_empty() {
        return Err("the file is empty (0 bytes)".into());
    }
    match image::guess_format(head) {
        Ok(f @ (image::ImageFormat::Jpeg | image::ImageFormat::Png)) => Ok(f),
        Ok(other) => Err(format!(
            "{other:?} images are not supported (JPEG and PNG are)"
        )),
        Err(_) => Err("not a JPEG or PNG image (its first bytes are no image signature)".into()),
    }
}

fn too_large(w: u64, h: u64, max_pixels: u64) -> std::result::Result<(), String> {
    if w * h > max_pixels {
        return Err(format!(
            "the header claims {w}x{h} pixels, more than the {max_pixels}-pixel limit"
        ));
    }
    Ok(())
}

/// Decode with the `image` crate (PNG's decoder fails on truncated or corrupt data by itself).
fn decode_lenient(
    bytes: &[u8],
    format: image::ImageFormat,
    max_pixels: u64,
) -> std::result::Result<RgbImage, String> {
    let reader = || image::ImageReader::with_format(Cursor::new(bytes), format);
    let (w, h) = reader()
        .into_dimensions()
        .map_err(|e| format!("{format:?} header: {}", e.to_string().trim()))?;
    too_large(w as u64, h as u64, max_pixels)?;
    let img = reader()
        .decode()
        .map_err(|e| format!("{format:?} data: {}", e.to_string().trim()))?;
    Ok(img.into_rgb8())
}

/// Strict-mode complaints that leave every pixel intact (junk between header segments, which
/// many cameras and editors write); the photo is then decoded as the `image` crate does.
const HARMLESS_JPEG: [&str; 1] = ["Extra bytes between headers"];

/// JPEG through zune-jpeg in strict mode (CMYK and YCCK photos only): a scan that ends early ("Premature end of buffer")
/// or a marker inside entropy-coded data is an error instead of a grey fill. Colour handling
/// is the `image` crate's (grey stays grey, every other colour space becomes RGB), so a
/// readable photo decodes to the same pixels as before.
fn decode_jpeg_strict(bytes: &[u8], max_pixels: u64) -> std::result::Result<RgbImage, String> {
    use zune_core::{bytestream::ZCursor, colorspace::ColorSpace, options::DecoderOptions};
    let options = DecoderOptions::default()
        .set_strict_mode(true)
        .set_max_width(usize::from(u16::MAX))
        .set_max_height(usize::from(u16::MAX));
    let mut d = zune_jpeg::JpegDecoder::new_with_options(ZCursor::new(bytes), options);
    d.decode_headers()
        .map_err(|e| format!("JPEG header: {e}"))?;
    let (w, h) = d.dimensions().ok_or("JPEG header without a size")?;
    too_large(w as u64, h as u64, max_pixels)?;
    let grey = matches!(
        d.input_colorspace(),
        Some(ColorSpace::Luma | ColorSpace::LumaA)
    );
    let out = if grey {
        ColorSpace::Luma
    } else {
        ColorSpace::RGB
    };
    d.set_options(d.options().jpeg_set_out_colorspace(out));
    let px = match d.decode() {
        Ok(px) => px,
        Err(e) if HARMLESS_JPEG.iter().any(|m| e.to_string().contains(m)) => {
            return decode_lenient(bytes, image::ImageFormat::Jpeg, max_pixels)
        }
        Err(e) => return Err(format!("JPEG data: {e}")),
    };
    let (w, h) = (w as u32, h as u32);
    let rgb = if grey {
        px.iter().flat_map(|&g| [g, g, g]).collect()
    } else {
        px
    };
    RgbImage::from_raw(w, h, rgb)
        .ok_or_else(|| format!("JPEG decoder gave a buffer that is not {w}x{h} RGB"))
}

/// Resize to the render size with Lanczos3 (a no-op when sizes agree). Pixel edges map to
/// edges, which is the convention under which scaling fx, cx by the same factor keeps
/// photo and render aligned.
pub fn resize_photo(img: &RgbImage, width: u32, height: u32) -> RgbImage {
    if img.width() == width && img.height() == height {
        return img.clone();
    }
    image::imageops::resize(img, width, height, image::imageops::FilterType::Lanczos3)
}

/// PNG of raw RGB8 bytes.
pub fn encode_rgb_bytes(name: &str, w: u32, h: u32, rgb: &[u8]) -> Result<Vec<u8>> {
    png(name, w, h, rgb, image::ExtendedColorType::Rgb8)
}

/// PNG of raw single-channel bytes.
pub fn encode_gray(name: &str, w: u32, h: u32, gray: &[u8]) -> Result<Vec<u8>> {
    png(name, w, h, gray, image::ExtendedColorType::L8)
}

/// PNG of 16-bit single-channel values (graphdeco's inverse-depth priors are 16-bit PNGs).
pub fn encode_gray16(name: &str, w: u32, h: u32, values: &[u16]) -> Result<Vec<u8>> {
    // The encoder takes 16-bit samples in native byte order and writes PNG's big-endian.
    let bytes: Vec<u8> = values.iter().flat_map(|v| v.to_ne_bytes()).collect();
    png(name, w, h, &bytes, image::ExtendedColorType::L16)
}

/// JPEG of an RGB8 image at `quality` (1–100), for layouts whose loaders open `.jpg` files.
pub fn encode_jpeg(name: &str, img: &RgbImage, quality: u8) -> Result<Vec<u8>> {
    let mut out = Vec::new();
    image::codecs::jpeg::JpegEncoder::new_with_quality(&mut out, quality)
        .write_image(
            img.as_raw(),
            img.width(),
            img.height(),
            image::ExtendedColorType::Rgb8,
        )
        .map_err(|e| DatasetError::Schema {
            path: name.into(),
            problem: format!("cannot encode JPEG: {e}"),
        })?;
    Ok(out)
}

/// PNG of an RGB8 image.
pub fn encode_rgb(name: &str, img: &RgbImage) -> Result<Vec<u8>> {
    png(
        name,
        img.width(),
        img.height(),
        img.as_raw(),
        image::ExtendedColorType::Rgb8,
    )
}

/// PNG of an RGBA8 image.
pub fn encode_rgba(name: &str, img: &image::RgbaImage) -> Result<Vec<u8>> {
    png(
        name,
        img.width(),
        img.height(),
        img.as_raw(),
        image::ExtendedColorType::Rgba8,
    )
}

/// PNG RGBA of a colour render: alpha 255 where a point was drawn, 0 elsewhere.
pub fn encode_color_render(
    name: &str,
    w: u32,
    h: u32,
    color: Option<&[[u8; 3]]>,
    depth: &[f32],
) -> Result<Vec<u8>> {
    let mut rgba = Vec::with_capacity(depth.len() * 4);
    for (i, d) in depth.iter().enumerate() {
        let c = color.map_or([0, 0, 0], |c| c[i]);
        rgba.extend_from_slice(&[c[0], c[1], c[2], if *d > 0.0 { 255 } else { 0 }]);
    }
    png(name, w, h, &rgba, image::ExtendedColorType::Rgba8)
}

/// PNG RGB of camera-space normals mapped from [-1, 1] to [0, 255]; (0, 0, 0) where empty.
pub fn encode_normals(
    name: &str,
    w: u32,
    h: u32,
    normal: &[[f32; 3]],
    depth: &[f32],
) -> Result<Vec<u8>> {
    let mut rgb = Vec::with_capacity(normal.len() * 3);
    for (n, d) in normal.iter().zip(depth) {
        if *d > 0.0 {
            rgb.extend(
                n.iter()
                    .map(|v| ((v.clamp(-1.0, 1.0) * 0.5 + 0.5) * 255.0).round() as u8),
            );
        } else {
            rgb.extend_from_slice(&[0, 0, 0]);
        }
    }
    png(name, w, h, &rgb, image::ExtendedColorType::Rgb8)
}

/// Decode any PNG payload into (width, height, channels, bytes).
pub fn decode_png(bytes: &[u8], name: &Path) -> Result<(u32, u32, u8, Vec<u8>)> {
    let img = image::ImageReader::with_format(Cursor::new(bytes), image::ImageFormat::Png)
        .decode()
        .map_err(|e| DatasetError::Schema {
            path: name.into(),
            problem: format!("not a PNG payload: {e}"),
        })?;
    let ch = img.color().channel_count();
    Ok((img.width(), img.height(), ch, img.into_bytes()))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn jpeg(img: &image::DynamicImage) -> Vec<u8> {
        let mut out = Vec::new();
        img.write_to(&mut Cursor::new(&mut out), image::ImageFormat::Jpeg)
            .unwrap();
        out
    }

    fn pattern(w: u32, h: u32) -> RgbImage {
        RgbImage::from_fn(w, h, |x, y| {
            image::Rgb([
                (x * 7 % 256) as u8,
                (y * 5 % 256) as u8,
                ((x ^ y) % 256) as u8,
            ])
        })
    }

    #[test]
    fn a_whole_jpeg_decodes_close_to_another_decoders_pixels_and_grey_stays_grey() {
        // libjpeg-turbo and the image crate's zune-jpeg differ in IDCT and upsampling by a
        // few levels (docs/bench/jpeg_decode.md); Pillow's equality is tested on real photos.
        for img in [
            image::DynamicImage::ImageRgb8(pattern(123, 77)),
            image::DynamicImage::ImageLuma8(
                image::DynamicImage::ImageRgb8(pattern(64, 50)).into_luma8(),
            ),
        ] {
            let bytes = jpeg(&img);
            let ours = decode_photo(&bytes, MAX_PHOTO_PIXELS).unwrap();
            let theirs = image::load_from_memory(&bytes).unwrap().into_rgb8();
            assert_eq!(ours.dimensions(), theirs.dimensions());
            let worst = ours
                .as_raw()
                .iter()
                .zip(theirs.as_raw())
                .map(|(a, b)| a.abs_diff(*b))
                .max();
            assert!(worst <= Some(8), "{:?}: {worst:?}", img.color());
            if img.color() == image::ColorType::L8 {
                assert!(ours.pixels().all(|p| p[0] == p[1] && p[1] == p[2]));
            }
        }
    }

    #[test]
    fn truncated_empty_and_foreign_bytes_are_unreadable_with_a_reason() {
        let bytes = jpeg(&image::DynamicImage::ImageRgb8(pattern(300, 200)));
        let cut = decode_photo(&bytes[..bytes.len() / 2], MAX_PHOTO_PIXELS).unwrap_err();
        assert!(cut.contains("JPEG data"), "{cut}");
        let mut png = Vec::new();
        image::DynamicImage::ImageRgb8(pattern(300, 200))
            .write_to(&mut Cursor::new(&mut png), image::ImageFormat::Png)
            .unwrap();
        let cut = decode_photo(&png[..png.len() / 2], MAX_PHOTO_PIXELS).unwrap_err();
        assert!(cut.contains("Png data"), "{cut}");
        assert!(decode_photo(b"", MAX_PHOTO_PIXELS)
            .unwrap_err()
            .contains("empty"));
        assert!(decode_photo(b"ply\nformat", MAX_PHOTO_PIXELS)
            .unwrap_err()
            .contains("not a JPEG or PNG"));
        let webp = decode_photo(b"RIFF\x10\0\0\0WEBPVP8 \0\0\0\0", MAX_PHOTO_PIXELS).unwrap_err();
        assert!(webp.contains("not supported"), "{webp}");
        let big = decode_photo(&bytes, 1000).unwrap_err();
        assert!(big.contains("300x200"), "{big}");
    }

    /// Intensity-weighted centre of an image, in pixel-edge coordinates (pixel x spans x..x+1).
    fn centroid(img: &RgbImage) -> (f64, f64) {
        let (mut m, mut mx, mut my) = (0.0, 0.0, 0.0);
        for (x, y, p) in img.enumerate_pixels() {
            let w = p[0] as f64;
            m += w;
            mx += w * (x as f64 + 0.5);
            my += w * (y as f64 + 0.5);
        }
        (mx / m, my / m)
    }

    #[test]
    fn a_resized_photo_puts_a_feature_where_the_scaled_intrinsics_do() {
        // A bright 6 × 6 block centred at (123, 83) on grey, resized by non-integer factors.
        // Intrinsics scale as x' = s·x (pixel edges to edges), so the block must land at
        // (123·sx, 83·sy); a centre-to-centre resize would put it ~0.25 px off.
        let mut img = RgbImage::from_pixel(301, 201, image::Rgb([40, 40, 40]));
        for y in 80..86 {
            for x in 120..126 {
                img.put_pixel(x, y, image::Rgb([240, 240, 240]));
            }
        }
        let (w, h) = (150, 100);
        let small = resize_photo(&img, w, h);
        // The grey floor weighs every pixel alike: subtract it so only the block counts.
        let mut block = small.clone();
        for p in block.pixels_mut() {
            p[0] = p[0].saturating_sub(40);
        }
        let (cx, cy) = centroid(&block);
        let (ex, ey) = (123.0 * w as f64 / 301.0, 83.0 * h as f64 / 201.0);
        assert!(
            (cx - ex).abs() < 0.05 && (cy - ey).abs() < 0.05,
            "block at ({cx:.3}, {cy:.3}), scaled intrinsics put it at ({ex:.3}, {ey:.3})"
        );
    }
}
