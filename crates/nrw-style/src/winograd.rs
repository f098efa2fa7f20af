//! Winograd F(4×4, 3×3) for VGG's 3 × 3 convolutions (Lavin & Gray, 2016): each 4 × 4 block
//! of output pixels costs 36 multiplications per input–output channel pair instead of 144, so
//! the GEMM work of a convolution falls by 4×. The input and output transforms are small
//! additions with constant coefficients, vectorised over channels; the 36 products are 36
//! GEMMs (tiles × Cᵢ) · (Cᵢ × Cₒ) on the `gemm` crate.
//!
//! Precision: the transformed weights U = G g Gᵀ are computed in f64 and rounded to f32 once;
//! the transforms and GEMMs run in f32. [`error_bound`] gives a rigorous elementwise bound
//! (Higham-style, γₙ = n·u / (1 − n·u) with u = 2⁻²⁴) of the result's error against exact
//! arithmetic, which the tests check against float64 at every output. Points 0, ±1, ±2 keep
//! the transform coefficients small (|coefficients| ≤ 8), so the bound is a small multiple of
//! the direct convolution's.
//!
//! The transforms are plain Rust compiled three times (AVX-512, AVX2 + FMA, baseline) and
//! chosen at run time. Rust never contracts a·b + c into an FMA by itself, so all three give
//! bit-identical results: a descriptor does not depend on the machine's vector width.

use nrw_gemm::Parallelism;
use rayon::prelude::*;

#[cfg(test)]
use crate::isa::{isa, Isa};
use crate::matmul::{gemm_strided, GemmOperands};
use crate::tensor::Activation;

/// Bᵀ of F(4×4, 3×3): the 6 × 6 input transform (Lavin & Gray's points 0, ±1, ±2, ∞).
pub const BT: [[f64; 6]; 6] = [
    [4.0, 0.0, -5.0, 0.0, 1.0, 0.0],
    [0.0, -4.0, -4.0, 1.0, 1.0, 0.0],
    [0.0, 4.0, -4.0, -1.0, 1.0, 0.0],
    [0.0, -2.0, -1.0, 2.0, 1.0, 0.0],
    [0.0, 2.0, -1.0, -2.0, 1.0, 0.0],
    [0.0, 4.0, 0.0, -5.0, 0.0, 1.0],
];

/// G: the 6 × 3 kernel transform.
pub const G: [[f64; 3]; 6] = [
    [1.0 / 4.0, 0.0, 0.0],
    [-1.0 / 6.0, -1.0 / 6.0, -1.0 / 6.0],
    [-1.0 / 6.0, 1.0 / 6.0, -1.0 / 6.0],
    [1.0 / 24.0, 1.0 / 12.0, 1.0 / 6.0],
    [1.0 / 24.0, -1.0 / 12.0, 1.0 / 6.0],
    [0.0, 0.0, 1.0],
];

/// Aᵀ: the 4 × 6 output transform.
pub const AT: [[f64; 6]; 4] = [
    [1.0, 1.0, 1.0, 1.0, 1.0, 0.0],
    [0.0, 1.0, -1.0, 2.0, -2.0, 0.0],
    [0.0, 1.0, 1.0, 4.0, 4.0, 0.0],
    [0.0, 1.0, -1.0, 8.0, -8.0, 1.0],
];

/// Output pixels per tile side.
const M: usize = 4;
/// Input pixels per tile side (M + 3 − 1).
const T: usize = 6;
/// Transform positions per tile.
const P: usize = T * T;
/// Channels per vector step of the transforms: one AVX-512 register, two AVX2 registers.
const L: usize = 16;
/// Tiles per band (at least): each band's transformed input and output (36 vectors per tile)
/// stay near the core's cache while its 36 GEMMs run, and a band's GEMM still has enough rows.
const BAND_TILES: usize = 256;

type Lanes = [f32; L];

/// A 3 × 3 convolution's weights in the Winograd domain: per position p of the 6 × 6 tile, a
/// Cᵢ × Cₒ row-major matrix, and the bias.
#[derive(Debug, Clone)]
pub struct WinogradConv {
    pub in_ch: usize,
    pub out_ch: usize,
    /// P × Cᵢ × Cₒ values: U[p][i][o] = (G g[o, i] Gᵀ)[p / 6][p % 6].
    pub u: Aligned,
    pub bias: Vec<f32>,
}

