//! The layers: 3×3 convolutions with ReLU (direct as one GEMM per row band, or Winograd
//! F(4×4, 3×3)) and 2×2 max pooling, on [`Activation`]s.

use nrw_gemm::Parallelism;
use rayon::prelude::*;

use crate::matmul::dst_plus_lhs_rhs;
use crate::tensor::Activation;
use crate::winograd::WinogradConv;

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
    bias_relu(conv, &mut out, h, pw, par);
    Activation {
        c: co,
        h,
        w,
        data: out,
    }
}

/// Bias and ReLU on the image pixels of `out` (h + 2 padded rows of `pw` pixels); the border
/// columns (written by the GEMM's straddling pixels) back to zero.
fn bias_relu(conv: &Conv, out: &mut [f32], h: usize, pw: usize, par: Parallelism) {
    let co = conv.out_ch;
    let row_of = |(y, row): (usize, &mut [f32])| {
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
        out.chunks_mut(pw * co).enumerate().for_each(row_of);
    } else {
        out.par_chunks_mut(pw * co).enumerate().for_each(row_of);
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
