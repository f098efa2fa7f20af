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
    /// The published code's whole path into tensorflow-vgg's Caffe weights: x = v·2/255 − 1
    /// (`style_loss.py`), then (x + 1)·255/2 minus the Caffe mean of the channel (its
    /// `vgg16.py`), each step in f32 as NumPy and TensorFlow compute it. Channels stay RGB:
    /// the weights' conv1_1 is reordered instead.
    Caffe,
}

impl Preprocess {
    /// Every scaling, for parsing stored names back.
    pub const ALL: [Preprocess; 3] = [
        Preprocess::Imagenet,
        Preprocess::MinusOneToOne,
        Preprocess::Caffe,
    ];

    /// The name stored with every descriptor (`preprocess` column, unit records, Gram
    /// files): fixed here, so renaming the variant cannot change what a stored descriptor
    /// says it is. (They are the names datasets have always stored.)
    pub const fn name(self) -> &'static str {
        match self {
            Preprocess::Imagenet => "Imagenet",
            Preprocess::MinusOneToOne => "MinusOneToOne",
            Preprocess::Caffe => "Caffe",
        }
    }

    /// The scaling a stored name stands for.
    pub fn from_name(name: &str) -> Option<Preprocess> {
        Preprocess::ALL.into_iter().find(|p| p.name() == name)
    }
}

/// The Caffe means tensorflow-vgg subtracts, in RGB order (its VGG_MEAN is B, G, R).
pub const CAFFE_MEAN_RGB: [f32; 3] = [123.68, 116.779, 103.939];

/// One RGB8 sample through the published code's f32 steps (see [`Preprocess::Caffe`]).
fn caffe(v: u8, c: usize) -> f32 {
    let x = v as f32 * 2.0 / 255.0 - 1.0;
    (x + 1.0) * 255.0 / 2.0 - CAFFE_MEAN_RGB[c]
}

/// Largest image `style --image` takes as given: peak memory is about 1 KiB per pixel
/// (two relu1_2-sized f32 activations of 64 channels plus their f64 copy for the Gram), so
/// this bounds it near 2 GiB. Descriptor tiers resize first and never come near it.
pub const MAX_EXACT_PIXELS: u64 = 2 * 1024 * 1024;

/// VGG16 halves the size four times before relu5_2: smaller inputs leave no activation.
pub const MIN_SIDE: u32 = 16;

/// Read a photo as RGB in [0, 1]: 8- and 16-bit, grey or colour, alpha dropped. 16-bit
/// samples keep their precision (no round trip through 8 bits).
pub fn load_rgb01(path: &std::path::Path) -> crate::Result<image::Rgb32FImage> {
    let img = image::open(path).map_err(|e| crate::StyleError::Image {
        path: path.into(),
        problem: format!("cannot read: {e}"),
    })?;
    let (w, h) = (img.width(), img.height());
    if w < MIN_SIDE || h < MIN_SIDE {
        return Err(crate::StyleError::Image {
            path: path.into(),
            problem: format!("{w}×{h} is too small: VGG16 needs at least {MIN_SIDE}×{MIN_SIDE} pixels to reach relu5_2"),
        });
    }
    if w as u64 * h as u64 > MAX_EXACT_PIXELS {
        return Err(crate::StyleError::Image {
            path: path.into(),
            problem: format!(
                "{w}×{h} is more than {MAX_EXACT_PIXELS} pixels (about 1 KiB of memory per pixel); resize it first"
            ),
        });
    }
    Ok(img.into_rgb32f())
}

/// CHW f32 input of an RGB image already in [0, 1].
pub fn to_input_01(img: &image::Rgb32FImage, p: Preprocess) -> Vec<f32> {
    let (w, h) = (img.width() as usize, img.height() as usize);
    let mut out = vec![0f32; 3 * w * h];
    for (i, px) in img.pixels().enumerate() {
        for c in 0..3 {
            let v = px[c];
            out[c * w * h + i] = match p {
                Preprocess::Imagenet => (v - IMAGENET_MEAN[c]) / IMAGENET_STD[c],
                Preprocess::MinusOneToOne => v * 2.0 - 1.0,
                Preprocess::Caffe => (v * 2.0 - 1.0 + 1.0) * 255.0 / 2.0 - CAFFE_MEAN_RGB[c],
            };
        }
    }
    out
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
                Preprocess::Caffe => caffe(px[c], c),
            };
        }
    }
    out
}

#[cfg(test)]
mod names {
    use super::Preprocess;

    #[test]
    fn stored_names_are_fixed_and_read_back() {
        // What datasets store: changing one changes what every stored descriptor means.
        let names: Vec<&str> = Preprocess::ALL.iter().map(|p| p.name()).collect();
        assert_eq!(names, ["Imagenet", "MinusOneToOne", "Caffe"]);
        for p in Preprocess::ALL {
            assert_eq!(Preprocess::from_name(p.name()), Some(p));
        }
        assert_eq!(Preprocess::from_name("imagenet"), None);
    }
}
