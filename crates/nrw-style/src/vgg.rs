//! VGG16's (or VGG19's) convolutional trunk up to relu5_2, on the CPU: 3×3 convolutions as banded
//! im2col + GEMM (the `gemm` crate), ReLU, 2×2 max pooling. Weights come from a user's
//! safetensors file with torchvision names (`features.N.weight` OIHW f32, `features.N.bias`);
//! nothing is downloaded.

use std::path::{Path, PathBuf};

use gemm::Parallelism;
use rayon::prelude::*;

use crate::error::{Result, StyleError};

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

/// One convolution: weights as an O × (I·9) matrix and a bias per output channel.
#[derive(Debug, Clone)]
pub struct Conv {
    pub out_ch: usize,
    pub in_ch: usize,
    pub weight: Vec<f32>,
    pub bias: Vec<f32>,
}

/// A VGG's convolutions up to conv5_2 (the last one relu5_2 needs).
#[derive(Debug, Clone)]
pub struct Vgg {
    pub arch: Arch,
    pub convs: Vec<Conv>,
    pub path: PathBuf,
    /// SHA-256 of the weights file: recorded with descriptors so incompatible ones are never mixed.
    pub sha256: String,
}

impl Vgg {
    /// Load from a safetensors file with torchvision names; every shape and dtype is checked.
    /// The architecture is recognised by its tensors (VGG19 has `features.34`, VGG16 does not).
    pub fn load(path: &Path) -> Result<Vgg> {
        use sha2::{Digest, Sha256};
        let bytes = std::fs::read(path).map_err(|e| StyleError::Io {
            path: path.into(),
            source: e,
        })?;
        let sha256 = Sha256::digest(&bytes)
            .iter()
            .map(|b| format!("{b:02x}"))
            .collect();
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
            convs.push(Conv {
                out_ch,
                in_ch,
                weight,
                bias,
            });
            in_ch = out_ch;
        }
        Ok(Vgg {
            arch,
            convs,
            path: path.into(),
            sha256,
        })
    }

    /// The five style layers' activations (C, H, W, data CHW) for a preprocessed CHW input.
    pub fn style_features(
        &self,
        input: &[f32],
        h: usize,
        w: usize,
        par: Parallelism,
    ) -> Vec<(usize, usize, usize, Vec<f32>)> {
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
    ) -> Vec<(usize, usize, usize, Vec<f32>)> {
        // Blocks of VGG16: convs per block; a pool precedes every block but the first.
        let blocks = self.arch.blocks();
        let mut x = input.to_vec();
        let (mut c, mut h, mut w) = (3usize, h, w);
        let mut out = Vec::with_capacity(5);
        let mut k = 0;
        for (b, &n) in blocks.iter().enumerate() {
            if out.len() >= layers {
                break;
            }
            if b > 0 {
                (x, h, w) = maxpool2(&x, c, h, w);
            }
            for j in 0..n {
                if k == self.convs.len() {
                    break;
                }
                x = conv3x3_relu(&self.convs[k], &x, h, w, par);
                c = self.convs[k].out_ch;
                k += 1;
                if j == 1 {
                    out.push((c, h, w, x.clone())); // reluB_2
                    if out.len() >= layers {
                        break;
                    }
                }
            }
        }
        out
    }
}

/// 3×3 convolution, stride 1, padding 1, then ReLU. Banded im2col bounds the scratch memory
/// to about 16 MB whatever the image size. (Running bands in parallel, each with a
/// single-threaded GEMM, measured no faster than one band at a time with a parallel GEMM.)
pub fn conv3x3_relu(conv: &Conv, x: &[f32], h: usize, w: usize, par: Parallelism) -> Vec<f32> {
    let (ci, co) = (conv.in_ch, conv.out_ch);
    let k = ci * 9;
    let mut out = vec![0f32; co * h * w];
    let band_rows = ((4 << 20) / (k * w).max(1)).clamp(1, h.max(1));
    let bands: Vec<(usize, usize)> = (0..h)
        .step_by(band_rows)
        .map(|y0| (y0, band_rows.min(h - y0)))
        .collect();
    let mut scratch = vec![0f32; k * band_rows * w];
    for &(y0, rows) in &bands {
        let n = rows * w;
        let cols = &mut scratch[..k * n];
        // One channel's 9 shifted copies are contiguous (rows c·9 … c·9 + 8): with a parallel
        // GEMM the copies run in parallel too, or they would serialise a third of the time.
        let fill = |(c, chunk): (usize, &mut [f32])| {
            let plane = &x[c * h * w..(c + 1) * h * w];
            for ky in 0..3 {
                for kx in 0..3 {
                    let row = &mut chunk[(ky * 3 + kx) * n..(ky * 3 + kx + 1) * n];
                    for yy in 0..rows {
                        let sy = (y0 + yy + ky) as isize - 1;
                        let dst = &mut row[yy * w..(yy + 1) * w];
                        if sy < 0 || sy >= h as isize {
                            dst.fill(0.0);
                            continue;
                        }
                        let src = &plane[sy as usize * w..(sy as usize + 1) * w];
                        // dst[x] = src[x + kx - 1], zero outside.
                        match kx {
                            0 => {
                                dst[0] = 0.0;
                                dst[1..].copy_from_slice(&src[..w - 1]);
                            }
                            1 => dst.copy_from_slice(src),
                            _ => {
                                dst[..w - 1].copy_from_slice(&src[1..]);
                                dst[w - 1] = 0.0;
                            }
                        }
                    }
                }
            }
        };
        if matches!(par, Parallelism::None) {
            cols.chunks_mut(9 * n).enumerate().for_each(fill);
        } else {
            cols.par_chunks_mut(9 * n).enumerate().for_each(fill);
        }
        // out[o, y0.., :] (O × n, row stride h·w) = W (O × k) · cols (k × n)
        // SAFETY: dimensions and strides describe exactly the slices passed: dst has co rows
        // of h·w with n ≤ h·w − y0·w columns available from offset y0·w; lhs is co × k
        // row-major; rhs is k × n row-major.
        unsafe {
            gemm::gemm(
                co,
                n,
                k,
                out.as_mut_ptr().add(y0 * w),
                1,
                (h * w) as isize,
                false,
                conv.weight.as_ptr(),
                1,
                k as isize,
                cols.as_ptr(),
                1,
                n as isize,
                0.0,
                1.0,
                false,
                false,
                false,
                par,
            );
        }
    }
    let bias_relu = |(o, plane): (usize, &mut [f32])| {
        let b = conv.bias[o];
        for v in plane {
            *v = (*v + b).max(0.0);
        }
    };
    if matches!(par, Parallelism::None) {
        out.chunks_mut(h * w).enumerate().for_each(bias_relu);
    } else {
        out.par_chunks_mut(h * w).enumerate().for_each(bias_relu);
    }
    out
}

