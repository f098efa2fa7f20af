//! Photo → network input exactly as Hugging Face's `SegformerImageProcessor` (the PIL backend:
//! transformers 4's default, transformers 5's `SegformerImageProcessorPil`) makes it: a PIL
//! bilinear resize of the 8-bit photo, then `v·(1/255)` in f64 cast to f32, minus the ImageNet
//! mean, divided by its standard deviation, in f32. Bit-identical to it (see the tests).

use image::RgbImage;

/// ImageNet mean (RGB), the processor's `image_mean`.
pub const IMAGENET_MEAN: [f32; 3] = [0.485, 0.456, 0.406];
/// ImageNet standard deviation (RGB), the processor's `image_std`.
pub const IMAGENET_STD: [f32; 3] = [0.229, 0.224, 0.225];

/// Pillow's fixed-point precision for 8-bit resampling (`Resample.c`: 32 − 8 − 2 bits).
const PRECISION_BITS: u32 = 22;

/// Planar CHW input of an 8-bit RGB image: `rescale` then `normalize` as the processor does.
pub fn normalize(img: &RgbImage) -> Vec<f32> {
    let n = (img.width() * img.height()) as usize;
    let mut out = vec![0f32; 3 * n];
    for (i, px) in img.pixels().enumerate() {
        for c in 0..3 {
            // The processor rescales in f64 and stores f32, then normalises in f32.
            let v = (px[c] as f64 * (1.0 / 255.0)) as f32;
            out[c * n + i] = (v - IMAGENET_MEAN[c]) / IMAGENET_STD[c];
        }
    }
    out
}

/// One axis of Pillow's resampling: for each output index, the first input index and the
/// fixed-point weights (`precompute_coeffs` then `normalize_coeffs_8bpc`).
struct Coeffs {
    bounds: Vec<(usize, usize)>,
    ksize: usize,
    k: Vec<i32>,
}

fn coeffs(n_in: usize, n_out: usize) -> Coeffs {
    // The triangle filter (Pillow's BILINEAR) has support 1, widened when shrinking.
    let scale = n_in as f64 / n_out as f64;
    let filterscale = scale.max(1.0);
    let support = filterscale;
    let ksize = support.ceil() as usize * 2 + 1;
    let mut bounds = Vec::with_capacity(n_out);
    let mut k = vec![0i32; n_out * ksize];
    for xx in 0..n_out {
        let center = (xx as f64 + 0.5) * scale;
        let ss = 1.0 / filterscale;
        // C's (int) casts truncate toward zero.
        let xmin = ((center - support + 0.5) as i64).max(0) as usize;
        let xmax = ((center + support + 0.5) as i64).min(n_in as i64) as usize - xmin;
        let w: Vec<f64> = (0..xmax)
            .map(|x| {
                let t = ((x + xmin) as f64 - center + 0.5) * ss;
                (1.0 - t.abs()).max(0.0)
            })
            .collect();
        let total: f64 = w.iter().sum();
        for (x, wx) in w.iter().enumerate() {
            let v = if total != 0.0 { wx / total } else { *wx };
            let f = v * (1u32 << PRECISION_BITS) as f64;
            k[xx * ksize + x] = if v < 0.0 {
                (f - 0.5) as i32
            } else {
                (f + 0.5) as i32
            };
        }
        bounds.push((xmin, xmax));
    }
    Coeffs { bounds, ksize, k }
}

/// Pillow's `clip8`: the fixed-point sum, shifted down and clamped to a byte.
fn clip8(v: i32) -> u8 {
    (v >> PRECISION_BITS).clamp(0, 255) as u8
}

/// One resampling pass along x (`horizontal`) or y of an RGB buffer `iw × ih`, Pillow's
/// fixed-point arithmetic: each output sample is `clip8` of the rounded weighted sum.
fn pass(src: &[u8], iw: usize, ih: usize, n_out: usize, horizontal: bool) -> Vec<u8> {
    let (ow, oh) = if horizontal { (n_out, ih) } else { (iw, n_out) };
    let co = coeffs(if horizontal { iw } else { ih }, n_out);
    let mut out = vec![0u8; ow * oh * 3];
    for (yy, row) in out.chunks_exact_mut(ow * 3).enumerate() {
        for xx in 0..ow {
            let o = if horizontal { xx } else { yy };
            let (first, n) = co.bounds[o];
            let k = &co.k[o * co.ksize..][..n];
            let mut ss = [1i32 << (PRECISION_BITS - 1); 3];
            for (j, kj) in k.iter().enumerate() {
                let at = if horizontal {
                    (yy * iw + first + j) * 3
                } else {
                    ((first + j) * iw + xx) * 3
                };
                for c in 0..3 {
                    ss[c] += src[at + c] as i32 * kj;
                }
            }
            for c in 0..3 {
                row[xx * 3 + c] = clip8(ss[c]);
            }
        }
    }
    out
}

/// `Image.resize((w, h), Image.BILINEAR)` of an RGB image, in Pillow's arithmetic: two
/// passes through an 8-bit intermediate, an axis that keeps its size skipped. Pillow 13 runs
/// the vertical pass first when the width grows and the height shrinks, the horizontal one
/// first otherwise (found by comparing with it; the order changes the rounding, and the
/// Pillow oracle test covers all four cases).
pub fn pil_bilinear(img: &RgbImage, w: u32, h: u32) -> RgbImage {
    let (iw, ih) = (img.width() as usize, img.height() as usize);
    let (w, h) = (w as usize, h as usize);
    let mut buf = img.as_raw().clone();
    let (mut cw, mut ch) = (iw, ih);
    let vertical_first = w > iw && h < ih;
    for horizontal in if vertical_first {
        [false, true]
    } else {
        [true, false]
    } {
        if horizontal && w != cw {
            buf = pass(&buf, cw, ch, w, true);
            cw = w;
        } else if !horizontal && h != ch {
            buf = pass(&buf, cw, ch, h, false);
            ch = h;
        }
    }
    RgbImage::from_raw(w as u32, h as u32, buf).expect("sized buffer")
}

/// The processor's whole preprocessing at `(w, h)`: resize (skipped when the size is kept,
/// as Pillow returns a copy), rescale, normalise.
pub fn preprocess(img: &RgbImage, w: u32, h: u32) -> Vec<f32> {
    if (img.width(), img.height()) == (w, h) {
        normalize(img)
    } else {
        normalize(&pil_bilinear(img, w, h))
    }
}
