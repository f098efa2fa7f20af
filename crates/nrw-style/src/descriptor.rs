//! Descriptors: vectors whose squared Euclidean distance *is* the style distance, so
//! nearest-neighbour search needs no Gram algebra.
//!
//! The style distance of the paper (Gatys et al.'s style loss) is Σ_layers ‖G_a − G_b‖²_F.
//! A symmetric Gram's Frobenius norm counts each off-diagonal entry twice, so the vector of
//! its upper triangle with off-diagonals scaled by √2 has the same squared norm; concatenating
//! those vectors over the layers turns the style distance into a plain squared L2 distance.

use image::RgbImage;

use crate::backend::{Backend, Grams, NetInput};
use crate::error::{Result, StyleError};
use crate::preprocess::{to_input, Preprocess, MIN_SIDE};
use crate::vgg::{Arch, STYLE_LAYERS};

/// A way of describing a photo's style, from the reference (VGG16, 512², five layers) down
/// to a cheap colour statistic.
#[derive(Debug, Clone, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Tier {
    /// VGG Grams of a centre square resized to `size` (None: the photo as it is), on the
    /// style layers whose indices (0 = relu1_2 … 4 = relu5_2) are listed.
    Vgg {
        arch: Arch,
        size: Option<u32>,
        layers: Vec<usize>,
    },
    /// Mean and covariance of RGB in [0, 1] (9 numbers): no network, no weights.
    ColorStats,
    /// The paper's published definition (`style_loss.compute_pairwise_style_loss_v2`): a
    /// `crop` × `crop` centre crop of the stored photo (no resize), input v·2/255 − 1 into
    /// the published VGG16 (tensorflow-vgg's Caffe weights and input, [`Preprocess::Caffe`]),
    /// Grams of relu1_2 … relu5_2 over C·H·W, distance Σ_layers mean((G_a − G_b)²). Each
    /// layer's packed Gram is divided by C so the squared L2 distance is that mean.
    Official { crop: u32 },
}

/// A tier shows as its name (what `--tier` and pipeline files take).
impl std::fmt::Display for Tier {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.name())
    }
}

impl std::str::FromStr for Tier {
    type Err = String;

    /// A tier by its name ([`Tier::parse`]); the error lists the forms.
    fn from_str(s: &str) -> Result<Tier, String> {
        Tier::parse(s).ok_or_else(|| {
            format!("{s:?} is not a tier: vgg16-<128|256|512|full>[-l<layers 1-5>], the same with vgg19, official[-N], or color-stats")
        })
    }
}

impl Tier {
    /// The paper's reference: VGG16, 512 × 512 centre crop, all five layers.
    pub fn reference() -> Tier {
        Tier::Vgg {
            arch: Arch::Vgg16,
            size: Some(512),
            layers: vec![0, 1, 2, 3, 4],
        }
    }

    /// The crop the published code uses by default (its README runs `train_resolution` 512).
    pub const OFFICIAL_CROP: u32 = 512;

    /// Parse `vgg16-256`, `vgg16-512-l12`, `vgg19-full`, `color-stats`, `official`,
    /// `official-256`.
    pub fn parse(s: &str) -> Option<Tier> {
        if s == "color-stats" {
            return Some(Tier::ColorStats);
        }
        if s == "official" {
            return Some(Tier::Official {
                crop: Self::OFFICIAL_CROP,
            });
        }
        if let Some(n) = s.strip_prefix("official-") {
            let crop = n.parse::<u32>().ok().filter(|&n| n >= MIN_SIDE)?;
            return Some(Tier::Official { crop });
        }
        let (arch, rest) = if let Some(r) = s.strip_prefix("vgg16-") {
            (Arch::Vgg16, r)
        } else {
            (Arch::Vgg19, s.strip_prefix("vgg19-")?)
        };
        let mut parts = rest.split("-l");
        let size = match parts.next()? {
            "full" => None,
            n => Some(n.parse::<u32>().ok().filter(|&n| n >= 16)?),
        };
        let layers = match parts.next() {
            None => vec![0, 1, 2, 3, 4],
            Some(ls) => {
                let v: Option<Vec<usize>> = ls
                    .chars()
                    .map(|c| {
                        c.to_digit(10)
                            .map(|d| d as usize)
                            .filter(|d| (1..=5).contains(d))
                            .map(|d| d - 1)
                    })
                    .collect();
                let mut v = v?;
                v.sort_unstable();
                v.dedup();
                if v.is_empty() {
                    return None;
                }
                v
            }
        };
        Some(Tier::Vgg { arch, size, layers })
    }

