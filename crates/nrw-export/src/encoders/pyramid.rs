//! Image pyramids (`images_2`, `images_4`, `images_8`) whose intrinsics are the level-0
//! intrinsics divided by the factor, exactly.
//!
//! COLMAP's pixel convention puts pixel `i`'s area at `[i, i + 1)`, so a camera's image
//! coordinate `u` becomes `u / f` when pixel `j` of level `f` is the `f × f` block of level-0
//! pixels `[j·f, (j + 1)·f)`. Each level is therefore a box filter of whole blocks: its size is
//! `⌊w / f⌋ × ⌊h / f⌋` (gsplat's `cam.width // factor`, so its loader rescales nothing), the
//! last `w mod f` columns and `h mod f` rows of level 0 are left out, and `fx, fy, cx, cy`
//! divide by `f` with no half-pixel shift. Every level is computed from level 0 (never from
//! the level before), so no rounding compounds.

use image::RgbImage;

/// The factors written beside level 0, as the consumers name their folders (`images_2`, …).
pub const FACTORS: [u32; 3] = [2, 4, 8];

/// The folder of level `f` for a base folder (`images` → `images_2`); level 1 is the base.
pub fn level_dir(base: &str, f: u32) -> String {
    if f == 1 {
        base.to_string()
    } else {
        format!("{base}_{f}")
    }
}

/// The size of level `f` of a `w × h` image: whole blocks only (floor).
pub fn level_size(w: u32, h: u32, f: u32) -> (u32, u32) {
    (w / f, h / f)
}

/// PINHOLE `[fx, fy, cx, cy]` at level `f`: each divided by `f` (exact in COLMAP's convention
/// for whole-block levels).
pub fn level_intrinsics(k: [f64; 4], f: u32) -> [f64; 4] {
    k.map(|x| x / f as f64)
}

/// Level `f` of an RGB image: each channel the mean of its `f × f` block, rounded half up.
pub fn box_rgb(img: &RgbImage, f: u32) -> RgbImage {
    let (w, h) = level_size(img.width(), img.height(), f);
    let n = f * f;
    RgbImage::from_fn(w, h, |x, y| {
        let mut sum = [0u32; 3];
        for dy in 0..f {
            for dx in 0..f {
                let p = img.get_pixel(x * f + dx, y * f + dy).0;
                for c in 0..3 {
                    sum[c] += p[c] as u32;
                }
            }
        }
        image::Rgb(sum.map(|s| ((s + n / 2) / n) as u8))
    })
}

/// Level `f` of a use-mask (255 = use the pixel, 0 = ignore): a block is used only when every
/// pixel of it is, so a coarse level never trains on a pixel the fine one ignores.
pub fn min_mask(mask: &[u8], w: u32, h: u32, f: u32) -> Vec<u8> {
    blocks(w, h, f, |xs, ys| {
        ys.flat_map(|y| xs.clone().map(move |x| (x, y)))
            .map(|(x, y)| mask[(y * w + x) as usize])
            .min()
            .unwrap_or(0)
    })
}

/// Level `f` of an inverse-depth map (0 = no depth): the block's mean when every pixel of it
/// has depth, else 0, so an edge between surface and hole never yields a depth of neither.
pub fn mean_inverse_depth(inv: &[f64], w: u32, h: u32, f: u32) -> Vec<f64> {
    blocks(w, h, f, |xs, ys| {
        let mut sum = 0.0;
        for y in ys {
            for x in xs.clone() {
                let v = inv[(y * w + x) as usize];
                if v <= 0.0 {
                    return 0.0;
                }
                sum += v;
            }
        }
        sum / (f * f) as f64
    })
}

/// One value per whole `f × f` block of a `w × h` grid, row-major.
fn blocks<T>(
    w: u32,
    h: u32,
    f: u32,
    mut of: impl FnMut(std::ops::Range<u32>, std::ops::Range<u32>) -> T,
) -> Vec<T> {
    let (lw, lh) = level_size(w, h, f);
    let mut out = Vec::with_capacity((lw * lh) as usize);
    for y in 0..lh {
        for x in 0..lw {
            out.push(of(x * f..(x + 1) * f, y * f..(y + 1) * f));
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn levels_are_whole_blocks_with_floor_sizes() {
        assert_eq!(level_size(101, 67, 2), (50, 33));
        assert_eq!(level_size(101, 67, 8), (12, 8));
        assert_eq!(level_dir("images", 1), "images");
        assert_eq!(level_dir("masks", 4), "masks_4");
        let img = RgbImage::from_fn(5, 3, |x, y| image::Rgb([(x * 10 + y) as u8, 0, 255]));
        let l = box_rgb(&img, 2);
        assert_eq!(l.dimensions(), (2, 1));
        // Block (0..2, 0..2): 0, 10, 1, 11 → 5.5 → 6 (half up); the fifth column is left out.
        assert_eq!(l.get_pixel(0, 0).0, [6, 0, 255]);
        assert_eq!(l.get_pixel(1, 0).0, [26, 0, 255]);
    }

    #[test]
    fn a_block_with_one_ignored_or_empty_pixel_is_ignored_or_empty() {
        let mask = [255, 255, 0, 255, 255, 255, 255, 255];
        assert_eq!(min_mask(&mask, 4, 2, 2), vec![255, 0]);
        let inv = [1.0, 3.0, 0.0, 1.0, 1.0, 3.0, 1.0, 1.0];
        assert_eq!(mean_inverse_depth(&inv, 4, 2, 2), vec![2.0, 0.0]);
    }

    #[test]
    fn intrinsics_divide_exactly() {
        let k = level_intrinsics([1000.5, 999.25, 320.0, 240.5], 8);
        assert_eq!(k, [125.0625, 124.90625, 40.0, 30.0625]);
    }
}
