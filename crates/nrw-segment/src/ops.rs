//! The few operations a SegFormer needs, on channels-last f32 maps: matrix products (the
//! `gemm` crate), convolutions as one matrix product over gathered patches, layer norm, exact
//! GELU, softmax, depthwise 3 × 3 convolution and bilinear resampling as PyTorch defines it.

use nrw_gemm::Parallelism;
use rayon::prelude::*;

/// A channels-last map: pixel (y, x) holds `c` contiguous values.
#[derive(Debug, Clone, PartialEq)]
pub struct Map {
    pub h: usize,
    pub w: usize,
    pub c: usize,
    pub data: Vec<f32>,
}

impl Map {
    /// A map of zeros.
    pub fn zeros(h: usize, w: usize, c: usize) -> Map {
        Map {
            h,
            w,
            c,
            data: vec![0.0; h * w * c],
        }
    }

    /// From PyTorch's planar CHW layout.
    pub fn from_chw(x: &[f32], c: usize, h: usize, w: usize) -> Map {
        let mut data = vec![0f32; h * w * c];
        for ch in 0..c {
            for (i, v) in x[ch * h * w..(ch + 1) * h * w].iter().enumerate() {
                data[i * c + ch] = *v;
            }
        }
        Map { h, w, c, data }
    }

    /// PyTorch's planar CHW copy (for comparisons with it).
    pub fn to_chw(&self) -> Vec<f32> {
        let n = self.h * self.w;
        let mut out = vec![0f32; n * self.c];
        for (i, px) in self.data.chunks_exact(self.c).enumerate() {
            for (ch, v) in px.iter().enumerate() {
                out[ch * n + i] = *v;
            }
        }
        out
    }
}

/// A matrix operand: `rows × cols` values of `data`, element (r, k) at `r·rs + k·cs`.
#[derive(Clone, Copy)]
pub struct Mat<'a> {
    pub data: &'a [f32],
    pub rows: usize,
    pub cols: usize,
    pub rs: usize,
    pub cs: usize,
}

impl Mat<'_> {
    fn last(&self) -> usize {
        (self.rows - 1) * self.rs + (self.cols - 1) * self.cs
    }
}

/// `dst = alpha·dst + beta·(a · b)` (`alpha = 0` overwrites), `dst` row-major with rows
/// `dst_rs` apart. Every index is checked against the slices before `gemm` reads raw pointers.
pub fn matmul(
    dst: &mut [f32],
    dst_rs: usize,
    alpha: f32,
    a: Mat,
    b: Mat,
    beta: f32,
    par: Parallelism,
) {
    let (m, k, n) = (a.rows, a.cols, b.cols);
    assert_eq!(k, b.rows, "matrix product: inner sizes differ");
    if m == 0 || n == 0 {
        return;
    }
    assert!(
        (m - 1) * dst_rs + n <= dst.len(),
        "matrix product: destination too small"
    );
    if k == 0 {
        dst.chunks_mut(dst_rs)
            .take(m)
            .for_each(|r| r[..n].iter_mut().for_each(|v| *v *= alpha));
        return;
    }
    assert!(
        a.last() < a.data.len() && b.last() < b.data.len(),
        "matrix product: operand too small"
    );
    // SAFETY: every element gemm touches lies inside the slices (asserted above), and `dst`
    // is borrowed mutably, so it aliases neither operand.
    unsafe {
        nrw_gemm::gemm(
            m,
            n,
            k,
            dst.as_mut_ptr(),
            1,
            dst_rs as isize,
            alpha != 0.0,
            a.data.as_ptr(),
            a.cs as isize,
            a.rs as isize,
            b.data.as_ptr(),
            b.cs as isize,
            b.rs as isize,
            alpha,
            beta,
            par,
        );
    }
}

/// A fully connected layer in PyTorch's layout: weight `out × in`, row-major.
#[derive(Debug, Clone)]
pub struct Linear {
    pub din: usize,
    pub dout: usize,
    pub w: Vec<f32>,
    pub b: Vec<f32>,
}