    /// The name `parse` reads back.
    pub fn name(&self) -> String {
        match self {
            Tier::ColorStats => "color-stats".into(),
            Tier::Official { crop } if *crop == Self::OFFICIAL_CROP => "official".into(),
            Tier::Official { crop } => format!("official-{crop}"),
            Tier::Vgg { arch, size, layers } => {
                let s = size.map_or("full".to_string(), |n| n.to_string());
                let a = arch.name();
                if layers.len() == 5 {
                    format!("{a}-{s}")
                } else {
                    let ls: String = layers.iter().map(|l| (l + 1).to_string()).collect();
                    format!("{a}-{s}-l{ls}")
                }
            }
        }
    }

    /// Whether this tier needs network weights.
    pub fn needs_weights(&self) -> bool {
        self.arch().is_some()
    }

    /// The network the tier runs, if any.
    pub fn arch(&self) -> Option<Arch> {
        match self {
            Tier::Vgg { arch, .. } => Some(*arch),
            Tier::Official { .. } => Some(Arch::Vgg16),
            Tier::ColorStats => None,
        }
    }

    /// The input scaling the tier runs with: the official tier fixes its own (the published
    /// code's, into Caffe weights), the others take the caller's.
    pub fn preprocess(&self, asked: Preprocess) -> Preprocess {
        match self {
            Tier::Official { .. } => Preprocess::Caffe,
            _ => asked,
        }
    }

    /// The style layers (indices into [`STYLE_LAYERS`], ascending, once each) whose Grams
    /// the descriptor packs: all five for the official tier, the tier's own for VGG tiers.
    pub fn taps(&self) -> Vec<usize> {
        match self {
            Tier::Official { .. } => (0..STYLE_LAYERS.len()).collect(),
            Tier::Vgg { layers, .. } => {
                let mut taps = layers.clone();
                taps.sort_unstable();
                taps.dedup();
                debug_assert!(taps.iter().all(|t| *t < STYLE_LAYERS.len()));
                taps
            }
            Tier::ColorStats => Vec::new(),
        }
    }

    /// The weights convention the tier needs: the official tier reproduces the published
    /// code, which runs tensorflow-vgg's Caffe weights; the others run torchvision's.
    pub fn convention(&self) -> Option<crate::Convention> {
        match self {
            Tier::Official { .. } => Some(crate::Convention::Caffe),
            Tier::Vgg { .. } => Some(crate::Convention::Torchvision),
            Tier::ColorStats => None,
        }
    }
}

/// `crop` × `crop` pixels from the centre, placed as the published `utils.get_central_crop`
/// places them (start = (side − crop) // 2), or None when the photo is smaller.
pub fn central_crop(photo: &RgbImage, crop: u32) -> Option<RgbImage> {
    let (w, h) = (photo.width(), photo.height());
    if w < crop || h < crop {
        return None;
    }
    Some(image::imageops::crop_imm(photo, (w - crop) / 2, (h - crop) / 2, crop, crop).to_image())
}

/// Upper triangle of a symmetric c × c matrix, off-diagonals times √2 (norm-preserving).
pub fn pack_symmetric(c: usize, g: &[f64], out: &mut Vec<f32>) {
    pack_symmetric_scaled(c, g, 1.0, out);
}

/// `pack_symmetric` of `scale` · g, scaled in f64 before the one rounding to f32 (where the
/// descriptor gives up precision).
pub fn pack_symmetric_scaled(c: usize, g: &[f64], scale: f64, out: &mut Vec<f32>) {
    let off = std::f64::consts::SQRT_2 * scale;
    for i in 0..c {
        out.push((g[i * c + i] * scale) as f32);
        for j in i + 1..c {
            out.push((g[i * c + j] * off) as f32);
        }
    }
}