impl WinogradConv {
    /// From torchvision's OIHW weights. Precision is given up here once: U is exact to f64
    /// and then rounded to f32 (relative error ≤ u = 2⁻²⁴ per entry).
    pub fn from_oihw(out_ch: usize, in_ch: usize, weight: &[f32], bias: Vec<f32>) -> Self {
        assert_eq!(weight.len(), out_ch * in_ch * 9, "OIHW weights");
        let mut u = Aligned::zeros(P * in_ch * out_ch);
        // One output channel's column of every position's matrix, computed per o in parallel.
        let cols: Vec<Vec<f32>> = (0..out_ch)
            .into_par_iter()
            .map(|o| {
                let mut col = vec![0f32; P * in_ch];
                for i in 0..in_ch {
                    let g = &weight[(o * in_ch + i) * 9..][..9];
                    let t = kernel_transform(g, false);
                    for (p, v) in t.iter().enumerate() {
                        col[p * in_ch + i] = *v as f32;
                    }
                }
                col
            })
            .collect();
        let um = u.as_mut_slice();
        for (o, col) in cols.iter().enumerate() {
            for (pi, v) in col.iter().enumerate() {
                um[pi * out_ch + o] = *v;
            }
        }
        WinogradConv {
            in_ch,
            out_ch,
            u,
            bias,
        }
    }
}

/// G g Gᵀ of one 3 × 3 kernel (row-major 9 values) in f64; with `absolute`, |G| |g| |G|ᵀ
/// (the error bound's magnitude of U).
fn kernel_transform(g: &[f32], absolute: bool) -> [f64; P] {
    let gm = |r: usize, c: usize| if absolute { G[r][c].abs() } else { G[r][c] };
    let gv = |i: usize| {
        if absolute {
            (g[i] as f64).abs()
        } else {
            g[i] as f64
        }
    };
    let mut t = [[0f64; 3]; T]; // G g
    for (a, row) in t.iter_mut().enumerate() {
        for (kx, v) in row.iter_mut().enumerate() {
            *v = (0..3).map(|ky| gm(a, ky) * gv(ky * 3 + kx)).sum();
        }
    }
    let mut out = [0f64; P];
    for a in 0..T {
        for b in 0..T {
            out[a * T + b] = (0..3).map(|kx| t[a][kx] * gm(b, kx)).sum();
        }
    }
    out
}

/// 3 × 3 convolution (stride 1, padding 1) + bias + ReLU of a padded channels-last
/// activation, by F(4×4, 3×3). Equal to [`crate::conv::conv3x3_relu`] within the bound of
/// [`error_bound`]; the output's zero border is kept. Bands of tiles are independent and
/// their GEMMs never split the inner dimension, so the result is the same for any thread
/// count.
pub fn conv3x3_relu(conv: &WinogradConv, x: &Activation, par: Parallelism) -> Activation {
    let (ci, co, h, w) = (conv.in_ch, conv.out_ch, x.h, x.w);
    assert_eq!(x.c, ci, "input channels");
    let pw = w + 2;
    let mut out = crate::pool::bordered(h, w, co);
    let (th, tw) = (h.div_ceil(M), w.div_ceil(M));
    // Wide layers take bigger bands: each band's GEMMs pack U (36 · Cᵢ · Cₒ values) afresh.
    let band_tiles = BAND_TILES.max(ci * co / 1024);
    let rows_per_band = band_tiles.div_ceil(tw).clamp(1, th.max(1));
    let bands = th.div_ceil(rows_per_band);
    let parallel = !matches!(par, Parallelism::None);
    // Image rows 0..h are padded rows 1..=h; band b covers image rows from 4·rows_per_band·b.
    let body = &mut out[pw * co..(h + 1) * pw * co];
    let band_len = rows_per_band * M * pw * co;
    let run = |(b, chunk): (usize, &mut [f32])| {
        let ty0 = b * rows_per_band;
        let rows = rows_per_band.min(th - ty0);
        band(conv, x, ty0, rows, tw, chunk, parallel && bands == 1);
    };
    if parallel && bands > 1 {
        body.par_chunks_mut(band_len).enumerate().for_each(run);
    } else {
        body.chunks_mut(band_len).enumerate().for_each(run);
    }
    Activation {
        c: co,
        h,
        w,
        data: out,
    }
}

