//! VGG16's (or VGG19's) convolutional trunk up to relu5_2, on the CPU: 3×3 convolutions as
//! GEMMs (the `gemm` crate) over padded channels-last activations, ReLU, 2×2 max pooling.
//! Weights come from a user's safetensors file with torchvision names (`features.N.weight`
//! OIHW f32, `features.N.bias`); nothing is downloaded.

use std::path::{Path, PathBuf};

use nrw_gemm::Parallelism;

use crate::conv::{maxpool2, Conv, ConvAlgo};
use crate::error::{Result, StyleError};
use crate::tensor::Activation;

/// Which VGG: the two torchvision layouts differ only in convolutions per block.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Arch {
    Vgg16,
    Vgg19,
}

impl Arch {
    /// Convolutions per block.
    pub fn blocks(self) -> [usize; 5] {
        match self {
            Arch::Vgg16 => [2, 2, 3, 3, 3],
            Arch::Vgg19 => [2, 2, 4, 4, 4],
        }
    }

    /// `vgg16` or `vgg19`.
    pub fn name(self) -> &'static str {
        match self {
            Arch::Vgg16 => "vgg16",
            Arch::Vgg19 => "vgg19",
        }
    }

    /// (torchvision `features` index, channels out) of every convolution up to conv5_2,
    /// the last one relu5_2 needs: in `features`, each conv is followed by its ReLU and each
    /// block by a max pool.
    pub fn convs_to_relu5_2(self) -> Vec<(usize, usize)> {
        const CHANNELS: [usize; 5] = [64, 128, 256, 512, 512];
        let mut out = Vec::new();
        let mut idx = 0;
        for (b, &n) in self.blocks().iter().enumerate() {
            for j in 0..n {
                if b == 4 && j == 2 {
                    return out;
                }
                out.push((idx, CHANNELS[b]));
                idx += 2;
            }
            idx += 1;
        }
        out
    }
}

/// The ReLU outputs the paper's published code used for the style loss.
pub const STYLE_LAYERS: [&str; 5] = ["relu1_2", "relu2_2", "relu3_2", "relu4_2", "relu5_2"];

/// Which convention a weights file was trained with: it decides the input the network expects.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Convention {
    /// torchvision's (safetensors): RGB in [0, 1], ImageNet mean and std.
    Torchvision,
    /// Caffe's, as tensorflow-vgg's `vgg16.npy` (the published code's weights): 0…255 minus
    /// the Caffe means. Its conv1_1 is stored for BGR input and is reordered to RGB at load.
    Caffe,
}

/// A VGG's convolutions up to conv5_2 (the last one relu5_2 needs).
#[derive(Debug, Clone)]
pub struct Vgg {
    pub arch: Arch,
    /// The input convention of the weights, which tiers check before running.
    pub convention: Convention,
    pub convs: Vec<Conv>,
    /// How the convolutions run.
    pub algo: ConvAlgo,
    pub path: PathBuf,
    /// SHA-256 of the weights file: recorded with descriptors so incompatible ones are never mixed.
    pub sha256: String,
}

impl Vgg {
    /// Load from a safetensors file with torchvision names; every shape and dtype is checked.
    /// The architecture is recognised by its tensors (VGG19 has `features.34`, VGG16 does not).
    /// Convolutions run by the default [`ConvAlgo`].
    pub fn load(path: &Path) -> Result<Vgg> {
        Vgg::load_with(path, ConvAlgo::default())
    }

