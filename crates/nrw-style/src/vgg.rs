//! VGG16's (or VGG19's) convolutional trunk up to relu5_2, on the CPU: 3×3 convolutions as
//! GEMMs (the `gemm` crate) over padded channels-last activations, ReLU, 2×2 max pooling.
//! Weights come from a user's safetensors file with torchvision names (`features.N.weight`
//! OIHW f32, `features.N.bias`); nothing is downloaded.

use std::path::{Path, PathBuf};

use gemm::Parallelism;
use rayon::prelude::*;

use crate::error::{Result, StyleError};
use crate::winograd::WinogradConv;

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

/// How the 3 × 3 convolutions are computed. Both agree with PyTorch's float64 Grams within the
/// parity tests' 1e-4; `cargo bench -p nrw-style --bench vs_torch` tables their time and error.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum ConvAlgo {
    /// Three GEMMs per convolution over the input read in place (9 multiplications per
    /// output, input and output channel).
    Direct,
    /// Winograd F(4×4, 3×3) wherever a layer has ≥ 16 input channels (2.25 multiplications);
    /// conv1_1's 3 input channels stay direct.
    #[default]
    Winograd,
}

impl ConvAlgo {
    /// `direct` or `winograd`.
    pub fn name(self) -> &'static str {
        match self {
            ConvAlgo::Direct => "direct",
            ConvAlgo::Winograd => "winograd",
        }
    }
}

/// The ReLU outputs the paper's published code used for the style loss.
pub const STYLE_LAYERS: [&str; 5] = ["relu1_2", "relu2_2", "relu3_2", "relu4_2", "relu5_2"];

/// One convolution: torchvision's O × I × 3 × 3 weights, rearranged for channels-last
/// GEMMs, and a bias per output channel.
#[derive(Debug, Clone)]
pub struct Conv {
    pub out_ch: usize,
    pub in_ch: usize,
    /// Per kernel row ky, a (3·I) × O row-major matrix: row kx·I + i, column o holds
    /// weight[o, i, ky, kx] (the order in which a channels-last input row lists the 3 × I
    /// values a kernel row sees).
    pub rows: [Vec<f32>; 3],
    pub bias: Vec<f32>,
    /// The same weights in the Winograd domain, when the network runs [`ConvAlgo::Winograd`]
    /// and the layer has ≥ 16 input channels.
    pub winograd: Option<WinogradConv>,
}

impl Conv {
    /// From torchvision's OIHW layout.
    pub fn from_oihw(out_ch: usize, in_ch: usize, weight: &[f32], bias: Vec<f32>) -> Conv {
        let rows = std::array::from_fn(|ky| {
            let mut m = vec![0f32; 3 * in_ch * out_ch];
            for o in 0..out_ch {
                for i in 0..in_ch {
                    for kx in 0..3 {
                        m[(kx * in_ch + i) * out_ch + o] =
                            weight[((o * in_ch + i) * 3 + ky) * 3 + kx];
                    }
                }
            }
            m
        });
        Conv {
            out_ch,
            in_ch,
            rows,
            bias,
            winograd: None,
        }
    }

    /// From torchvision's OIHW layout, with the Winograd form when `algo` asks for it and the
    /// layer is wide enough to profit (≥ 16 input channels).
    pub fn with_algo(
        out_ch: usize,
        in_ch: usize,
        weight: &[f32],
        bias: Vec<f32>,
        algo: ConvAlgo,
    ) -> Conv {
        let mut conv = Conv::from_oihw(out_ch, in_ch, weight, bias);
        if algo == ConvAlgo::Winograd && in_ch >= 16 {
            conv.winograd = Some(WinogradConv::from_oihw(
                out_ch,
                in_ch,
                weight,
                conv.bias.clone(),
            ));
        }
        conv
    }

    /// This convolution + bias + ReLU of `x`, by the algorithm it was built for.
    pub fn apply(&self, x: &Activation, par: Parallelism) -> Activation {
        match &self.winograd {
            Some(w) => crate::winograd::conv3x3_relu(w, x, par),
            None => conv3x3_relu(self, x, par),
        }
    }
}

