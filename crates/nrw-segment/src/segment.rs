//! A photo → its ADE20K label map, in one of four documented modes.

use image::{GrayImage, RgbImage};
use nrw_gemm::Parallelism;

use crate::error::{Result, SegmentError};
use crate::model::Segformer;
use crate::ops::Map;
use crate::postprocess::labels;
use crate::preprocess::{normalize, pil_bilinear, preprocess};

/// How a photo is fed to the network.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Mode {
    /// Hugging Face's default: the whole photo resized to `width × height` (512 × 512),
    /// logits upsampled back to the photo's size.
    Resize { width: u32, height: u32 },
    /// mmsegmentation's ADE20K test protocol (the SegFormer paper's numbers): the photo
    /// scaled, aspect ratio kept, so its shorter side is `size` (the longer at most 4·size),
    /// one pass over the whole image.
    Whole { size: u32 },
    /// Sliding windows of `size × size` at a stride of about two thirds of a window over the
    /// photo scaled so its shorter side is `size` (mmsegmentation's `slide` inference),
    /// logits averaged where windows overlap.
    Slide { size: u32 },
    /// The published code's `segment_dataset.py`: the central `size × size` crop of the
    /// photo, unresized; pixels outside it are 0 (unlabelled).
    CenterCrop { size: u32 },
}

/// Largest network input side: memory grows with its square (about 1 GB of activations for
/// SegFormer-b2 at 2048²); the released models were trained at 512 and 640.
pub const MAX_SIZE: u32 = 2048;

impl Default for Mode {
    fn default() -> Self {
        Mode::Resize {
            width: 512,
            height: 512,
        }
    }
}

impl std::fmt::Display for Mode {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Mode::Resize { width, height } => write!(f, "resize {width}x{height}"),
            Mode::Whole { size } => write!(f, "whole {size}"),
            Mode::Slide { size } => write!(f, "slide {size}"),
            Mode::CenterCrop { size } => write!(f, "crop {size}"),
        }
    }
}

/// The kinds of [`Mode`], without their size: what a caller chooses before the size.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ModeKind {
    Resize,
    Whole,
    Slide,
    Crop,
}

impl ModeKind {
    /// Every kind, in the order help lists them.
    pub const ALL: [ModeKind; 4] = [
        ModeKind::Resize,
        ModeKind::Whole,
        ModeKind::Slide,
        ModeKind::Crop,
    ];

    /// The kind's name on the command line and in pipeline files.
    pub fn name(self) -> &'static str {
        match self {
            ModeKind::Resize => "resize",
            ModeKind::Whole => "whole",
            ModeKind::Slide => "slide",
            ModeKind::Crop => "crop",
        }
    }

    /// What the kind does, in one line (the CLI's help for each value).
    pub fn summary(self) -> &'static str {
        match self {
            ModeKind::Resize => "Hugging Face's default: the photo resized to SIZE×SIZE, logits upsampled to the photo",
            ModeKind::Whole => "mmsegmentation's ADE20K protocol: aspect ratio kept, shorter side SIZE, one pass",
            ModeKind::Slide => "SIZE×SIZE windows (stride ⅔) over the photo scaled to a shorter side of SIZE, logits averaged",
            ModeKind::Crop => "The published code: the central SIZE×SIZE crop, unresized; 0 (unlabelled) outside it",
        }
    }
}

impl std::str::FromStr for ModeKind {
    type Err = String;

    /// A kind by its name; the error lists the names.
    fn from_str(name: &str) -> std::result::Result<ModeKind, String> {
        ModeKind::ALL
            .into_iter()
            .find(|k| k.name() == name)
            .ok_or_else(|| format!("unknown mode `{name}`: resize, whole, slide or crop"))
    }
}

impl Mode {
    /// A mode of `kind` at `size` pixels, refusing sizes the kind cannot take.
    pub fn new(kind: ModeKind, size: u32) -> std::result::Result<Mode, String> {
        if size == 0 || size > MAX_SIZE {
            return Err(format!(
                "the size must be 1..={MAX_SIZE} pixels, not {size}"
            ));
        }
        match kind {
            ModeKind::Whole => Ok(Mode::Whole { size }),
            ModeKind::Resize => Ok(Mode::Resize {
                width: size,
                height: size,
            }),
            ModeKind::Slide if !size.is_multiple_of(4) => Err(format!(
                "slide windows must be a multiple of 4 pixels (the logits' grid), not {size}"
            )),
            ModeKind::Slide => Ok(Mode::Slide { size }),
            ModeKind::Crop => Ok(Mode::CenterCrop { size }),
        }
    }

    /// From the words of pipeline files: `resize`, `whole`, `slide` or `crop`, with the size
    /// in pixels.
    pub fn parse(name: &str, size: u32) -> std::result::Result<Mode, String> {
        let kind: ModeKind = name.parse()?;
        Mode::new(kind, size)
    }
}

