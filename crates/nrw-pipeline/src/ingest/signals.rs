//! What a photo's pixels say before any model does: sharpness (instant-ngp colmap2nerf's
//! variance of the Laplacian), exposure, and a DCT perceptual hash (imagehash's `phash`),
//! all from one grey image made as OpenCV makes it.

use image::RgbImage;
use nrw_dataset::scene::{PhotoSignals, BRIGHT_LEVEL, DARK_LEVEL};

/// A grey image, 8 bits a pixel, row-major.
pub struct Grey {
    pub width: usize,
    pub height: usize,
    pub pixels: Vec<u8>,
}

/// OpenCV's `cvtColor(…, COLOR_RGB2GRAY)` for 8-bit pixels as opencv-python 5.1 computes
/// it (what colmap2nerf's `cv2.cvtColor` gives): fixed-point weights 9798 / 19235 / 3735
/// over 2¹⁵, rounded (the 2¹⁴ weights of older OpenCV round some pixels the other way).
pub fn grey(photo: &RgbImage) -> Grey {
    let pixels = photo
        .pixels()
        .map(|p| {
            let [r, g, b] = p.0;
            ((r as u32 * 9798 + g as u32 * 19235 + b as u32 * 3735 + (1 << 14)) >> 15) as u8
        })
        .collect();
    Grey {
        width: photo.width() as usize,
        height: photo.height() as usize,
        pixels,
    }
}

/// OpenCV's BORDER_REFLECT_101 (`cv2.Laplacian`'s default border): -1 → 1, n → n - 2.
fn reflect101(i: isize, n: usize) -> usize {
    let n = n as isize;
    let r = if i < 0 {
        -i
    } else if i >= n {
        2 * n - 2 - i
    } else {
        i
    };
    r.clamp(0, n - 1) as usize
}

/// `cv2.Laplacian(grey, cv2.CV_64F).var()`: the 3×3 kernel [0 1 0; 1 −4 1; 0 1 0] with
/// reflected borders, and the population variance of its output. The Laplacian of 8-bit
/// pixels is an integer, so sums are exact (i128) and the variance is rounded once.
pub fn variance_of_laplacian(g: &Grey) -> f64 {
    let (w, h) = (g.width, g.height);
    if w == 0 || h == 0 {
        return 0.0;
    }
    let at = |x: isize, y: isize| g.pixels[reflect101(y, h) * w + reflect101(x, w)] as i64;
    let (mut sum, mut sum_sq) = (0i128, 0i128);
    for y in 0..h as isize {
        for x in 0..w as isize {
            let l = at(x - 1, y) + at(x + 1, y) + at(x, y - 1) + at(x, y + 1) - 4 * at(x, y);
            sum += l as i128;
            sum_sq += (l * l) as i128;
        }
    }
    let n = (w * h) as i128;
    // var = (n Σl² − (Σl)²) / n², exact up to the final division.
    (n * sum_sq - sum * sum) as f64 / (n * n) as f64
}

/// The grey image averaged down to `w`×`h` cells, each the mean of the input pixels whose
/// centres fall in it: the hash's 32×32 input, and the near-duplicate search's working size.
pub fn area_resize(g: &Grey, w: usize, h: usize) -> Vec<f64> {
    let mut sums = vec![0f64; w * h];
    let mut counts = vec![0u32; w * h];
    for y in 0..g.height {
        let cy = y * h / g.height;
        for x in 0..g.width {
            let c = cy * w + x * w / g.width;
            sums[c] += g.pixels[y * g.width + x] as f64;
            counts[c] += 1;
        }
    }
    sums.iter()
        .zip(&counts)
        .map(|(s, c)| if *c > 0 { s / *c as f64 } else { 0.0 })
        .collect()
}

/// scipy.fftpack's unnormalised DCT-II of each row of a `n`×`n` block, in place of a copy.
fn dct_rows(v: &[f64], n: usize) -> Vec<f64> {
    let mut out = vec![0f64; n * n];
    for r in 0..n {
        for k in 0..n {
            let s: f64 = (0..n)
                .map(|i| {
                    v[r * n + i]
                        * (std::f64::consts::PI * k as f64 * (2 * i + 1) as f64 / (2 * n) as f64)
                            .cos()
                })
                .sum();
            out[r * n + k] = 2.0 * s;
        }
    }
    out
}

fn transpose(v: &[f64], n: usize) -> Vec<f64> {
    (0..n * n).map(|i| v[(i % n) * n + i / n]).collect()
}

/// Side of the grey image the hash is taken from (imagehash: hash size 8 × factor 4).
const PHASH_INPUT: usize = 32;
/// Side of the block of lowest DCT terms the hash keeps.
const PHASH_SIZE: usize = 8;