/// An activation in channels-last layout with a one-pixel zero border: pixel (y, x) of the
/// image is at padded (y + 1, x + 1), its c values contiguous. The border lets a 3×3
/// convolution read its input as strided matrices (no im2col copy) and adds nothing to Grams.
#[derive(Debug, Clone)]
pub struct Activation {
    pub c: usize,
    pub h: usize,
    pub w: usize,
    /// (h + 2) × (w + 2) × c values.
    pub data: Vec<f32>,
}

impl Activation {
    /// From a planar CHW input (the preprocessed photo).
    pub fn from_chw(x: &[f32], c: usize, h: usize, w: usize) -> Activation {
        let pw = w + 2;
        let mut data = vec![0f32; (h + 2) * pw * c];
        for ch in 0..c {
            for y in 0..h {
                for xx in 0..w {
                    data[((y + 1) * pw + xx + 1) * c + ch] = x[(ch * h + y) * w + xx];
                }
            }
        }
        Activation { c, h, w, data }
    }

    /// Planar CHW copy (torch's layout, for comparisons).
    pub fn to_chw(&self) -> Vec<f32> {
        let (c, h, w, pw) = (self.c, self.h, self.w, self.w + 2);
        let mut out = vec![0f32; c * h * w];
        for y in 0..h {
            for xx in 0..w {
                let px = &self.data[((y + 1) * pw + xx + 1) * c..][..c];
                for (ch, v) in px.iter().enumerate() {
                    out[(ch * h + y) * w + xx] = *v;
                }
            }
        }
        out
    }

    /// Its Gram matrix, f64 (see [`gram`]); the zero border adds nothing.
    pub fn gram(&self, par: Parallelism) -> Vec<f64> {
        gram(self.c, self.h * self.w, &self.data, par)
    }
}

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
    pub fn style_grams(
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

/// 3×3 convolution, stride 1, padding 1, then ReLU, as three GEMMs (one per kernel row) that
/// read the padded channels-last input in place: output pixel p (on the padded grid) sees
/// the 3·I values starting at input pixel p − (w + 3) + ky·(w + 2), so a kernel row's input
/// is a matrix with row stride I over the buffer itself. No im2col copy and no scratch memory
/// (the planar im2col version copied every input 9× and ran the first layers at 105–145
/// GFLOPS). The two pixels per row that straddle the border are computed, then zeroed.
pub fn conv3x3_relu(conv: &Conv, x: &Activation, par: Parallelism) -> Activation {
    let (ci, co, h, w) = (conv.in_ch, conv.out_ch, x.h, x.w);
    assert_eq!(x.c, ci, "input channels");
    let pw = w + 2;
    let mut out = crate::pool::zeroed((h + 2) * pw * co);
    // Output rows: the h·pw − 2 consecutive padded pixels from (1, 1) to (h, w).
    let m = h * pw - 2;
    if ci < 16 {
        // Few input channels (the photo's 3): K = 3·I would starve the GEMM, so gather the
        // three kernel rows into one im2col matrix (m × 9·I, 108 bytes per pixel for RGB)
        // and run a single GEMM against the stacked kernel rows.
        let k = 9 * ci;
        let mut cols = crate::pool::overwritten(m * k);
        let gather = |(q, row): (usize, &mut [f32])| {
            for ky in 0..3 {
                let at = (q + ky * pw) * ci;
                row[ky * 3 * ci..(ky + 1) * 3 * ci].copy_from_slice(&x.data[at..at + 3 * ci]);
            }
        };
        if matches!(par, Parallelism::None) {
            cols.chunks_mut(k).enumerate().for_each(gather);
        } else {
            cols.par_chunks_mut(k).enumerate().for_each(gather);
        }
        let weights = conv.rows.concat();
        dst_plus_lhs_rhs(
            &mut out[(pw + 1) * co..],
            m,
            co,
            k,
            &cols,
            k,
            &weights,
            false,
            par,
        );
        crate::pool::recycle(cols);
    } else {
        let k = 3 * ci;
        for (ky, wk) in conv.rows.iter().enumerate() {
            // Kernel row ky reads the input from pixel ky·pw with row stride ci; for ky = 2
            // its last row ends exactly at the buffer's end.
            let lhs = &x.data[ky * pw * ci..];
            dst_plus_lhs_rhs(
                &mut out[(pw + 1) * co..],
                m,
                co,
                k,
                lhs,
                ci,
                wk,
                ky > 0,
                par,
            );
        }
    }
    // Bias and ReLU on image pixels; the border columns (written by the straddling pixels)
    // back to zero.
    let bias_relu = |(y, row): (usize, &mut [f32])| {
        if y == 0 || y == h + 1 {
            return;
        }
        row[..co].fill(0.0);
        row[(pw - 1) * co..].fill(0.0);
        for px in row[co..(pw - 1) * co].chunks_exact_mut(co) {
            for (v, b) in px.iter_mut().zip(&conv.bias) {
                *v = (*v + b).max(0.0);
            }
        }
    };
    if matches!(par, Parallelism::None) {
        out.chunks_mut(pw * co).enumerate().for_each(bias_relu);
    } else {
        out.par_chunks_mut(pw * co).enumerate().for_each(bias_relu);
    }
    Activation {
        c: co,
        h,
        w,
        data: out,
    }
}

/// dst (m × n, row-major) = [dst +] lhs · rhs, where lhs holds m rows of k values `lhs_rs`
/// apart (rows may overlap: a convolution's input read in place) and rhs is k × n row-major.
/// Lengths are checked, so the GEMM cannot touch memory outside the slices.
#[allow(clippy::too_many_arguments)]
fn dst_plus_lhs_rhs(
    dst: &mut [f32],
    m: usize,
    n: usize,
    k: usize,
    lhs: &[f32],
    lhs_rs: usize,
    rhs: &[f32],
    accumulate: bool,
    par: Parallelism,
) {
    if m == 0 {
        return;
    }
    assert!(dst.len() >= m * n && rhs.len() >= k * n);
    assert!(lhs.len() >= (m - 1) * lhs_rs + k);
    // SAFETY: dst element (i, j) is dst[i·n + j], lhs element (i, t) is lhs[i·lhs_rs + t],
    // rhs element (t, j) is rhs[t·n + j]: all inside the slices by the asserts above.
    unsafe {
        gemm::gemm(
            m,
            n,
            k,
            dst.as_mut_ptr(),
            1,
            n as isize,
            accumulate,
            lhs.as_ptr(),
            1,
            lhs_rs as isize,
            rhs.as_ptr(),
            1,
            n as isize,
            1.0,
            1.0,
            false,
            false,
            false,
            par,
        );
    }
}

/// The operands of one GEMM dst = lhs · rhs with row strides: dst is m rows of n values
/// `dst_rs` apart from a raw pointer (parallel GEMMs may write interleaved rows of one
/// buffer), lhs m rows of k values `lhs_rs` apart, rhs k × n row-major.
pub(crate) struct GemmOperands<'a> {
    pub dst: *mut f32,
    /// Elements writable from `dst`.
    pub dst_len: usize,
    pub dst_rs: usize,
    pub m: usize,
    pub n: usize,
    pub k: usize,
    pub lhs: &'a [f32],
    pub lhs_rs: usize,
    pub rhs: &'a [f32],
}