/// The model's label map of a photo at the photo's size: ADE ids 1…150 (0 only outside a
/// centre crop). `what` names the photo in errors.
pub fn segment(
    model: &Segformer,
    photo: &RgbImage,
    mode: Mode,
    what: &str,
    par: Parallelism,
) -> Result<GrayImage> {
    let (w, h) = (photo.width(), photo.height());
    let min = model.min_side() as u32;
    let too_small = |size: u32| SegmentError::Input {
        what: what.into(),
        problem: format!(
            "{mode}: a {size}-pixel input is below the {min} pixels this model's stages need"
        ),
    };
    let ids = match mode {
        Mode::Resize { width, height } => {
            if width.min(height) < min {
                return Err(too_small(width.min(height)));
            }
            let logits = model.logits(
                &preprocess(photo, width, height),
                height as usize,
                width as usize,
                par,
            );
            labels(&logits, w as usize, h as usize)
        }
        Mode::Whole { size } => {
            let (sw, sh) = whole_size(w, h, size);
            if sw.min(sh) < min {
                return Err(too_small(sw.min(sh)));
            }
            let logits = model.logits(&preprocess(photo, sw, sh), sh as usize, sw as usize, par);
            labels(&logits, w as usize, h as usize)
        }
        Mode::Slide { size } => {
            if size < min {
                return Err(too_small(size));
            }
            labels(
                &slide_logits(model, photo, size, what, par)?,
                w as usize,
                h as usize,
            )
        }
        Mode::CenterCrop { size } => {
            if size < min {
                return Err(too_small(size));
            }
            return center_crop(model, photo, size, what, par);
        }
    };
    Ok(GrayImage::from_raw(w, h, ids).expect("sized label map"))
}

/// mmcv's `Resize(scale=(4·size, size), keep_ratio=True)`: one factor that brings the
/// shorter side to `size` unless the longer would pass `4·size`; sides rounded half up.
pub fn whole_size(w: u32, h: u32, size: u32) -> (u32, u32) {
    let (long, short) = (w.max(h) as f64, w.min(h) as f64);
    let f = (4.0 * size as f64 / long).min(size as f64 / short);
    let side = |v: u32| ((v as f64 * f + 0.5) as u32).max(1);
    (side(w), side(h))
}

fn center_crop(
    model: &Segformer,
    photo: &RgbImage,
    size: u32,
    what: &str,
    par: Parallelism,
) -> Result<GrayImage> {
    let (w, h) = (photo.width(), photo.height());
    if w < size || h < size {
        return Err(SegmentError::Input {
            what: what.into(),
            problem: format!(
                "{w}×{h} is smaller than the {size}×{size} centre crop of mode crop (the published code asserts the same); use mode resize or slide"
            ),
        });
    }
    let (x0, y0) = ((w - size) / 2, (h - size) / 2);
    let crop = image::imageops::crop_imm(photo, x0, y0, size, size).to_image();
    let s = size as usize;
    let ids = labels(&model.logits(&normalize(&crop), s, s, par), s, s);
    let mut out = GrayImage::new(w, h);
    for (y, row) in ids.chunks_exact(s).enumerate() {
        let at = (y0 as usize + y) * w as usize + x0 as usize;
        out.as_mut()[at..at + s].copy_from_slice(row);
    }
    Ok(out)
}

/// Where `slide` windows of `win` pixels start along an axis of `len`: every two thirds of a
/// window (rounded down to the logits' grid of 4), plus one window flush with the end.
pub fn slide_windows(len: usize, win: usize) -> Vec<usize> {
    starts(len, win, ((2 * win / 3) / 4 * 4).max(4))
}

/// Window starts along an axis of `len` (a multiple of 4): every `stride`, plus one flush
/// with the end.
fn starts(len: usize, win: usize, stride: usize) -> Vec<usize> {
    let mut v: Vec<usize> = (0..)
        .map(|i| i * stride)
        .take_while(|s| s + win < len)
        .collect();
    v.push(len - win);
    v
}

/// `slide` mode's logits: the photo scaled to shorter side `size`, windows at
/// [`slide_windows`], each grid cell the mean of the windows' logits that cover it; at a
/// quarter of the scaled size.
pub fn slide_logits(
    model: &Segformer,
    photo: &RgbImage,
    size: u32,
    what: &str,
    par: Parallelism,
) -> Result<Map> {
    let (w, h) = (photo.width() as f64, photo.height() as f64);
    let short = w.min(h);
    // The long side keeps the aspect ratio, rounded to a multiple of 4 pixels (the logits'
    // grid) and at least one window.
    let long = |l: f64| (((l * size as f64 / short) / 4.0).round() as u32 * 4).max(size);
    let (sw, sh) = if w <= h {
        (size, long(h))
    } else {
        (long(w), size)
    };
    let scaled = pil_bilinear(photo, sw, sh);
    let s = size as usize;
    let (gw, gh) = (sw as usize / 4, sh as usize / 4);
    let mut sum = Map::zeros(gh, gw, crate::config::ADE_CLASSES);
    let mut count = vec![0u32; gw * gh];
    for y0 in slide_windows(sh as usize, s) {
        for x0 in slide_windows(sw as usize, s) {
            let win =
                image::imageops::crop_imm(&scaled, x0 as u32, y0 as u32, size, size).to_image();
            let l = model.logits(&normalize(&win), s, s, par);
            if l.h * 4 != s || l.w * 4 != s {
                return Err(SegmentError::Input {
                    what: what.into(),
                    problem: format!("mode slide needs a model whose logits are a quarter of its input; a {s}-pixel window gave {}×{}", l.w, l.h),
                });
            }
            for y in 0..l.h {
                for x in 0..l.w {
                    let g = (y0 / 4 + y) * gw + x0 / 4 + x;
                    count[g] += 1;
                    let dst = &mut sum.data[g * l.c..][..l.c];
                    dst.iter_mut()
                        .zip(&l.data[(y * l.w + x) * l.c..][..l.c])
                        .for_each(|(a, b)| *a += b);
                }
            }
        }
    }
    for (px, n) in sum.data.chunks_exact_mut(sum.c).zip(&count) {
        let inv = 1.0 / *n as f32;
        px.iter_mut().for_each(|v| *v *= inv);
    }
    Ok(sum)
}