impl Linear {
    /// `x` (n × din) · Wᵀ + b, a new n × dout matrix.
    pub fn apply(&self, x: &[f32], par: Parallelism) -> Vec<f32> {
        let n = x.len() / self.din;
        let mut out = vec![0f32; n * self.dout];
        self.apply_into(&mut out, 0.0, x, par);
        out
    }

    /// `dst = alpha·dst + x · Wᵀ + b`: with `alpha = 1` a residual connection costs no pass.
    pub fn apply_into(&self, dst: &mut [f32], alpha: f32, x: &[f32], par: Parallelism) {
        let n = x.len() / self.din;
        let a = Mat {
            data: x,
            rows: n,
            cols: self.din,
            rs: self.din,
            cs: 1,
        };
        // Wᵀ without a copy: element (i, o) of Wᵀ is w[o·din + i].
        let b = Mat {
            data: &self.w,
            rows: self.din,
            cols: self.dout,
            rs: 1,
            cs: self.din,
        };
        matmul(dst, self.dout, alpha, a, b, 1.0, par);
        add_bias(dst, &self.b);
    }
}

/// Add a per-channel bias to every row.
pub fn add_bias(x: &mut [f32], b: &[f32]) {
    x.par_chunks_mut(b.len() * 64).for_each(|rows| {
        for r in rows.chunks_exact_mut(b.len()) {
            r.iter_mut().zip(b).for_each(|(v, b)| *v += b);
        }
    });
}

/// A convolution in PyTorch's layout (weight O × I × k × k), rearranged once into the
/// (k·k·I) × O matrix a gathered patch row multiplies.
#[derive(Debug, Clone)]
pub struct Conv {
    pub cin: usize,
    pub cout: usize,
    pub k: usize,
    pub stride: usize,
    pub pad: usize,
    /// Row (ky·k + kx)·I + i, column o: weight[o, i, ky, kx].
    pub w: Vec<f32>,
    pub b: Vec<f32>,
}

impl Conv {
    /// From PyTorch's OIHW weight.
    pub fn from_oihw(
        cout: usize,
        cin: usize,
        k: usize,
        stride: usize,
        pad: usize,
        weight: &[f32],
        b: Vec<f32>,
    ) -> Conv {
        let mut w = vec![0f32; k * k * cin * cout];
        for o in 0..cout {
            for i in 0..cin {
                for ky in 0..k {
                    for kx in 0..k {
                        w[((ky * k + kx) * cin + i) * cout + o] =
                            weight[((o * cin + i) * k + ky) * k + kx];
                    }
                }
            }
        }
        Conv {
            cin,
            cout,
            k,
            stride,
            pad,
            w,
            b,
        }
    }

    /// Output size along one axis: ⌊(n + 2·pad − k) / stride⌋ + 1, as PyTorch (0 if none).
    pub fn out_len(&self, n: usize) -> usize {
        (n + 2 * self.pad)
            .checked_sub(self.k)
            .map_or(0, |v| v / self.stride + 1)
    }

    /// Apply to a channels-last map: gather each output pixel's k × k × I patch (zeros
    /// outside), then one matrix product.
    pub fn apply(&self, x: &Map, par: Parallelism) -> Map {
        let (ho, wo) = (self.out_len(x.h), self.out_len(x.w));
        let kk = self.k * self.k * self.cin;
        let mut patches = vec![0f32; ho * wo * kk];
        patches
            .par_chunks_mut(wo * kk)
            .enumerate()
            .for_each(|(oy, row)| {
                for ox in 0..wo {
                    let dst = &mut row[ox * kk..(ox + 1) * kk];
                    for ky in 0..self.k {
                        let iy = (oy * self.stride + ky) as isize - self.pad as isize;
                        if iy < 0 || iy >= x.h as isize {
                            continue;
                        }
                        for kx in 0..self.k {
                            let ix = (ox * self.stride + kx) as isize - self.pad as isize;
                            if ix < 0 || ix >= x.w as isize {
                                continue;
                            }
                            let src = (iy as usize * x.w + ix as usize) * x.c;
                            dst[(ky * self.k + kx) * self.cin..][..self.cin]
                                .copy_from_slice(&x.data[src..src + x.c]);
                        }
                    }
                }
            });
        let mut out = Map::zeros(ho, wo, self.cout);
        let a = Mat {
            data: &patches,
            rows: ho * wo,
            cols: kk,
            rs: kk,
            cs: 1,
        };
        let b = Mat {
            data: &self.w,
            rows: kk,
            cols: self.cout,
            rs: self.cout,
            cs: 1,
        };
        matmul(&mut out.data, self.cout, 0.0, a, b, 1.0, par);
        add_bias(&mut out.data, &self.b);
        out
    }
}

