//! Photo → network input, as torchvision expects (RGB in [0, 1], ImageNet mean and std), or
//! the paper's official code's [−1, 1] scaling when reproducing it.

use image::RgbImage;

/// ImageNet mean (RGB), as torchvision's `Normalize` uses.
pub const IMAGENET_MEAN: [f32; 3] = [0.485, 0.456, 0.406];
/// ImageNet standard deviation (RGB).
pub const IMAGENET_STD: [f32; 3] = [0.229, 0.224, 0.225];

/// How pixel values are mapped before the network.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Preprocess {
    /// (v/255 − mean) / std per channel: what the ImageNet weights were trained with.
    Imagenet,
    /// v/127.5 − 1: the official NRW code's scaling.
    MinusOneToOne,
}

/// CHW f32 input of an RGB8 image, computed in f32 in the same order as torchvision
/// (`ToTensor` then `Normalize`), so the fixture inputs are reproduced bit for bit.
pub fn to_input(img: &RgbImage, p: Preprocess) -> Vec<f32> {
    let (w, h) = (img.width() as usize, img.height() as usize);
    let mut out = vec![0f32; 3 * w * h];
    for (i, px) in img.pixels().enumerate() {
        for c in 0..3 {
            let v = px[c] as f32;
            out[c * w * h + i] = match p {
                Preprocess::Imagenet => (v / 255.0 - IMAGENET_MEAN[c]) / IMAGENET_STD[c],
                Preprocess::MinusOneToOne => v / 127.5 - 1.0,
            };
        }
    }
    out
}