/// One band of `rows` tile rows from tile row `ty0`: transform its input tiles, run the 36
/// GEMMs, transform back into `out` (the band's image rows of the padded output, border
/// columns included). `parallel` spreads the band's own work over the cores (used when the
/// layer is a single band).
fn band(
    conv: &WinogradConv,
    x: &Activation,
    ty0: usize,
    rows: usize,
    tw: usize,
    out: &mut [f32],
    parallel: bool,
) {
    let (ci, co) = (conv.in_ch, conv.out_ch);
    let tiles = rows * tw;
    // Tile-major: tile t's 36 transformed vectors are contiguous (t·36 + p)·C.
    let (nv, nm) = (tiles * P * ci, tiles * P * co);
    SCRATCH.with(|cell| match cell.try_borrow_mut() {
        Ok(mut bufs) => {
            let (v_buf, m_buf) = &mut *bufs;
            v_buf.reserve(nv);
            m_buf.reserve(nm);
            let (v, m) = (v_buf.as_mut_slice(), m_buf.as_mut_slice());
            band_in(conv, x, ty0, tw, tiles, out, parallel, v, m);
        }
        // This thread is already inside a band (rayon let it pick up another photo's
        // work while waiting): that band owns the scratch, this one gets its own.
        Err(_) => {
            let (mut v, mut m) = (Aligned::zeros(nv), Aligned::zeros(nm));
            let (v, m) = (v.as_mut_slice(), m.as_mut_slice());
            band_in(conv, x, ty0, tw, tiles, out, parallel, v, m);
        }
    });
}

thread_local! {
    /// Each thread's transformed input and products, reused from band to band (a fresh
    /// buffer per band cost page faults): every element is written before it is read.
    static SCRATCH: std::cell::RefCell<(Aligned, Aligned)> =
        std::cell::RefCell::new((Aligned::zeros(0), Aligned::zeros(0)));
}

/// [`band`] with its scratch buffers `v` (tiles × 36 × Cᵢ) and `m` (tiles × 36 × Cₒ).
#[allow(clippy::too_many_arguments)]
fn band_in(
    conv: &WinogradConv,
    x: &Activation,
    ty0: usize,
    tw: usize,
    tiles: usize,
    out: &mut [f32],
    parallel: bool,
    v: &mut [f32],
    m: &mut [f32],
) {
    let (ci, co) = (conv.in_ch, conv.out_ch);
    let rows = tiles / tw;
    let (v, m) = (&mut v[..tiles * P * ci], &mut m[..tiles * P * co]);
    debug_assert!(rows * tw == tiles);
    let input = |(t, vt): (usize, &mut [f32])| {
        input_tile(x, ty0 + t / tw, t % tw, vt);
    };
    if parallel {
        v.par_chunks_mut(P * ci).enumerate().for_each(input);
    } else {
        v.chunks_mut(P * ci).enumerate().for_each(input);
    }
    let v = &*v;
    let (dst, dst_len) = (SendPtr(m.as_mut_ptr()), m.len());
    let gemm_at = |p: usize| {
        let dst = &dst;
        // GEMM p writes elements t·36·Cₒ + p·Cₒ + o (o < Cₒ) of m only: the positions'
        // writes are disjoint, so they may run in parallel through one raw pointer.
        gemm_strided(GemmOperands {
            // SAFETY: p·Cₒ < m.len(); the view's extent is checked by gemm_strided.
            dst: unsafe { dst.0.add(p * co) },
            dst_len: dst_len - p * co,
            dst_rs: P * co,
            m: tiles,
            n: co,
            k: ci,
            lhs: &v[p * ci..],
            lhs_rs: P * ci,
            rhs: &conv.u.as_slice()[p * ci * co..(p + 1) * ci * co],
        });
    };
    if parallel {
        (0..P).into_par_iter().for_each(gemm_at);
    } else {
        (0..P).for_each(gemm_at);
    }
    let pw = x.w + 2;
    let h_rows = out.len() / (pw * co);
    let output = |(r, row_chunk): (usize, &mut [f32])| {
        // row_chunk: image rows 4r … 4r + 3 of this band (fewer at the image's bottom).
        let here = row_chunk.len() / (pw * co);
        for tx in 0..tw {
            let t = r * tw + tx;
            output_tile(
                &m[t * P * co..(t + 1) * P * co],
                &conv.bias,
                row_chunk,
                here,
                pw,
                tx,
                x.w,
            );
        }
    };
    debug_assert!(h_rows <= rows * M);
    if parallel {
        out.par_chunks_mut(M * pw * co).enumerate().for_each(output);
    } else {
        out.chunks_mut(M * pw * co).enumerate().for_each(output);
    }
}