/// imagehash's `phash`: the 8×8 lowest terms of the 2-D DCT of a 32×32 grey image, each
/// bit whether its term is above their median, row-major from the most significant bit.
/// The 32×32 image is an area average (imagehash resizes with Lanczos: the bits that
/// differ are those whose term lies nearest the median).
pub fn phash(g: &Grey) -> u64 {
    let small = area_resize(g, PHASH_INPUT, PHASH_INPUT);
    let dct = transpose(
        &dct_rows(
            &transpose(&dct_rows(&small, PHASH_INPUT), PHASH_INPUT),
            PHASH_INPUT,
        ),
        PHASH_INPUT,
    );
    let low: Vec<f64> = (0..PHASH_SIZE * PHASH_SIZE)
        .map(|i| dct[(i / PHASH_SIZE) * PHASH_INPUT + i % PHASH_SIZE])
        .collect();
    let mut sorted = low.clone();
    sorted.sort_by(f64::total_cmp);
    let m = sorted.len() / 2;
    let median = (sorted[m - 1] + sorted[m]) / 2.0;
    low.iter()
        .fold(0u64, |h, v| (h << 1) | u64::from(*v > median))
}

/// Sharpness, exposure and perceptual hash of a photo as decoded (before any undistortion).
pub fn signals(photo: &RgbImage) -> PhotoSignals {
    let g = grey(photo);
    let count = g.pixels.len().max(1) as u128;
    let n = count as f64;
    let (mut sum, mut sum_sq, mut dark, mut bright) = (0u64, 0u64, 0u64, 0u64);
    for &p in &g.pixels {
        sum += p as u64;
        sum_sq += (p as u64) * (p as u64);
        dark += u64::from(p <= DARK_LEVEL);
        bright += u64::from(p >= BRIGHT_LEVEL);
    }
    PhotoSignals {
        sharpness: variance_of_laplacian(&g),
        luma_mean: sum as f64 / n,
        // Exact integer sums, one rounding: n Σp² − (Σp)² ≥ 0.
        luma_std: ((count * sum_sq as u128 - sum as u128 * sum as u128) as f64 / (n * n)).sqrt(),
        dark_fraction: dark as f64 / n,
        bright_fraction: bright as f64 / n,
        phash: phash(&g),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn photo(w: u32, h: u32, f: impl Fn(u32, u32) -> [u8; 3]) -> RgbImage {
        RgbImage::from_fn(w, h, |x, y| image::Rgb(f(x, y)))
    }

    #[test]
    fn a_flat_photo_has_no_sharpness_and_a_checkerboard_the_most() {
        let flat = signals(&photo(40, 30, |_, _| [90, 90, 90]));
        assert_eq!(flat.sharpness, 0.0);
        assert_eq!(flat.luma_mean, 90.0);
        let black = signals(&photo(40, 30, |_, _| [0, 0, 0]));
        assert_eq!((black.dark_fraction, black.bright_fraction), (1.0, 0.0));
        // A 0/255 checkerboard: every Laplacian is ±1020, mean 0, variance 1020².
        let board = signals(&photo(40, 30, |x, y| [((x + y) % 2 * 255) as u8; 3]));
        assert_eq!(board.sharpness, 1020.0 * 1020.0);
        assert_eq!(board.dark_fraction + board.bright_fraction, 1.0);
    }

    #[test]
    fn borders_reflect_as_opencv_s_default() {
        assert_eq!(reflect101(-1, 5), 1);
        assert_eq!(reflect101(5, 5), 3);
        assert_eq!(reflect101(-1, 1), 0);
    }

    #[test]
    fn a_resized_copy_hashes_near_its_original_and_another_picture_far() {
        let f = |x: u32, y: u32| {
            let (x, y) = (x as f64, y as f64);
            let v = ((x / 97.0).sin() * (y / 61.0).cos() * 70.0 + (x * y / 9e4) * 40.0 + 100.0)
                .clamp(0.0, 255.0) as u8;
            [v, v / 2, 255 - v]
        };
        let original = photo(640, 480, f);
        let half =
            image::imageops::resize(&original, 320, 240, image::imageops::FilterType::Triangle);
        let (a, b) = (phash(&grey(&original)), phash(&grey(&half)));
        let other = phash(&grey(&photo(640, 480, |x, y| f(639 - x, y))));
        assert!((a ^ b).count_ones() <= 2, "{a:064b}\n{b:064b}");
        assert!((a ^ other).count_ones() >= 16, "{a:064b}\n{other:064b}");
    }
}
