//! Thumbnails for the report: photos, renders, colour-mapped depth and a photo/render
//! checkerboard that makes misalignment visible, as JPEG data URIs (the report stays one self-contained file).

use base64::Engine as _;
use image::{imageops::FilterType, Rgb, RgbImage, RgbaImage};
use nrw_dataset::depth::DepthMap;

/// Thumbnail width in pixels.
pub const THUMB: u32 = 220;

/// A JPEG data URI of an image (quality 85: a report of dozens of thumbnails stays small).
pub fn data_uri(img: &RgbImage) -> String {
    let mut jpg = Vec::new();
    image::codecs::jpeg::JpegEncoder::new_with_quality(&mut jpg, 85)
        .write_image(
            img.as_raw(),
            img.width(),
            img.height(),
            image::ExtendedColorType::Rgb8,
        )
        .expect("JPEG encoding of an in-memory image");
    format!(
        "data:image/jpeg;base64,{}",
        base64::engine::general_purpose::STANDARD.encode(jpg)
    )
}

use image::ImageEncoder as _;

/// Resize to `width` keeping the aspect ratio (Triangle filter: thumbnails, not data).
pub fn thumb(img: &RgbImage, width: u32) -> RgbImage {
    let h =
        ((img.height() as f64 * width as f64 / img.width().max(1) as f64).round() as u32).max(1);
    image::imageops::resize(img, width, h, FilterType::Triangle)
}

/// The render on black where nothing was drawn (alpha 0).
pub fn render_rgb(c: &RgbaImage) -> RgbImage {
    RgbImage::from_fn(c.width(), c.height(), |x, y| {
        let p = c.get_pixel(x, y);
        if p[3] == 0 {
            Rgb([0, 0, 0])
        } else {
            Rgb([p[0], p[1], p[2]])
        }
    })
}

/// Viridis-like colour map: 5 stops, linear between them.
fn colormap(t: f64) -> Rgb<u8> {
    const STOPS: [[f64; 3]; 5] = [
        [68.0, 1.0, 84.0],
        [59.0, 82.0, 139.0],
        [33.0, 145.0, 140.0],
        [94.0, 201.0, 98.0],
        [253.0, 231.0, 37.0],
    ];
    let t = t.clamp(0.0, 1.0) * 4.0;
    let i = (t.floor() as usize).min(3);
    let f = t - i as f64;
    let c = |k: usize| (STOPS[i][k] * (1.0 - f) + STOPS[i + 1][k] * f).round() as u8;
    Rgb([c(0), c(1), c(2)])
}

/// Depth colour-mapped between its 2nd and 98th percentiles of covered pixels (near = dark);
/// empty pixels (depth 0 or not finite) are white.
pub fn depth_rgb(d: &DepthMap) -> RgbImage {
    let mut v: Vec<f32> = d
        .data
        .iter()
        .copied()
        .filter(|z| z.is_finite() && *z > 0.0)
        .collect();
    v.sort_by(|a, b| a.total_cmp(b));
    let (lo, hi) = if v.is_empty() {
        (0.0, 1.0)
    } else {
        (v[v.len() / 50] as f64, v[v.len() * 49 / 50] as f64)
    };
    let span = (hi - lo).max(1e-12);
    RgbImage::from_fn(d.width as u32, d.height as u32, |x, y| {
        let z = d.data[y as usize * d.width + x as usize];
        if z.is_finite() && z > 0.0 {
            colormap((z as f64 - lo) / span)
        } else {
            Rgb([255, 255, 255])
        }
    })
}

/// Photo and render in alternating `tile`-pixel squares (a registration checkerboard): where
/// render and photo align, lines run straight across tile borders; a shift breaks them.
/// Pixels the render left empty show the photo, dimmed.
pub fn checkerboard(photo: &RgbImage, render: &RgbaImage, tile: u32) -> RgbImage {
    RgbImage::from_fn(photo.width(), photo.height(), |x, y| {
        let p = *photo.get_pixel(x, y);
        let from_render = ((x / tile) + (y / tile)) % 2 == 1;
        if from_render && x < render.width() && y < render.height() {
            let r = render.get_pixel(x, y);
            if r[3] > 0 {
                return Rgb([r[0], r[1], r[2]]);
            }
            return Rgb([p[0] / 3, p[1] / 3, p[2] / 3]);
        }
        p
    })
}