/// A zeroed f32 buffer whose first element sits on a 64-byte boundary. The `gemm` crate's
/// rounding depends on its operands' alignment (its kernels peel differently), so every
/// buffer a Winograd GEMM reads or writes is aligned the same way in every run: equal inputs
/// give equal bits.
#[derive(Debug, Clone)]
pub struct Aligned {
    buf: Vec<f32>,
    start: usize,
    len: usize,
}

impl Aligned {
    /// `len` zeros, 64-byte aligned.
    pub fn zeros(len: usize) -> Aligned {
        let buf = vec![0f32; len + 16];
        let start = buf.as_ptr().align_offset(64).min(16);
        Aligned { buf, start, len }
    }

    /// The values.
    pub fn as_slice(&self) -> &[f32] {
        &self.buf[self.start..self.start + self.len]
    }

    /// The values, writable.
    pub fn as_mut_slice(&mut self) -> &mut [f32] {
        &mut self.buf[self.start..self.start + self.len]
    }

    /// Grow to at least `len` values (old contents are not kept).
    pub fn reserve(&mut self, len: usize) {
        if self.len < len {
            *self = Aligned::zeros(len);
        }
    }
}

/// A raw pointer shared by parallel GEMMs that write disjoint elements.
struct SendPtr(*mut f32);
// SAFETY: used only for the disjoint writes described at its use.
unsafe impl Sync for SendPtr {}
unsafe impl Send for SendPtr {}

/// Bᵀ d of one column of six lane vectors.
#[inline(always)]
fn bt6(d: &[Lanes; T]) -> [Lanes; T] {
    let mut r = [[0f32; L]; T];
    for l in 0..L {
        let (d0, d1, d2, d3, d4, d5) = (d[0][l], d[1][l], d[2][l], d[3][l], d[4][l], d[5][l]);
        r[0][l] = 4.0 * d0 - 5.0 * d2 + d4;
        r[1][l] = -4.0 * d1 - 4.0 * d2 + d3 + d4;
        r[2][l] = 4.0 * d1 - 4.0 * d2 - d3 + d4;
        r[3][l] = -2.0 * d1 - d2 + 2.0 * d3 + d4;
        r[4][l] = 2.0 * d1 - d2 - 2.0 * d3 + d4;
        r[5][l] = 4.0 * d1 - 5.0 * d3 + d5;
    }
    r
}

/// Aᵀ m of one column of six lane vectors.
#[inline(always)]
fn at6(m: &[Lanes; T]) -> [Lanes; M] {
    let mut r = [[0f32; L]; M];
    for l in 0..L {
        let (m0, m1, m2, m3, m4, m5) = (m[0][l], m[1][l], m[2][l], m[3][l], m[4][l], m[5][l]);
        let (s12, d12, s34, d34) = (m1 + m2, m1 - m2, m3 + m4, m3 - m4);
        r[0][l] = m0 + s12 + s34;
        r[1][l] = d12 + 2.0 * d34;
        r[2][l] = s12 + 4.0 * s34;
        r[3][l] = d12 + 8.0 * d34 + m5;
    }
    r
}