/// The square centre of a photo resized to `size` (Lanczos3), or the photo itself.
pub fn prepare(photo: &RgbImage, size: Option<u32>) -> RgbImage {
    let Some(s) = size else { return photo.clone() };
    let side = photo.width().min(photo.height());
    let (x, y) = ((photo.width() - side) / 2, (photo.height() - side) / 2);
    let square = image::imageops::crop_imm(photo, x, y, side, side).to_image();
    if side == s {
        return square;
    }
    image::imageops::resize(&square, s, s, image::imageops::FilterType::Lanczos3)
}

/// The descriptor of a photo under a tier (`net` is required for VGG tiers; `pre` is the
/// network's input scaling and does not affect `color-stats`): [`network_input`], the
/// backend, [`from_grams`], for one photo. The style stage batches the same three steps.
pub fn describe<B: Backend + ?Sized>(
    tier: &Tier,
    net: Option<&B>,
    photo: &RgbImage,
    pre: Preprocess,
) -> Result<Vec<f32>> {
    let Some(input) = network_input(tier, photo, pre)? else {
        return Ok(color_stats(photo));
    };
    let net = net.expect("VGG tiers need weights (checked by the caller)");
    check_arch(tier, net);
    let grams = crate::backend::grams_of_one(net, &input, &tier.taps())?;
    Ok(from_grams(tier, &grams))
}

/// The architecture a tier runs is the one the weights hold (the caller checked it when it
/// loaded them; a mismatch here is a bug).
pub(crate) fn check_arch<B: Backend + ?Sized>(tier: &Tier, net: &B) {
    let Some(want) = tier.arch() else {
        return;
    };
    assert_eq!(
        net.arch(),
        want,
        "weights and tier architecture (checked by the caller)"
    );
}

/// What a tier feeds its network for a photo: the crop or resize and the input scaling; None
/// for `color-stats`, which has no network. A `-full` tier refuses photos under 16 × 16:
/// pooling would leave no pixel for the deep Grams, whose normalisation would then divide by
/// zero.
pub fn network_input(tier: &Tier, photo: &RgbImage, pre: Preprocess) -> Result<Option<NetInput>> {
    let img = match tier {
        Tier::ColorStats => return Ok(None),
        Tier::Official { crop } => {
            central_crop(photo, *crop).ok_or_else(|| StyleError::SmallerThanCrop {
                width: photo.width(),
                height: photo.height(),
                crop: *crop,
            })?
        }
        Tier::Vgg { size: None, .. } if photo.width().min(photo.height()) < MIN_SIDE => {
            return Err(StyleError::TooSmall {
                width: photo.width(),
                height: photo.height(),
                tier: tier.name(),
            });
        }
        Tier::Vgg { size, .. } => prepare(photo, *size),
    };
    Ok(Some(NetInput {
        chw: to_input(&img, tier.preprocess(pre)),
        height: img.height() as usize,
        width: img.width() as usize,
    }))
}

/// The descriptor from a photo's Grams at [`Tier::taps`] (VGG and official tiers).
pub fn from_grams(tier: &Tier, grams: &Grams) -> Vec<f32> {
    let mut out = Vec::new();
    for (c, g) in grams {
        match tier {
            // mean over the C × C entries = ‖·‖²_F / C², so each Gram is scaled by 1/C.
            Tier::Official { .. } => pack_symmetric_scaled(*c, g, 1.0 / *c as f64, &mut out),
            _ => pack_symmetric(*c, g, &mut out),
        }
    }
    out
}

/// Mean and covariance of a photo's RGB in [0, 1], summed in f64: the `color-stats` descriptor.
pub fn color_stats(photo: &RgbImage) -> Vec<f32> {
    let n = (photo.width() * photo.height()) as f64;
    let mut mean = [0f64; 3];
    for p in photo.pixels() {
        for c in 0..3 {
            mean[c] += p[c] as f64 / 255.0;
        }
    }
    mean.iter_mut().for_each(|m| *m /= n);
    let mut cov = [0f64; 9];
    for p in photo.pixels() {
        let d = [
            p[0] as f64 / 255.0 - mean[0],
            p[1] as f64 / 255.0 - mean[1],
            p[2] as f64 / 255.0 - mean[2],
        ];
        for i in 0..3 {
            for j in 0..3 {
                cov[i * 3 + j] += d[i] * d[j] / n;
            }
        }
    }
    let mut out: Vec<f32> = mean.iter().map(|v| *v as f32).collect();
    pack_symmetric(3, &cov, &mut out);
    out
}

