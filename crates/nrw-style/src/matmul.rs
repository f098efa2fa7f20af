//! The GEMM products of the trunk: a strided matrix product on the `gemm` crate (what the
//! direct and the Winograd convolutions reduce to) and the Gram matrices of a layer.

use nrw_gemm::Parallelism;
use rayon::prelude::*;

/// dst (m × n, row-major) = [dst +] lhs · rhs, where lhs holds m rows of k values `lhs_rs`
/// apart (rows may overlap: a convolution's input read in place) and rhs is k × n row-major.
/// Lengths are checked, so the GEMM cannot touch memory outside the slices.
#[allow(clippy::too_many_arguments)]
pub(crate) fn dst_plus_lhs_rhs(
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
        nrw_gemm::gemm(
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
        nrw_gemm::gemm(
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
            Parallelism::None,
        );
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
                nrw_gemm::gemm(
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