/// dst = lhs · rhs on one thread (callers parallelise across GEMMs, so the result never
/// depends on the thread count). Extents are checked against the slices and `dst_len`.
pub(crate) fn gemm_strided(g: GemmOperands) {
    let GemmOperands {
        dst,
        dst_len,
        dst_rs,
        m,
        n,
        k,
        lhs,
        lhs_rs,
        rhs,
    } = g;
    if m == 0 {
        return;
    }
    assert!(dst_len >= (m - 1) * dst_rs + n && rhs.len() >= k * n);
    assert!(lhs.len() >= (m - 1) * lhs_rs + k);
    // SAFETY: dst (i, j) is dst[i·dst_rs + j] < dst_len, lhs (i, t) is lhs[i·lhs_rs + t], rhs
    // (t, j) is rhs[t·n + j]: all inside by the asserts above; the caller guarantees that no
    // other thread writes the elements this GEMM writes.
    unsafe {
        gemm::gemm(
            m,
            n,
            k,
            dst,
            1,
            dst_rs as isize,
            false,
            lhs.as_ptr(),
            1,
            lhs_rs as isize,
            rhs.as_ptr(),
            1,
            n as isize,
            0.0,
            1.0,
            false,
            false,
            false,
            Parallelism::None,
        );
    }
}