/// Lanes c0 … c0 + L of a C-long vector, zero past its end.
#[inline(always)]
fn load(src: &[f32], c0: usize) -> Lanes {
    if let Some(full) = src.get(c0..c0 + L) {
        return full.try_into().expect("L values"); // a fixed-size copy: vector moves
    }
    let mut v = [0f32; L];
    let n = src.len() - c0;
    v[..n].copy_from_slice(&src[c0..]);
    v
}

/// Store the first `n` lanes at `dst[at..]` (all L as one fixed-size copy when n = L).
#[inline(always)]
fn store(dst: &mut [f32], at: usize, v: &Lanes, n: usize) {
    if n == L {
        let d: &mut Lanes = (&mut dst[at..at + L]).try_into().expect("L values");
        *d = *v;
    } else {
        dst[at..at + n].copy_from_slice(&v[..n]);
    }
}

multiversion! {
    /// Transform the input tile (ty, tx) — padded rows 4ty … 4ty + 5, columns 4tx … 4tx + 5,
    /// zero outside the buffer — into its 36 vectors of C values (`vt`, position-major).
    #[allow(clippy::needless_range_loop)] // i indexes both the rows of `cols` and the output
    fn input_tile(x: &Activation, ty: usize, tx: usize, vt: &mut [f32]) {
        let (c, pw, ph) = (x.c, x.w + 2, x.h + 2);
        let zeros = [0f32; L];
        for c0 in (0..c).step_by(L) {
            // Pass 1: each column j, Bᵀ over its six rows.
            let mut cols = [[[0f32; L]; T]; T]; // cols[j][r]
            for (j, col) in cols.iter_mut().enumerate() {
                let xx = M * tx + j;
                let mut d = [zeros; T];
                if xx < pw {
                    for (r, dr) in d.iter_mut().enumerate() {
                        let yy = M * ty + r;
                        if yy < ph {
                            *dr = load(&x.data[(yy * pw + xx) * c..(yy * pw + xx + 1) * c], c0);
                        }
                    }
                }
                *col = bt6(&d);
            }
            // Pass 2: each row i, Bᵀ over its six columns: V[i][k].
            for i in 0..T {
                let row: [Lanes; T] = std::array::from_fn(|j| cols[j][i]);
                let vr = bt6(&row);
                let n = (c - c0).min(L);
                for (k, vk) in vr.iter().enumerate() {
                    store(vt, (i * T + k) * c + c0, vk, n);
                }
            }
        }
    }
}

multiversion! {
    /// Transform tile tx's 36 product vectors back to its 4 × 4 output pixels, add the bias,
    /// apply ReLU and write the pixels inside the image (`here` image rows, `w` columns).
    #[allow(clippy::needless_range_loop)] // r indexes both `s` and the output rows
    fn output_tile(
        mt: &[f32],
        bias: &[f32],
        out: &mut [f32],
        here: usize,
        pw: usize,
        tx: usize,
        w: usize,
    ) {
        let c = bias.len();
        for c0 in (0..c).step_by(L) {
            let n = (c - c0).min(L);
            let b = load(bias, c0);
            // Pass 1: each column b, Aᵀ over its six rows: s[b][r].
            let mut s = [[[0f32; L]; M]; T];
            for (bc, sb) in s.iter_mut().enumerate() {
                let col: [Lanes; T] = std::array::from_fn(|a| load(&mt[(a * T + bc) * c..][..c], c0));
                *sb = at6(&col);
            }
            // Pass 2: each output row r, Aᵀ over its six columns.
            for r in 0..here.min(M) {
                let row: [Lanes; T] = std::array::from_fn(|bc| s[bc][r]);
                let y = at6(&row);
                for (q, yq) in y.iter().enumerate() {
                    let xx = M * tx + q;
                    if xx >= w {
                        break;
                    }
                    let y: Lanes = std::array::from_fn(|l| (yq[l] + b[l]).max(0.0));
                    store(out, (r * pw + xx + 1) * c + c0, &y, n);
                }
            }
        }
    }
}