    /// [`Vgg::load`] with the convolutions run by `algo`. A NumPy `.npy` file is read as
    /// tensorflow-vgg's `vgg16.npy` (Caffe convention), anything else as safetensors.
    pub fn load_with(path: &Path, algo: ConvAlgo) -> Result<Vgg> {
        use sha2::{Digest, Sha256};
        let bytes = std::fs::read(path).map_err(|e| StyleError::Io {
            path: path.into(),
            source: e,
        })?;
        let sha256: String = Sha256::digest(&bytes)
            .iter()
            .map(|b| format!("{b:02x}"))
            .collect();
        if bytes.starts_with(b"\x93NUMPY") {
            let convs = npy_convs(path, &bytes, algo)?;
            return Ok(Vgg {
                arch: Arch::Vgg16,
                convention: Convention::Caffe,
                convs,
                algo,
                path: path.into(),
                sha256,
            });
        }
        let st =
            safetensors::SafeTensors::deserialize(&bytes).map_err(|e| StyleError::Weights {
                path: path.into(),
                problem: format!("not a safetensors file: {e}"),
            })?;
        let arch = if st.tensor("features.34.weight").is_ok() {
            Arch::Vgg19
        } else {
            Arch::Vgg16
        };
        let mut convs = Vec::new();
        let mut in_ch = 3;
        for (idx, out_ch) in arch.convs_to_relu5_2() {
            let get = |name: &str, shape: &[usize]| -> Result<Vec<f32>> {
                let t = st.tensor(name).map_err(|_| StyleError::Weights {
                    path: path.into(),
                    problem: format!(
                        "tensor `{name}` is missing (torchvision VGG16/VGG19 names expected)"
                    ),
                })?;
                if t.dtype() != safetensors::Dtype::F32 || t.shape() != shape {
                    return Err(StyleError::Weights {
                        path: path.into(),
                        problem: format!(
                            "tensor `{name}` is {:?} {:?}, expected F32 {shape:?}",
                            t.dtype(),
                            t.shape()
                        ),
                    });
                }
                Ok(t.data()
                    .chunks_exact(4)
                    .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
                    .collect())
            };
            let weight = get(&format!("features.{idx}.weight"), &[out_ch, in_ch, 3, 3])?;
            let bias = get(&format!("features.{idx}.bias"), &[out_ch])?;
            convs.push(Conv::with_algo(out_ch, in_ch, &weight, bias, algo));
            in_ch = out_ch;
        }
        Ok(Vgg {
            arch,
            convention: Convention::Torchvision,
            convs,
            algo,
            path: path.into(),
            sha256,
        })
    }

    /// The five style layers' activations for a preprocessed CHW input.
    pub fn style_features(
        &self,
        input: &[f32],
        h: usize,
        w: usize,
        par: Parallelism,
    ) -> Vec<Activation> {
        self.style_features_upto(input, h, w, 5, par)
    }

    /// The first `layers` style activations only: the trunk stops after the last one needed,
    /// so a tier on relu1_2 costs two convolutions, not twelve.
    pub fn style_features_upto(
        &self,
        input: &[f32],
        h: usize,
        w: usize,
        layers: usize,
        par: Parallelism,
    ) -> Vec<Activation> {
        let mut out = Vec::with_capacity(layers);
        self.forward(input, h, w, layers, par, |_, a| out.push(a.clone()));
        out
    }

    /// The Gram matrices (channels, f64 row-major; see [`gram`]) of the style layers listed in
    /// `taps` (indices into [`STYLE_LAYERS`], ascending), each computed while its activation
    /// is fresh in memory; the trunk stops after the last tap.
    pub fn grams_of_taps(
        &self,
        input: &[f32],
        h: usize,
        w: usize,
        taps: &[usize],
        par: Parallelism,
    ) -> Vec<(usize, Vec<f64>)> {
        let upto = taps.iter().max().map_or(0, |t| t + 1);
        let mut out = Vec::with_capacity(taps.len());
        self.forward(input, h, w, upto, par, |k, a| {
            if taps.contains(&k) {
                out.push((a.c, a.gram(par)));
            }
        });
        out
    }

    /// Runs the trunk until the first `layers` style layers have been handed to `tap` (with
    /// their index). Each activation's buffer goes back to this thread's pool once the next
    /// layer has read it.
    fn forward(
        &self,
        input: &[f32],
        h: usize,
        w: usize,
        layers: usize,
        par: Parallelism,
        mut tap: impl FnMut(usize, &Activation),
    ) {
        let blocks = self.arch.blocks();
        let mut x = Activation::from_chw(input, 3, h, w);
        let mut taken = 0;
        let mut k = 0;
        let step = |x: &mut Activation, next: Activation| {
            crate::pool::recycle(std::mem::replace(x, next).data);
        };
        for (b, &n) in blocks.iter().enumerate() {
            if taken >= layers {
                break;
            }
            if b > 0 {
                let pooled = maxpool2(&x);
                step(&mut x, pooled);
            }
            for j in 0..n {
                if k == self.convs.len() {
                    break;
                }
                let next = self.convs[k].apply(&x, par);
                step(&mut x, next);
                k += 1;
                if j == 1 {
                    tap(taken, &x); // reluB_2
                    taken += 1;
                    if taken >= layers {
                        break;
                    }
                }
            }
        }
        crate::pool::recycle(x.data);
    }
}