/// Layer norm's scale and shift (PyTorch's default epsilon 1e-5; SegFormer sets no other).
#[derive(Debug, Clone)]
pub struct Norm {
    pub g: Vec<f32>,
    pub b: Vec<f32>,
}

/// `nn.LayerNorm`'s epsilon, which every SegFormer norm uses.
pub const LN_EPS: f32 = 1e-5;

impl Norm {
    /// Normalise every row (pixel) in place: mean and biased variance over its channels.
    pub fn apply(&self, x: &mut [f32]) {
        let c = self.g.len();
        x.par_chunks_mut(c * 64).for_each(|rows| {
            for r in rows.chunks_exact_mut(c) {
                let mean = r.iter().sum::<f32>() / c as f32;
                let var = r.iter().map(|v| (v - mean) * (v - mean)).sum::<f32>() / c as f32;
                let inv = 1.0 / (var + LN_EPS).sqrt();
                for ((v, g), b) in r.iter_mut().zip(&self.g).zip(&self.b) {
                    *v = (*v - mean) * inv * g + b;
                }
            }
        });
    }
}

/// e^x in f32 without a library call, so loops over it vectorise: Cephes' `expf` (range
/// reduction by ln 2 in two parts, degree-5 polynomial), within 2 ulp for |x| < 87; below
/// −87.3 it returns ≈ 0 and above 88 it saturates (softmax arguments are ≤ 0).
#[inline(always)]
pub fn exp(x: f32) -> f32 {
    let x = x.clamp(-87.3, 88.0);
    let n = (x * std::f32::consts::LOG2_E).round();
    let r = x - n * 0.693_359_4 + n * 2.121_944_4e-4;
    let z = r * r;
    let p = ((((1.987_569_1e-4 * r + 1.398_2e-3) * r + 8.333_452e-3) * r + 4.166_579_6e-2) * r
        + 1.666_666_5e-1)
        * r
        + 5.0e-1;
    let y = p * z + r + 1.0;
    y * f32::from_bits(((n as i32 + 127) as u32) << 23)
}

/// GELU with the exact erf (`nn.GELU()`, SegFormer's `gelu`): erf from Abramowitz & Stegun
/// 7.1.26 (absolute error ≤ 1.5e-7 in exact arithmetic; f32 rounding adds a few ulp).
#[inline(always)]
pub fn gelu(x: f32) -> f32 {
    let z = x.abs() * std::f32::consts::FRAC_1_SQRT_2;
    let t = 1.0 / (1.0 + 0.327_591_1 * z);
    let poly = t
        * (0.254_829_6
            + t * (-0.284_496_74 + t * (1.421_413_7 + t * (-1.453_152 + t * 1.061_405_4))));
    // erfc(|x|/√2) = poly·e^(−z²); GELU = x·Φ(x) = x·(1 − ½·erfc(x/√2)) for x ≥ 0.
    let half_erfc = 0.5 * poly * exp(-z * z);
    if x >= 0.0 {
        x * (1.0 - half_erfc)
    } else {
        x * half_erfc
    }
}

/// Softmax of each row in place (max subtracted first, as PyTorch does).
pub fn softmax_rows(x: &mut [f32], cols: usize) {
    for r in x.chunks_exact_mut(cols) {
        let max = r.iter().fold(f32::NEG_INFINITY, |a, &b| a.max(b));
        let mut sum = 0f32;
        for v in r.iter_mut() {
            *v = exp(*v - max);
            sum += *v;
        }
        let inv = 1.0 / sum;
        r.iter_mut().for_each(|v| *v *= inv);
    }
}

/// A depthwise 3 × 3 convolution (padding 1, one filter per channel), the Mix-FFN's.
#[derive(Debug, Clone)]
pub struct DwConv {
    /// Tap t = ky·3 + kx of channel c at `w[t·C + c]` (contiguous over channels).
    pub w: Vec<f32>,
    pub b: Vec<f32>,
}

