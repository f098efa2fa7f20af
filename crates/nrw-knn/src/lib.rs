//! Exact k-nearest and k-furthest neighbours under squared Euclidean distance (which, for
//! `nrw-style` descriptors, is the style distance), for triplet mining.
//!
//! All-pairs distances come from the GEMM identity ‖a−b‖² = ‖a‖² + ‖b‖² − 2a·b in f32 (or
//! f64 for small N), in blocks of anchors; each pair is computed once while the N × N
//! dot-product matrix fits 512 MiB (N ≤ 8,192), and memory stays O(block · N) beyond. That
//! identity loses digits when two descriptors are close, so it only *selects* candidates:
//! with the standard bound |fl(a·b) − a·b| ≤ γ_K ‖a‖‖b‖ (γ_K = K·u / (1 − K·u), u = 2⁻²⁴ or
//! 2⁻⁵³; dot products are summed in f64 from GEMMs over K ≤ 4,096 terms, so K is not the full
//! dimension) every pair gets an interval that must contain its true distance; any point
//! that could be among the true k nearest (furthest) is kept, and the candidates are
//! re-ranked with Σ(a−b)² summed in f64 (where their intervals already prove the order,
//! only the k they put first). The result equals a naive f64 double loop: same ids, same
//! order, distances to 1e-15 relative. Ties are broken by the lower index, so tables are
//! deterministic; and no stored distance is a GEMM value, whose summation order depends on
//! the instruction set (AVX-512 or AVX2 kernels), so the tables are the same bits on every
//! machine.
//!
//! Memory does not grow with N × D: descriptors are [`Spilled`] once (chunk-major, into a
//! scratch file when they come from a dataset), and every pass reads one chunk of every row
//! or one block of rows; the exact re-rank sums each uncertain pair chunk by chunk with the
//! partial sums of [`distance2_f64`] carried along, so it gives the same bits.

pub mod approx;
mod exact;
pub mod spill;

pub use spill::{Spilled, StreamError};

use rayon::prelude::*;

/// Errors of neighbour search, naming the offending row.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum KnnError {
    #[error("row {row}: descriptor has {len} values, the others {dim}")]
    Dimension { row: usize, len: usize, dim: usize },
    #[error("row {row}: descriptor value {index} is {value} (not finite)")]
    NotFinite {
        row: usize,
        index: usize,
        value: f32,
    },
    #[error("row {row}: no descriptor was given for it")]
    Missing { row: usize },
    #[error("k = {k} needs at least {need} descriptors, found {n}")]
    TooFew { k: usize, need: usize, n: usize },
}

/// One anchor's neighbours: (row, squared distance), nearest first / furthest first.
#[derive(Debug, Clone, PartialEq)]
pub struct Neighbours {
    pub nearest: Vec<(usize, f64)>,
    pub furthest: Vec<(usize, f64)>,
}

/// The full N × N matrix of squared distances, row-major, each pair summed exactly in f64
/// (`distance2_f64`) and mirrored: symmetric with a zero diagonal by construction. O(N² · D):
/// for the published pretraining's `dist_<name>.pckl`, which wants every pair.
pub fn distance_matrix(rows: &[&[f32]]) -> Vec<f64> {
    let n = rows.len();
    let upper: Vec<Vec<f64>> = (0..n)
        .into_par_iter()
        .map(|i| {
            (i + 1..n)
                .map(|j| distance2_f64(rows[i], rows[j]))
                .collect()
        })
        .collect();
    let mut m = vec![0f64; n * n];
    for (i, row) in upper.iter().enumerate() {
        for (k, &d) in row.iter().enumerate() {
            let j = i + 1 + k;
            m[i * n + j] = d;
            m[j * n + i] = d;
        }
    }
    m
}

/// Squared distance summed in f64 (eight interleaved partial sums, so it vectorises; the
/// f64 sum of f32 differences is exact to ~1e-15 relative either way).
pub fn distance2_f64(a: &[f32], b: &[f32]) -> f64 {
    let mut acc = [0f64; 8];
    let (ca, cb) = (a.chunks_exact(8), b.chunks_exact(8));
    let (ra, rb) = (ca.remainder(), cb.remainder());
    for (x, y) in ca.zip(cb) {
        for l in 0..8 {
            let d = x[l] as f64 - y[l] as f64;
            acc[l] += d * d;
        }
    }
    let mut s = acc.iter().sum::<f64>();
    for (x, y) in ra.iter().zip(rb) {
        let d = *x as f64 - *y as f64;
        s += d * d;
    }
    s
}

