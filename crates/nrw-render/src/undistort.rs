//! A photo resampled to its undistorted pinhole camera, as COLMAP 3.8's `image_undistorter`
//! does (`WarpImageBetweenCameras`), through this workspace's own camera models: each pixel
//! centre of the pinhole camera — rescaled to the photo's size first, against aliasing, as
//! COLMAP does — is unprojected by the pinhole camera and projected by the photo's exact
//! model, the photo is sampled bilinearly there (`Bitmap::InterpolateBilinear`), and the
//! result is resized to the pinhole camera's size with a triangle filter (COLMAP:
//! FreeImage's bilinear `Rescale`). So the undistorted photo and a render drawn with the
//! pinhole camera stay aligned pixel for pixel.

use glam::{DVec2, DVec3};
use nrw_colmap::Camera;

/// An 8-bit RGB raster, row-major, 3 bytes per pixel.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Rgb8 {
    pub width: u32,
    pub height: u32,
    pub data: Vec<u8>,
}

/// The photo `src` (taken with `from`, whose size it must have) seen through the pinhole
/// camera `to`. Pixels whose sample falls outside the photo's pixel centres are black, as
/// COLMAP leaves them (with its default `blank_pixels = 0` there are none but a thin edge).
///
/// Precision: positions are f64; each channel is interpolated in f64 and rounded to 8 bits
/// once (COLMAP rounds the same way).
pub fn undistort_photo(src: &Rgb8, from: &Camera, to: &Camera) -> Rgb8 {
    assert_eq!(
        (src.width as u64, src.height as u64),
        (from.width, from.height),
        "the photo has its camera's size (checked by the caller)"
    );
    if (to.width, to.height) == (from.width, from.height) {
        return warp(src, from, to);
    }
    // COLMAP's Camera::Rescale(width, height) of the pinhole camera to the photo's size.
    let (sx, sy) = (
        from.width as f64 / to.width as f64,
        from.height as f64 / to.height as f64,
    );
    let p = &to.params;
    let at_source_size = Camera {
        width: from.width,
        height: from.height,
        params: vec![p[0] * sx, p[1] * sy, p[2] * sx, p[3] * sy],
        ..to.clone()
    };
    let warped = warp(src, from, &at_source_size);
    resize_triangle(&warped, to.width as u32, to.height as u32)
}

/// A label map of the photo (`width` × `height` class ids, the size of camera `from`) seen
/// through the pinhole camera `to`: each pixel centre of `to` takes the class of the photo
/// pixel its ray lands in (nearest, never a blend of classes), 0 where it lands outside
/// the photo. Drawn at `to`'s own size (a nearest sample needs no anti-aliasing pass).
pub fn undistort_labels(ids: &[u8], from: &Camera, to: &Camera) -> Vec<u8> {
    let (sw, sh) = (from.width as usize, from.height as usize);
    assert_eq!(ids.len(), sw * sh, "the label map has its camera's size");
    let (w, h) = (to.width as usize, to.height as usize);
    let source = source_of(from, to);
    let mut out = vec![0u8; w * h];
    for (y, row) in out.chunks_exact_mut(w).enumerate() {
        for (x, class) in row.iter_mut().enumerate() {
            let Some(s) = source(x, y) else {
                continue;
            };
            // The pixel whose square [i, i + 1) holds the sample.
            let (sx, sy) = (s.x.floor(), s.y.floor());
            if sx >= 0.0 && sy >= 0.0 && sx < sw as f64 && sy < sh as f64 {
                *class = ids[sy as usize * sw + sx as usize];
            }
        }
    }
    out
}

/// Where the centre of the pinhole camera `to`'s pixel (x, y) lies in the photo of camera
/// `from`: unprojected by `to`, projected by `from`'s exact model; None where it has no pixel.
fn source_of<'a>(from: &'a Camera, to: &Camera) -> impl Fn(usize, usize) -> Option<DVec2> + 'a {
    let (f, pp) = (to.focal(), to.principal_point());
    move |x, y| {
        let world = (DVec2::new(x as f64 + 0.5, y as f64 + 0.5) - pp) / f;
        from.img_from_cam(DVec3::new(world.x, world.y, 1.0))
    }
}

/// Each pixel of the pinhole camera `to` sampled from the photo `src` (camera `from`).
fn warp(src: &Rgb8, from: &Camera, to: &Camera) -> Rgb8 {
    let (w, h) = (to.width as u32, to.height as u32);
    let mut data = vec![0u8; w as usize * h as usize * 3];
    let source = source_of(from, to);
    for (y, row) in data.chunks_exact_mut(w as usize * 3).enumerate() {
        for (x, px) in row.chunks_exact_mut(3).enumerate() {
            let Some(s) = source(x, y) else {
                continue;
            };
            if let Some(rgb) = bilinear(src, s.x - 0.5, s.y - 0.5) {
                px.copy_from_slice(&rgb);
            }
        }
    }
    Rgb8 {
        width: w,
        height: h,
        data,
    }
}