/// 2×2 max pooling, stride 2, floor mode (PyTorch's default); rows in parallel.
pub fn maxpool2(x: &Activation) -> Activation {
    let (c, oh, ow) = (x.c, x.h / 2, x.w / 2);
    let (pw, opw) = (x.w + 2, ow + 2);
    let mut out = crate::pool::bordered(oh, ow, c);
    out.par_chunks_mut(opw * c)
        .enumerate()
        .for_each(|(oy, row)| {
            if oy == 0 || oy > oh {
                return;
            }
            let y = 2 * oy - 1; // padded input row of the window's top
            let px = |yy: usize, xx: usize| &x.data[(yy * pw + xx) * c..][..c];
            for ox in 0..ow {
                let (a, b) = (px(y, 2 * ox + 1), px(y, 2 * ox + 2));
                let (d, e) = (px(y + 1, 2 * ox + 1), px(y + 1, 2 * ox + 2));
                let o = &mut row[(ox + 1) * c..(ox + 2) * c];
                for ch in 0..c {
                    o[ch] = a[ch].max(b[ch]).max(d[ch]).max(e[ch]);
                }
            }
        });
    Activation {
        c,
        h: oh,
        w: ow,
        data: out,
    }
}

/// Gram matrix G = F Fᵀ / (C·n) of n pixels with C channels each, given channels-last
/// (`f` may hold more C-long pixels than n, all zero, such as a border: they add nothing).
///
/// Precision is given up here, a little: each block of pixels is one f32 GEMM read in place,
/// and the blocks' partial Grams are summed in f64. Post-ReLU activations are ≥ 0, so every
/// product is ≥ 0 and a block's rounding error is at most γ_b ≈ b·2⁻²⁴ of the entry itself
/// for a block of b ≤ 4,096 pixels (typically ~10⁻⁶, the size of the f32 activations' own
/// error; the parity tests hold 1e-4 of the largest entry against PyTorch's float64). Blocks
/// hold 2¹⁸ / C pixels (4,096 at C = 64, 512 at C = 512), so deep layers still have blocks
/// to share; they are dealt to a fixed number of groups (8 up to C = 128, fewer above: each
/// group's C × C partial sums are fresh memory) whose sums are added in a fixed order, so the
/// result does not depend on the thread count. A single C × C × n GEMM
/// was 4× slower: a 64 × 64 output with a 262,144-long inner dimension gives the GEMM nothing
/// to parallelise or block on.
pub fn gram(c: usize, n: usize, f: &[f32], par: Parallelism) -> Vec<f64> {
    let block = ((1usize << 18) / c.max(1)).clamp(512, 4096);
    let groups = ((1usize << 21) / (c * c).max(1)).clamp(2, 8);
    let pixels = f.len() / c;
    let blocks = pixels.div_ceil(block);
    // Deep layers have one block but a large c: there the GEMM itself is parallel.
    let inner = if blocks == 1 { par } else { Parallelism::None };
    let group = |gi: usize| -> Vec<f64> {
        let mut g = vec![0f64; c * c];
        let mut part = vec![0f32; c * c];
        for bi in (gi..blocks).step_by(groups) {
            let (p0, p1) = (bi * block, ((bi + 1) * block).min(pixels));
            let b = &f[p0 * c..p1 * c];
            // part = Bᵀ B with B = the block's pixels (m × c, row-major).
            // SAFETY: part is c × c row-major; lhs is Bᵀ (c × m): element (i, k) at k·c + i,
            // row stride 1, column stride c; rhs is B (m × c) row-major.
            unsafe {
                gemm::gemm(
                    c,
                    c,
                    p1 - p0,
                    part.as_mut_ptr(),
                    1,
                    c as isize,
                    false,
                    b.as_ptr(),
                    c as isize,
                    1,
                    b.as_ptr(),
                    1,
                    c as isize,
                    0.0,
                    1.0,
                    false,
                    false,
                    false,
                    inner,
                );
            }
            g.iter_mut().zip(&part).for_each(|(a, v)| *a += *v as f64);
        }
        g
    };
    let parts: Vec<Vec<f64>> = if matches!(par, Parallelism::None) {
        (0..groups).map(group).collect()
    } else {
        (0..groups).into_par_iter().map(group).collect()
    };
    let scale = 1.0 / (c * n) as f64;
    let mut g = vec![0f64; c * c];
    for p in &parts {
        g.iter_mut().zip(p).for_each(|(a, b)| *a += b);
    }
    g.iter_mut().for_each(|v| *v *= scale);
    g
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
    let layers = crate::npy::read_layers(bytes).map_err(&bad)?;
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