/// tensorflow-vgg's layer names of VGG16, in order; the first twelve reach relu5_2.
pub const VGG16_NPY_LAYERS: [&str; 16] = [
    "conv1_1", "conv1_2", "conv2_1", "conv2_2", "conv3_1", "conv3_2", "conv3_3", "conv4_1",
    "conv4_2", "conv4_3", "conv5_1", "conv5_2", "conv5_3", "fc6", "fc7", "fc8",
];

/// The convolutions up to conv5_2 of a `vgg16.npy`: W (3, 3, in, out) → OIHW, conv1_1's
/// input channels reordered from BGR to RGB (a permutation: no value changes). A key that is
/// not a VGG16 layer is refused by name.
fn npy_convs(path: &Path, bytes: &[u8], algo: ConvAlgo) -> Result<Vec<Conv>> {
    let bad = |problem: String| StyleError::Weights {
        path: path.into(),
        problem,
    };
    let layers = nrw_npy::read::read_layers(bytes).map_err(&bad)?;
    if let Some(k) = layers
        .keys()
        .find(|k| !VGG16_NPY_LAYERS.contains(&k.as_str()))
    {
        return Err(bad(format!(
            "layer '{k}' is not one of tensorflow-vgg's VGG16 layers (conv1_1 … conv5_3, fc6 … fc8)"
        )));
    }
    let mut convs = Vec::new();
    let mut in_ch = 3;
    for ((_, out_ch), name) in Arch::Vgg16
        .convs_to_relu5_2()
        .into_iter()
        .zip(VGG16_NPY_LAYERS)
    {
        let l = layers
            .get(name)
            .ok_or_else(|| bad(format!("layer '{name}' is missing")))?;
        let [w, b] = l.as_slice() else {
            return Err(bad(format!(
                "layer '{name}' has {} arrays, not [W, b]",
                l.len()
            )));
        };
        if w.shape != [3, 3, in_ch, out_ch] || b.shape != [out_ch] {
            return Err(bad(format!(
                "layer '{name}' has W {:?} and b {:?}, expected [3, 3, {in_ch}, {out_ch}] and [{out_ch}]",
                w.shape, b.shape
            )));
        }
        let mut oihw = vec![0f32; w.data.len()];
        for kh in 0..3 {
            for kw in 0..3 {
                for i in 0..in_ch {
                    // conv1_1 reads BGR in the file; our input is RGB.
                    let src_i = if in_ch == 3 { 2 - i } else { i };
                    for o in 0..out_ch {
                        oihw[((o * in_ch + i) * 3 + kh) * 3 + kw] =
                            w.data[((kh * 3 + kw) * in_ch + src_i) * out_ch + o];
                    }
                }
            }
        }
        convs.push(Conv::with_algo(out_ch, in_ch, &oihw, b.data.clone(), algo));
        in_ch = out_ch;
    }
    Ok(convs)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Naive planar 3×3 convolution (padding 1) + ReLU, in f64.
    fn conv_naive(x: &[f32], ci: usize, h: usize, w: usize, wt: &[f32], b: &[f32]) -> Vec<f64> {
        let co = b.len();
        let mut out = vec![0f64; co * h * w];
        for o in 0..co {
            for y in 0..h {
                for xx in 0..w {
                    let mut acc = b[o] as f64;
                    for i in 0..ci {
                        for ky in 0..3 {
                            for kx in 0..3 {
                                let (sy, sx) =
                                    (y as isize + ky as isize - 1, xx as isize + kx as isize - 1);
                                if sy >= 0 && sx >= 0 && (sy as usize) < h && (sx as usize) < w {
                                    acc += wt[((o * ci + i) * 3 + ky) * 3 + kx] as f64
                                        * x[(i * h + sy as usize) * w + sx as usize] as f64;
                                }
                            }
                        }
                    }
                    out[(o * h + y) * w + xx] = acc.max(0.0);
                }
            }
        }
        out
    }

    /// A seeded uniform generator in [−0.5, 0.5).
    fn rnd(seed: u64) -> impl FnMut() -> f32 {
        let mut seed = seed;
        move || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((seed >> 33) as f32 / (1u64 << 31) as f32) - 0.5
        }
    }

    #[test]
    fn channels_last_convolution_and_pooling_equal_the_planar_definition() {
        // Odd sizes (pooling floors, ragged Winograd tiles), both direct paths (im2col below
        // 16 input channels, in-place kernel rows above) and the Winograd path (which a Conv
        // only takes from 16 input channels on), every border pixel; channel counts that are
        // not multiples of the transforms' 16 lanes; sizes below one 4 × 4 tile; layers of one
        // band and of several.
        let mut rnd = rnd(1);
        for (ci, co, h, w, algo) in [
            (3, 8, 7, 5, ConvAlgo::Direct),
            (17, 6, 5, 9, ConvAlgo::Direct),
            (17, 6, 5, 9, ConvAlgo::Winograd),
            (33, 19, 13, 7, ConvAlgo::Winograd),
            (16, 16, 1, 1, ConvAlgo::Winograd),
            (20, 5, 2, 3, ConvAlgo::Winograd),
            (16, 24, 40, 30, ConvAlgo::Winograd),
            // 18 × 17 tiles: several bands of tile rows, the last one short.
            (16, 16, 70, 66, ConvAlgo::Winograd),
        ] {
            let x: Vec<f32> = (0..ci * h * w).map(|_| rnd()).collect();
            let wt: Vec<f32> = (0..co * ci * 9).map(|_| rnd()).collect();
            let b: Vec<f32> = (0..co).map(|_| rnd() * 0.1).collect();
            let conv = Conv::with_algo(co, ci, &wt, b.clone(), algo);
            assert_eq!(conv.winograd.is_some(), algo == ConvAlgo::Winograd);
            let input = Activation::from_chw(&x, ci, h, w);
            let got = conv.apply(&input, Parallelism::None);
            // Any thread count gives the same bits.
            assert_eq!(conv.apply(&input, Parallelism::Rayon(0)).data, got.data);
            let want = conv_naive(&x, ci, h, w, &wt, &b);
            let planar = got.to_chw();
            // Winograd's transforms amplify f32 rounding (its own bound is tested below).
            let tol = if algo == ConvAlgo::Winograd {
                1e-4
            } else {
                1e-5
            };
            for (g, e) in planar.iter().zip(&want) {
                assert!(
                    (*g as f64 - e).abs() < tol,
                    "{algo:?} {ci}→{co} {h}×{w}: {g} vs {e}"
                );
            }
            // The border stays zero: a Gram of the padded buffer is the Gram of the image.
            let pw = w + 2;
            for y in 0..h + 2 {
                for xx in 0..pw {
                    if y == 0 || y == h + 1 || xx == 0 || xx == pw - 1 {
                        assert!(got.data[(y * pw + xx) * co..][..co]
                            .iter()
                            .all(|v| *v == 0.0));
                    }
                }
            }
            let pooled = maxpool2(&got).to_chw();
            let (oh, ow) = (h / 2, w / 2);
            for o in 0..co {
                for y in 0..oh {
                    for xx in 0..ow {
                        let at = |yy: usize, xw: usize| planar[(o * h + yy) * w + xw];
                        let m = at(2 * y, 2 * xx)
                            .max(at(2 * y, 2 * xx + 1))
                            .max(at(2 * y + 1, 2 * xx))
                            .max(at(2 * y + 1, 2 * xx + 1));
                        assert_eq!(pooled[(o * oh + y) * ow + xx], m);
                    }
                }
            }
        }
    }

    /// The planar convolution before ReLU, f64 (for error measurements, where ReLU would hide
    /// the negative outputs' errors).
    fn conv_linear(x: &[f32], ci: usize, h: usize, w: usize, wt: &[f32], b: &[f32]) -> Vec<f64> {
        // conv_naive of (x, wt, b) minus conv_naive of (x, −wt, −b) = the linear output.
        let neg_w: Vec<f32> = wt.iter().map(|v| -v).collect();
        let neg_b: Vec<f32> = b.iter().map(|v| -v).collect();
        let pos = conv_naive(x, ci, h, w, wt, b);
        let neg = conv_naive(x, ci, h, w, &neg_w, &neg_b);
        pos.iter().zip(&neg).map(|(p, n)| p - n).collect()
    }

    #[test]
    fn winograd_errors_stay_inside_their_rigorous_bound() {
        // Wide layers (the GEMM's rounding dominates), magnitudes like VGG's after ImageNet
        // preprocessing, a ragged size. The pre-ReLU output is measured through a ReLU-free
        // pair: conv(x) and conv of negated weights, so every output's error is visible.
        let mut rnd = rnd(7);
        for (ci, co, h, w, scale) in [(64, 8, 9, 11, 4.0f32), (256, 4, 6, 5, 30.0)] {
            let x: Vec<f32> = (0..ci * h * w).map(|_| (rnd() + 0.5) * scale).collect();
            let wt: Vec<f32> = (0..co * ci * 9).map(|_| rnd() * 0.1).collect();
            let b: Vec<f32> = (0..co).map(|_| rnd() * 0.1).collect();
            let exact = conv_linear(&x, ci, h, w, &wt, &b);
            let input = Activation::from_chw(&x, ci, h, w);
            let run = |wt: &[f32], b: &[f32], algo| {
                Conv::with_algo(co, ci, wt, b.to_vec(), algo)
                    .apply(&input, Parallelism::None)
                    .to_chw()
            };
            let neg_w: Vec<f32> = wt.iter().map(|v| -v).collect();
            let neg_b: Vec<f32> = b.iter().map(|v| -v).collect();
            let linear = |algo| -> Vec<f64> {
                let (p, n) = (run(&wt, &b, algo), run(&neg_w, &neg_b, algo));
                p.iter()
                    .zip(&n)
                    .map(|(a, c)| *a as f64 - *c as f64)
                    .collect()
            };
            let bound = crate::winograd::error_bound(&x, ci, h, w, &wt, &b);
            let wino = linear(ConvAlgo::Winograd);
            let direct = linear(ConvAlgo::Direct);
            let (mut worst_ratio, mut wino_max, mut direct_max) = (0f64, 0f64, 0f64);
            for i in 0..exact.len() {
                let err = (wino[i] - exact[i]).abs();
                assert!(
                    err <= bound[i],
                    "{ci}→{co}: output {i} error {err:e} above its bound {:e}",
                    bound[i]
                );
                worst_ratio = worst_ratio.max(err / bound[i]);
                wino_max = wino_max.max(err);
                direct_max = direct_max.max((direct[i] - exact[i]).abs());
            }
            let big = exact.iter().fold(0f64, |m, v| m.max(v.abs()));
            let loosest = bound.iter().fold(0f64, |m, v| m.max(*v));
            eprintln!(
                "{ci}→{co}: max error winograd {wino_max:.2e}, direct {direct_max:.2e}, \
                 largest output {big:.2e}, loosest bound {loosest:.2e}, \
                 worst error / bound {worst_ratio:.3}"
            );
            // In practice: a few f32 ulps of the largest output, several times the direct
            // convolution's error, three orders of magnitude inside the rigorous bound.
            assert!(wino_max < 1e-5 * big, "{ci}→{co}: {wino_max:e} of {big:e}");
        }
    }

    #[test]
    fn torchvision_indices_of_both_architectures() {
        let v16: Vec<usize> = Arch::Vgg16.convs_to_relu5_2().iter().map(|c| c.0).collect();
        assert_eq!(v16, [0, 2, 5, 7, 10, 12, 14, 17, 19, 21, 24, 26]);
        let v19: Vec<usize> = Arch::Vgg19.convs_to_relu5_2().iter().map(|c| c.0).collect();
        assert_eq!(v19, [0, 2, 5, 7, 10, 12, 14, 16, 19, 21, 23, 25, 28, 30]);
    }
}