/// The rigorous elementwise error bound of [`conv3x3_relu`] against exact arithmetic, for a
/// planar CHW input and OIHW weights: γₙ · E with E the same algorithm run in f64 on |d|,
/// |g|, |Bᵀ|, |G| and |Aᵀ| (plus |bias|), n = Cᵢ + 26 rounding steps along any path (8 in
/// the input transform, 1 rounding U to f32, Cᵢ + 1 in the GEMM, 12 in the output transform,
/// 1 for the bias, with margin). Returns the bound per output, planar Cₒ × H × W.
pub fn error_bound(
    x: &[f32],
    ci: usize,
    h: usize,
    w: usize,
    weight: &[f32],
    bias: &[f32],
) -> Vec<f64> {
    let co = bias.len();
    let u = f64::powi(2.0, -24);
    let n = (ci + 26) as f64;
    let gamma = n * u / (1.0 - n * u);
    let at = |i: usize, a: usize| AT[i][a].abs();
    let bt = |i: usize, a: usize| BT[i][a].abs();
    let mut out = vec![0f64; co * h * w];
    for ty in 0..h.div_ceil(M) {
        for tx in 0..w.div_ceil(M) {
            // |Bᵀ| |d| |B| per input channel.
            let vabs: Vec<[f64; P]> = (0..ci)
                .map(|i| {
                    let d = |r: usize, q: usize| -> f64 {
                        let (y, xx) = ((M * ty + r) as isize - 1, (M * tx + q) as isize - 1);
                        if y < 0 || xx < 0 || y as usize >= h || xx as usize >= w {
                            0.0
                        } else {
                            (x[(i * h + y as usize) * w + xx as usize] as f64).abs()
                        }
                    };
                    let mut v = [0f64; P];
                    for a in 0..T {
                        for b in 0..T {
                            v[a * T + b] = (0..T)
                                .flat_map(|r| (0..T).map(move |q| (r, q)))
                                .map(|(r, q)| bt(a, r) * d(r, q) * bt(b, q))
                                .sum();
                        }
                    }
                    v
                })
                .collect();
            for o in 0..co {
                let mut prod = [0f64; P];
                for (i, vi) in vabs.iter().enumerate() {
                    let ug = kernel_transform(&weight[(o * ci + i) * 9..][..9], true);
                    for p in 0..P {
                        prod[p] += ug[p] * vi[p];
                    }
                }
                for r in 0..M {
                    for q in 0..M {
                        let (y, xx) = (M * ty + r, M * tx + q);
                        if y >= h || xx >= w {
                            continue;
                        }
                        let e: f64 = (0..T)
                            .flat_map(|a| (0..T).map(move |b| (a, b)))
                            .map(|(a, b)| at(r, a) * prod[a * T + b] * at(q, b))
                            .sum();
                        out[(o * h + y) * w + xx] = gamma * (e + (bias[o] as f64).abs());
                    }
                }
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_instruction_set_gives_the_same_bits() {
        // A layer whose channels are not a multiple of the 16 lanes and whose size leaves
        // ragged tiles: the AVX-512, AVX2 and baseline builds of the transforms must agree
        // bit for bit (Rust never contracts a·b + c into an FMA).
        let (ci, co, h, w) = (20, 18, 9, 11);
        let mut seed = 3u64;
        let mut rnd = move || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((seed >> 33) as f32 / (1u64 << 31) as f32) - 0.5
        };
        let x: Vec<f32> = (0..ci * h * w).map(|_| rnd()).collect();
        let wt: Vec<f32> = (0..co * ci * 9).map(|_| rnd()).collect();
        let b: Vec<f32> = (0..co).map(|_| rnd()).collect();
        let conv = WinogradConv::from_oihw(co, ci, &wt, b);
        let input = Activation::from_chw(&x, ci, h, w);
        let run = |forced: Isa| {
            crate::isa::FORCE.set(Some(forced));
            let out = conv3x3_relu(&conv, &input, Parallelism::None).data;
            crate::isa::FORCE.set(None);
            out
        };
        let baseline = run(Isa::Baseline);
        assert!(baseline.iter().any(|v| *v > 0.0));
        let mut available = vec![];
        if isa() != Isa::Baseline {
            available.push(Isa::Avx2);
        }
        if isa() == Isa::Avx512 {
            available.push(Isa::Avx512);
        }
        for forced in available {
            assert_eq!(
                run(forced),
                baseline,
                "{} differs from baseline",
                forced.name()
            );
        }
    }
}