impl DwConv {
    /// From PyTorch's C × 1 × 3 × 3 weight.
    pub fn from_weight(c: usize, weight: &[f32], b: Vec<f32>) -> DwConv {
        let mut w = vec![0f32; 9 * c];
        for ch in 0..c {
            for t in 0..9 {
                w[t * c + ch] = weight[ch * 9 + t];
            }
        }
        DwConv { w, b }
    }

    /// The convolution followed by GELU (the Mix-FFN applies them in this order).
    pub fn apply_gelu(&self, x: &Map) -> Map {
        let c = x.c;
        let mut out = Map::zeros(x.h, x.w, c);
        out.data
            .par_chunks_mut(x.w * c)
            .enumerate()
            .for_each(|(y, row)| {
                for (xx, px) in row.chunks_exact_mut(c).enumerate() {
                    px.copy_from_slice(&self.b);
                    for ky in 0..3 {
                        let iy = y as isize + ky as isize - 1;
                        if iy < 0 || iy >= x.h as isize {
                            continue;
                        }
                        for kx in 0..3 {
                            let ix = xx as isize + kx as isize - 1;
                            if ix < 0 || ix >= x.w as isize {
                                continue;
                            }
                            let src = &x.data[(iy as usize * x.w + ix as usize) * c..][..c];
                            let w = &self.w[(ky * 3 + kx) * c..][..c];
                            for ((o, s), w) in px.iter_mut().zip(src).zip(w) {
                                *o += s * w;
                            }
                        }
                    }
                    px.iter_mut().for_each(|v| *v = gelu(*v));
                }
            });
        out
    }
}

/// Source index pair and weights of one output index under PyTorch's bilinear resampling
/// with `align_corners=False`: src = (o + ½)·in/out − ½, clamped at 0; the upper neighbour is
/// clamped to the last index. Computed in f32 as PyTorch does for f32 tensors.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Tap {
    pub i0: usize,
    pub i1: usize,
    pub l0: f32,
    pub l1: f32,
}

/// The taps of every output index when resampling `n_in` values to `n_out`.
pub fn taps(n_in: usize, n_out: usize) -> Vec<Tap> {
    let scale = n_in as f32 / n_out as f32;
    (0..n_out)
        .map(|o| {
            let src = ((o as f32 + 0.5) * scale - 0.5).max(0.0);
            let i0 = (src as usize).min(n_in - 1);
            let l1 = (src - i0 as f32).clamp(0.0, 1.0);
            let i1 = if i0 < n_in - 1 { i0 + 1 } else { i0 };
            Tap {
                i0,
                i1,
                l0: 1.0 - l1,
                l1,
            }
        })
        .collect()
}

/// `dst += bilinear(src)` to dst's size (`F.interpolate(mode="bilinear",
/// align_corners=False)`), both channels-last with the same channels.
pub fn upsample_add(dst: &mut Map, src: &Map) {
    let c = src.c;
    let (ty, tx) = (taps(src.h, dst.h), taps(src.w, dst.w));
    let w = dst.w;
    dst.data
        .par_chunks_mut(w * c)
        .zip(ty.par_iter())
        .for_each(|(row, t)| {
            let r0 = &src.data[t.i0 * src.w * c..][..src.w * c];
            let r1 = &src.data[t.i1 * src.w * c..][..src.w * c];
            for (px, s) in row.chunks_exact_mut(c).zip(&tx) {
                let (a0, a1) = (&r0[s.i0 * c..][..c], &r0[s.i1 * c..][..c]);
                let (b0, b1) = (&r1[s.i0 * c..][..c], &r1[s.i1 * c..][..c]);
                for k in 0..c {
                    px[k] +=
                        t.l0 * (s.l0 * a0[k] + s.l1 * a1[k]) + t.l1 * (s.l0 * b0[k] + s.l1 * b1[k]);
                }
            }
        });
}

#[cfg(test)]
mod tests {
    use super::*;