/// Check descriptors: one dimension, all finite; returns the dimension.
pub fn validate(rows: &[Vec<f32>]) -> Result<usize, KnnError> {
    let dim = rows.first().map_or(0, |r| r.len());
    // Rows in parallel (reference-tier descriptors are 10⁸–10⁹ values); the error reported
    // is the first offending row's, as a sequential scan would find it.
    let bad = rows.par_iter().enumerate().find_map_first(|(row, r)| {
        if r.len() != dim {
            return Some(KnnError::Dimension {
                row,
                len: r.len(),
                dim,
            });
        }
        spill::not_finite(row, r)
    });
    match bad {
        Some(e) => Err(e),
        None => Ok(dim),
    }
}

/// Largest N × N f64 dot-product matrix kept whole to compute each pair once (N ≤ 8,192).
const SYM_MAX_BYTES: usize = 512 << 20;

/// Exact k nearest and k furthest of every row among the others (self excluded).
pub fn exact(rows: &[Vec<f32>], k: usize) -> Result<Vec<Neighbours>, KnnError> {
    exact_with_matrix_limit(rows, k, SYM_MAX_BYTES)
}

/// [`exact`] with the symmetric scheme's N × N matrix limited to `max_bytes` (0: never
/// symmetric), so tests reach the blocked path without 8,192 rows.
#[doc(hidden)]
pub fn exact_with_matrix_limit(
    rows: &[Vec<f32>],
    k: usize,
    max_bytes: usize,
) -> Result<Vec<Neighbours>, KnnError> {
    exact_spilled_with(&Spilled::from_rows(rows)?, k, max_bytes)
}

/// [`exact`] of descriptors read in passes (see [`Spilled::from_source`]): the same lists,
/// to the bit, without N descriptors in memory.
pub fn exact_spilled(s: &Spilled, k: usize) -> Result<Vec<Neighbours>, KnnError> {
    exact_spilled_with(s, k, SYM_MAX_BYTES)
}

fn exact_spilled_with(
    s: &Spilled,
    k: usize,
    max_bytes: usize,
) -> Result<Vec<Neighbours>, KnnError> {
    let (n, dim) = (s.len(), s.dim());
    if k == 0 || k + 1 > n {
        return Err(KnnError::TooFew { k, need: k + 1, n });
    }
    // Dot products in f64 when re-ranking f32 candidates would cost more than the GEMM itself
    // (small N: each anchor re-ranks ~2k candidates, each a cache-missing pass over D values,
    // measured here ≈ 36 GEMM dot products; see docs/triplets.md) and a chunk of f64 values
    // stays small. f64 intervals are so narrow that re-ranking is rarely needed at all.
    Ok(
        if n < 64 * k && (n * n * 8 <= max_bytes || n * dim * 8 <= 1 << 30) {
            exact::exact_in::<f64>(s, k, max_bytes)
        } else {
            exact::exact_in::<f32>(s, k, max_bytes)
        },
    )
}

/// Sort a list of (row, distance) nearest first, or furthest first, ties by the lower row.
pub(crate) fn sort_list(v: &mut [(usize, f64)], furthest: bool) {
    if furthest {
        v.sort_by(|a, b| b.1.total_cmp(&a.1).then(a.0.cmp(&b.0)));
    } else {
        v.sort_by(|a, b| a.1.total_cmp(&b.1).then(a.0.cmp(&b.0)));
    }
}

/// The naive reference: every pair in f64, sorted; O(N²·D) time, O(N) memory per anchor.
pub fn naive(rows: &[Vec<f32>], k: usize) -> Vec<Neighbours> {
    (0..rows.len())
        .map(|i| {
            let mut d: Vec<(usize, f64)> = (0..rows.len())
                .filter(|&j| j != i)
                .map(|j| {
                    let s: f64 = rows[i]
                        .iter()
                        .zip(&rows[j])
                        .map(|(x, y)| (*x as f64 - *y as f64).powi(2))
                        .sum();
                    (j, s)
                })
                .collect();
            let mut near = d.clone();
            near.sort_by(|a, b| a.1.total_cmp(&b.1).then(a.0.cmp(&b.0)));
            near.truncate(k);
            d.sort_by(|a, b| b.1.total_cmp(&a.1).then(a.0.cmp(&b.0)));
            d.truncate(k);
            Neighbours {
                nearest: near,
                furthest: d,
            }
        })
        .collect()
}