/// Separable triangle-filter resize (support 1 pixel, widened by the reduction factor when
/// shrinking, pixel centres aligned), horizontal pass first, kept in f64 and rounded once.
/// COLMAP uses FreeImage's `FILTER_BILINEAR`, the same filter; FreeImage rounds its
/// intermediate to 8 bits, this does not, so values may differ by a level.
fn resize_triangle(src: &Rgb8, w: u32, h: u32) -> Rgb8 {
    let (sw, sh) = (src.width as usize, src.height as usize);
    let (w, h) = (w as usize, h as usize);
    let xs = weights(sw, w);
    let ys = weights(sh, h);
    // Horizontal: sh rows of w pixels.
    let mut mid = vec![0f64; sh * w * 3];
    for y in 0..sh {
        for (x, (first, ws)) in xs.iter().enumerate() {
            for c in 0..3 {
                mid[(y * w + x) * 3 + c] = ws
                    .iter()
                    .enumerate()
                    .map(|(k, wt)| wt * src.data[(y * sw + first + k) * 3 + c] as f64)
                    .sum();
            }
        }
    }
    let mut data = vec![0u8; w * h * 3];
    for (y, (first, ws)) in ys.iter().enumerate() {
        for x in 0..w {
            for c in 0..3 {
                let v: f64 = ws
                    .iter()
                    .enumerate()
                    .map(|(k, wt)| wt * mid[((first + k) * w + x) * 3 + c])
                    .sum();
                data[(y * w + x) * 3 + c] = v.round().clamp(0.0, 255.0) as u8;
            }
        }
    }
    Rgb8 {
        width: w as u32,
        height: h as u32,
        data,
    }
}

/// Per output index along one axis: the first input index and the normalised triangle
/// weights of the inputs from there.
fn weights(src: usize, dst: usize) -> Vec<(usize, Vec<f64>)> {
    let scale = dst as f64 / src as f64;
    let support = if scale < 1.0 { 1.0 / scale } else { 1.0 };
    (0..dst)
        .map(|i| {
            let centre = (i as f64 + 0.5) / scale;
            let lo = ((centre - support).floor().max(0.0)) as usize;
            let hi = ((centre + support).ceil() as usize).min(src);
            let ws: Vec<f64> = (lo..hi)
                .map(|j| (1.0 - ((j as f64 + 0.5 - centre) / support).abs()).max(0.0))
                .collect();
            let total: f64 = ws.iter().sum();
            (lo, ws.iter().map(|v| v / total).collect())
        })
        .collect()
}

/// COLMAP's `Bitmap::InterpolateBilinear` at pixel-index coordinates (x, y): defined for
/// x ∈ [0, w − 1) and y ∈ (0, h − 1] — FreeImage stores rows bottom-up, which makes the valid
/// range asymmetric in y; transcribed as is so the same edge pixels are black.
fn bilinear(img: &Rgb8, x: f64, y: f64) -> Option<[u8; 3]> {
    let (w, h) = (img.width as i64, img.height as i64);
    if !(x.is_finite() && y.is_finite()) {
        return None;
    }
    let inv_y = (h - 1) as f64 - y;
    let (x0, y0) = (x.floor() as i64, inv_y.floor() as i64);
    if x0 < 0 || x0 + 1 >= w || y0 < 0 || y0 + 1 >= h {
        return None;
    }
    let (dx, dy) = (x - x0 as f64, inv_y - y0 as f64);
    // Bottom-up rows y0 and y0 + 1 are top-down rows h − 1 − y0 and h − 2 − y0.
    let at = |row: i64, col: i64, c: usize| img.data[((row * w + col) * 3) as usize + c] as f64;
    let (r0, r1) = (h - 1 - y0, h - 2 - y0);
    Some(std::array::from_fn(|c| {
        let v = (1.0 - dy) * ((1.0 - dx) * at(r0, x0, c) + dx * at(r0, x0 + 1, c))
            + dy * ((1.0 - dx) * at(r1, x0, c) + dx * at(r1, x0 + 1, c));
        v.round().clamp(0.0, 255.0) as u8
    }))
}

#[cfg(test)]
mod tests {
    use super::*;
    use nrw_colmap::CameraModel;

    fn photo(w: u32, h: u32) -> Rgb8 {
        let data = (0..w * h * 3).map(|i| (i * 37 % 251) as u8).collect();
        Rgb8 {
            width: w,
            height: h,
            data,
        }
    }

    fn pinhole(w: u64, h: u64) -> Camera {
        Camera {
            id: 1,
            model: CameraModel::Pinhole,
            width: w,
            height: h,
            params: vec![50.0, 50.0, w as f64 / 2.0, h as f64 / 2.0],
        }
    }

    #[test]
    fn the_same_camera_copies_the_photo_but_colmaps_black_edge() {
        // COLMAP's bilinear lookup is defined for x ∈ [0, w − 1) and y ∈ (0, h − 1]: with
        // the same camera on both sides, the last column and the first row come out black.
        let (w, h) = (7, 5);
        let src = photo(w, h);
        let out = undistort_photo(&src, &pinhole(7, 5), &pinhole(7, 5));
        for y in 0..h as usize {
            for x in 0..w as usize {
                let i = (y * w as usize + x) * 3;
                let want = if x == w as usize - 1 || y == 0 {
                    [0, 0, 0]
                } else {
                    [src.data[i], src.data[i + 1], src.data[i + 2]]
                };
                assert_eq!(out.data[i..i + 3], want, "pixel ({x}, {y})");
            }
        }
        // A 1 × 1 photo has no pixel to interpolate between: black, no panic.
        let one = undistort_photo(&photo(1, 1), &pinhole(1, 1), &pinhole(1, 1));
        assert_eq!(one.data, vec![0, 0, 0]);
    }

    #[test]
    fn resizing_keeps_a_constant_photo_constant() {
        for (sw, dw) in [(10usize, 7usize), (7, 10), (1020, 1018), (3, 1)] {
            let ws = weights(sw, dw);
            for (first, w) in &ws {
                assert!((w.iter().sum::<f64>() - 1.0).abs() < 1e-12);
                assert!(first + w.len() <= sw);
            }
        }
        let flat = Rgb8 {
            width: 9,
            height: 6,
            data: vec![200; 9 * 6 * 3],
        };
        let small = resize_triangle(&flat, 4, 5);
        assert!(small.data.iter().all(|v| *v == 200));
    }
}