    /// erf(x) in f64 by Simpson's rule on 2/√π·e^(−t²) (error far below f32's).
    fn erf64(x: f64) -> f64 {
        let n = 20_000;
        let h = x / n as f64;
        let f = |t: f64| (-t * t).exp();
        let mut s = f(0.0) + f(x);
        for i in 1..n {
            s += f(i as f64 * h) * if i % 2 == 1 { 4.0 } else { 2.0 };
        }
        s * h / 3.0 * 2.0 / std::f64::consts::PI.sqrt()
    }

    #[test]
    fn exp_is_within_a_few_ulp_of_f64() {
        let mut worst = 0f64;
        for i in 0..=200_000 {
            let x = -87.0 + i as f64 * (87.0 + 80.0) / 200_000.0;
            let want = x.exp();
            let got = exp(x as f32) as f64;
            worst = worst.max(((got - (x as f32 as f64).exp()) / want).abs());
        }
        assert!(worst < 4e-7, "exp's worst relative error {worst:e}");
        assert_eq!(exp(-200.0), exp(-87.3));
        assert!(exp(-200.0) < 1e-37);
    }

    #[test]
    fn gelu_matches_the_exact_definition() {
        let mut worst = 0f64;
        for i in 0..=4_000 {
            let x = -10.0 + i as f64 * 20.0 / 4_000.0;
            let want = 0.5 * x * (1.0 + erf64(x / std::f64::consts::SQRT_2));
            let got = gelu(x as f32) as f64;
            worst = worst.max((got - want).abs() / x.abs().max(1.0));
        }
        assert!(worst < 5e-7, "GELU's worst error {worst:e}");
        assert_eq!(gelu(0.0), 0.0);
        assert!(gelu(-30.0).abs() < 1e-30 && gelu(30.0) == 30.0);
    }

    #[test]
    fn convolution_equals_its_definition_at_odd_sizes() {
        let (cin, cout, k, stride, pad) = (3, 5, 3, 2, 1);
        let weight: Vec<f32> = (0..cout * cin * k * k)
            .map(|i| ((i * 37 % 23) as f32 - 11.0) / 7.0)
            .collect();
        let bias: Vec<f32> = (0..cout).map(|o| o as f32 * 0.1).collect();
        let conv = Conv::from_oihw(cout, cin, k, stride, pad, &weight, bias.clone());
        let (h, w) = (7, 10);
        let chw: Vec<f32> = (0..cin * h * w)
            .map(|i| ((i * 13 % 17) as f32) / 5.0 - 1.0)
            .collect();
        let out = conv.apply(&Map::from_chw(&chw, cin, h, w), Parallelism::None);
        assert_eq!((out.h, out.w), (4, 5));
        for o in 0..cout {
            for oy in 0..out.h {
                for ox in 0..out.w {
                    let mut s = bias[o] as f64;
                    for i in 0..cin {
                        for ky in 0..k {
                            for kx in 0..k {
                                let (iy, ix) = (
                                    (oy * stride + ky) as isize - 1,
                                    (ox * stride + kx) as isize - 1,
                                );
                                if iy >= 0 && ix >= 0 && (iy as usize) < h && (ix as usize) < w {
                                    s += weight[((o * cin + i) * k + ky) * k + kx] as f64
                                        * chw[(i * h + iy as usize) * w + ix as usize] as f64;
                                }
                            }
                        }
                    }
                    let got = out.data[(oy * out.w + ox) * cout + o] as f64;
                    assert!((got - s).abs() < 1e-5, "({o}, {oy}, {ox}): {got} vs {s}");
                }
            }
        }
    }

    #[test]
    fn resampling_taps_are_pytorchs() {
        // 2 → 4 with align_corners=False: sources −0.25 (clamped), 0.25, 0.75, 1.25.
        let t = taps(2, 4);
        assert_eq!((t[0].i0, t[0].i1, t[0].l1), (0, 1, 0.0));
        assert_eq!((t[1].i0, t[1].l1), (0, 0.25));
        assert_eq!((t[2].i0, t[2].l1), (0, 0.75));
        assert_eq!((t[3].i0, t[3].i1), (1, 1));
        // Same size: the identity.
        assert!(taps(5, 5)
            .iter()
            .enumerate()
            .all(|(i, t)| t.i0 == i && t.l1 == 0.0));
    }
}
