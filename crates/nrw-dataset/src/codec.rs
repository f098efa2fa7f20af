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

/// Decode a photo file into RGB8 (EXIF orientation ignored, as COLMAP ignores it).
pub fn load_photo(path: &Path) -> Result<RgbImage> {
    let img = image::ImageReader::open(path)
        .map_err(|e| DatasetError::io(path, e))?
        .with_guessed_format()
        .map_err(|e| DatasetError::io(path, e))?
        .decode()
        .map_err(|e| DatasetError::Schema {
            path: path.to_path_buf(),
            problem: format!("cannot decode photo: {e}"),
        })?;
    Ok(img.into_rgb8())
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
            path: name.to_path_buf(),
            problem: format!("not a PNG payload: {e}"),
        })?;
    let ch = img.color().channel_count();
    Ok((img.width(), img.height(), ch, img.into_bytes()))
}

#[cfg(test)]
mod tests {
    use super::*;

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