/// 2×2 max pooling, stride 2, floor mode (PyTorch's default); channels in parallel.
pub fn maxpool2(x: &[f32], c: usize, h: usize, w: usize) -> (Vec<f32>, usize, usize) {
    let (oh, ow) = (h / 2, w / 2);
    let mut out = vec![0f32; c * oh * ow];
    if oh * ow == 0 {
        return (out, oh, ow);
    }
    out.par_chunks_mut(oh * ow).enumerate().for_each(|(ch, o)| {
        let p = &x[ch * h * w..];
        for y in 0..oh {
            for xx in 0..ow {
                let i = (2 * y) * w + 2 * xx;
                o[y * ow + xx] = p[i].max(p[i + 1]).max(p[i + w]).max(p[i + w + 1]);
            }
        }
    });
    (out, oh, ow)
}

/// Gram matrix G = F Fᵀ / (C·H·W) of a C × (H·W) activation, accumulated in f64.
///
/// F is converted to f64 a block of columns at a time (2 MB, not a copy of the whole
/// activation) and the partial Grams are summed. Blocks are dealt to `GRAM_GROUPS` fixed
/// groups whose sums are added in a fixed order, so the result does not depend on the thread
/// count. A single c × c × (H·W) GEMM was 4× slower: a 64 × 64 output with a 262,144-long inner
/// dimension gives the GEMM nothing to parallelise or block on.
pub fn gram(c: usize, h: usize, w: usize, f: &[f32], par: Parallelism) -> Vec<f64> {
    const BLOCK: usize = 4096;
    const GRAM_GROUPS: usize = 8;
    let n = h * w;
    let blocks = n.div_ceil(BLOCK);
    // Deep layers have one block (n ≤ 4096) but a large c: there the GEMM itself is parallel.
    let inner = if blocks == 1 { par } else { Parallelism::None };
    let group = |gi: usize| -> Vec<f64> {
        let mut g = vec![0f64; c * c];
        let mut buf = Vec::new();
        for bi in (gi..blocks).step_by(GRAM_GROUPS) {
            let (j0, j1) = (bi * BLOCK, ((bi + 1) * BLOCK).min(n));
            let m = j1 - j0;
            buf.clear();
            for row in 0..c {
                buf.extend(f[row * n + j0..row * n + j1].iter().map(|&v| v as f64));
            }
            // g += B Bᵀ with B = F[:, j0..j1] (c × m, row-major in buf).
            // SAFETY: g is c × c row-major; lhs is B (c × m, row stride m); rhs is Bᵀ
            // (m × c): element (k, j) at j·m + k, row stride 1, column stride m.
            unsafe {
                gemm::gemm(
                    c,
                    c,
                    m,
                    g.as_mut_ptr(),
                    1,
                    c as isize,
                    true,
                    buf.as_ptr(),
                    1,
                    m as isize,
                    buf.as_ptr(),
                    m as isize,
                    1,
                    1.0,
                    1.0,
                    false,
                    false,
                    false,
                    inner,
                );
            }
        }
        g
    };
    let parts: Vec<Vec<f64>> = if matches!(par, Parallelism::None) {
        (0..GRAM_GROUPS).map(group).collect()
    } else {
        (0..GRAM_GROUPS).into_par_iter().map(group).collect()
    };
    let scale = 1.0 / (c * n) as f64;
    let mut g = vec![0f64; c * c];
    for p in &parts {
        g.iter_mut().zip(p).for_each(|(a, b)| *a += b);
    }
    g.iter_mut().for_each(|v| *v *= scale);
    g
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn torchvision_indices_of_both_architectures() {
        let v16: Vec<usize> = Arch::Vgg16.convs_to_relu5_2().iter().map(|c| c.0).collect();
        assert_eq!(v16, [0, 2, 5, 7, 10, 12, 14, 17, 19, 21, 24, 26]);
        let v19: Vec<usize> = Arch::Vgg19.convs_to_relu5_2().iter().map(|c| c.0).collect();
        assert_eq!(v19, [0, 2, 5, 7, 10, 12, 14, 16, 19, 21, 23, 25, 28, 30]);
    }
}