/// Squared L2 distance, accumulated in f64.
pub fn distance2(a: &[f32], b: &[f32]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (*x as f64 - *y as f64).powi(2))
        .sum()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::vgg::Vgg;

    /// A backend that is not a VGG: the seam a GPU backend would use.
    struct Fake;

    impl Backend for Fake {
        fn arch(&self) -> Arch {
            Arch::Vgg16
        }
        fn weights_sha256(&self) -> &str {
            "fake"
        }
        fn device(&self) -> String {
            "fake".into()
        }
        fn batch_size(&self) -> usize {
            1
        }
        fn style_grams(&self, batch: &[NetInput], taps: &[usize]) -> Result<Vec<Grams>> {
            // Grams of 2 channels whose entries record the tap and the input size.
            Ok(batch
                .iter()
                .map(|x| {
                    taps.iter()
                        .map(|&t| (2, vec![t as f64, 1.0, 1.0, (x.height * x.width) as f64]))
                        .collect()
                })
                .collect())
        }
    }

    #[test]
    fn descriptors_come_through_any_backend() {
        let tier = Tier::parse("vgg16-128-l25").unwrap();
        let photo = RgbImage::new(300, 200);
        let d = describe(&tier, Some(&Fake), &photo, Preprocess::Imagenet);
        // Taps relu2_2 and relu5_2 (indices 1 and 4), the photo resized to 128²; each packed
        // as the upper triangle with the off-diagonal × √2.
        let s2 = std::f32::consts::SQRT_2;
        assert_eq!(
            d.unwrap(),
            vec![1.0, s2, 16384.0, 4.0, s2, 16384.0],
            "taps, order and packing"
        );
    }

    #[test]
    fn packed_distance_is_the_frobenius_distance() {
        let c = 4;
        let sym = |seed: f64| {
            let mut g = vec![0.0; c * c];
            for i in 0..c {
                for j in i..c {
                    let v = ((i * 7 + j * 3) as f64 * seed).sin();
                    g[i * c + j] = v;
                    g[j * c + i] = v;
                }
            }
            g
        };
        let (a, b) = (sym(1.3), sym(0.7));
        let frob: f64 = a.iter().zip(&b).map(|(x, y)| (x - y).powi(2)).sum();
        let (mut pa, mut pb) = (Vec::new(), Vec::new());
        pack_symmetric(c, &a, &mut pa);
        pack_symmetric(c, &b, &mut pb);
        assert_eq!(pa.len(), c * (c + 1) / 2);
        assert!((distance2(&pa, &pb) - frob).abs() < 1e-6 * frob);
    }

    #[test]
    fn tier_names_round_trip() {
        for s in [
            "vgg16-512",
            "vgg16-256-l12",
            "vgg16-full",
            "vgg16-128-l5",
            "color-stats",
            "official",
            "official-256",
        ] {
            assert_eq!(Tier::parse(s).unwrap().name(), s);
        }
        assert_eq!(
            Tier::parse("official-512").unwrap(),
            Tier::Official { crop: 512 }
        );
        assert_eq!(Tier::parse("vgg16-512").unwrap(), Tier::reference());
        for bad in [
            "vgg16-8",
            "vgg16-256-l9",
            "vgg11-256",
            "vgg16-",
            "colour",
            "official-8",
            "official-",
        ] {
            assert!(Tier::parse(bad).is_none(), "{bad}");
        }
    }

    #[test]
    fn color_stats_of_a_constant_photo_have_zero_covariance() {
        let img = RgbImage::from_pixel(10, 10, image::Rgb([255, 0, 51]));
        let d = describe(&Tier::ColorStats, None::<&Vgg>, &img, Preprocess::Imagenet).unwrap();
        assert_eq!(d.len(), 9);
        assert!((d[0] - 1.0).abs() < 1e-6 && d[1].abs() < 1e-6 && (d[2] - 0.2).abs() < 1e-6);
        assert!(d[3..].iter().all(|v| v.abs() < 1e-9));
    }
}
