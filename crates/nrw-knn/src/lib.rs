//! Exact k-nearest and k-furthest neighbours under squared Euclidean distance (which, for
//! `nrw-style` descriptors, is the style distance), for triplet mining.
//!
//! All-pairs distances come from the GEMM identity ‖a−b‖² = ‖a‖² + ‖b‖² − 2a·b in f32,
//! blocked over anchors so memory stays O(block · N), never N × N. In f32 that identity loses
//! digits when two descriptors are close, so it only *selects* candidates: with the standard
//! bound |fl(a·b) − a·b| ≤ γ_D ‖a‖‖b‖ (γ_D = D·u / (1 − D·u), u = 2⁻²⁴) every pair gets an
//! interval that must contain its true distance; any point that could be among the true k
//! nearest (furthest) is kept, and the candidates are re-ranked with Σ(a−b)² summed in f64.
//! The result equals a naive f64 double loop: same ids, same order, same distances. Ties are
//! broken by the lower index, so tables are deterministic.

pub mod approx;

use gemm::Parallelism;
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
    #[error("k = {k} needs at least {need} descriptors, found {n}")]
    TooFew { k: usize, need: usize, n: usize },
}

/// One anchor's neighbours: (row, squared distance), nearest first / furthest first.
#[derive(Debug, Clone, PartialEq)]
pub struct Neighbours {
    pub nearest: Vec<(usize, f64)>,
    pub furthest: Vec<(usize, f64)>,
}

/// Squared distance summed in f64, in index order: the reference every result must equal.
pub fn distance2_f64(a: &[f32], b: &[f32]) -> f64 {
    let mut s = 0f64;
    for (x, y) in a.iter().zip(b) {
        let d = *x as f64 - *y as f64;
        s += d * d;
    }
    s
}

/// Check descriptors: one dimension, all finite; returns the dimension.
pub fn validate(rows: &[Vec<f32>]) -> Result<usize, KnnError> {
    let dim = rows.first().map_or(0, |r| r.len());
    for (row, r) in rows.iter().enumerate() {
        if r.len() != dim {
            return Err(KnnError::Dimension {
                row,
                len: r.len(),
                dim,
            });
        }
        if let Some((index, value)) = r.iter().enumerate().find(|(_, v)| !v.is_finite()) {
            return Err(KnnError::NotFinite {
                row,
                index,
                value: *value,
            });
        }
    }
    Ok(dim)
}

/// Anchors per GEMM block: memory is BLOCK × N f32 for the dot products.
const BLOCK: usize = 256;

/// Exact k nearest and k furthest of every row among the others (self excluded).
pub fn exact(rows: &[Vec<f32>], k: usize) -> Result<Vec<Neighbours>, KnnError> {
    let n = rows.len();
    let dim = validate(rows)?;
    if k == 0 || k + 1 > n {
        return Err(KnnError::TooFew { k, need: k + 1, n });
    }
    let flat: Vec<f32> = rows.iter().flat_map(|r| r.iter().copied()).collect();
    let norm2: Vec<f64> = rows
        .iter()
        .map(|r| r.iter().map(|v| (*v as f64) * (*v as f64)).sum())
        .collect();
    let norm: Vec<f64> = norm2.iter().map(|v| v.sqrt()).collect();
    let u = f32::EPSILON as f64 / 2.0;
    let gamma = (dim as f64 * u) / (1.0 - dim as f64 * u);
    let mut out = Vec::with_capacity(n);
    let mut dots = vec![0f32; BLOCK.min(n) * n];
    for start in (0..n).step_by(BLOCK) {
        let b = BLOCK.min(n - start);
        let dots = &mut dots[..b * n];
        // dots (b × n) = rows[start..start+b] (b × dim) · rowsᵀ (dim × n)
        // SAFETY: dst is b × n row-major; lhs is b × dim row-major at the block's offset;
        // rhs element (k, j) is flat[j·dim + k] (row stride 1, column stride dim).
        unsafe {
            gemm::gemm(
                b,
                n,
                dim,
                dots.as_mut_ptr(),
                1,
                n as isize,
                false,
                flat.as_ptr().add(start * dim),
                1,
                dim as isize,
                flat.as_ptr(),
                dim as isize,
                1,
                0.0,
                1.0,
                false,
                false,
                false,
                Parallelism::Rayon(0),
            );
        }
        let block: Vec<Neighbours> = (0..b)
            .into_par_iter()
            .map(|r| {
                let i = start + r;
                let row = &dots[r * n..(r + 1) * n];
                // Interval of every distance: approx ± bound (bound also covers rounding of
                // the approximate sum itself, at 4 ulps of its largest term).
                let mut lo = Vec::with_capacity(n - 1);
                let mut hi = Vec::with_capacity(n - 1);
                for j in (0..n).filter(|&j| j != i) {
                    let approx = norm2[i] + norm2[j] - 2.0 * row[j] as f64;
                    let bound = 2.0 * gamma * norm[i] * norm[j]
                        + 4.0 * f64::EPSILON * (norm2[i] + norm2[j])
                        + 2.0 * u * (row[j] as f64).abs();
                    lo.push((approx - bound, j));
                    hi.push((approx + bound, j));
                }
                // Nearest: j can be among the true k nearest only if its lower end does not
                // exceed the k-th smallest upper end.
                let mut ub: Vec<f64> = hi.iter().map(|h| h.0).collect();
                let kth_ub = *ub.select_nth_unstable_by(k - 1, |a, b| a.total_cmp(b)).1;
                let near: Vec<usize> = lo
                    .iter()
                    .filter(|(l, _)| *l <= kth_ub)
                    .map(|(_, j)| *j)
                    .collect();
                // Furthest: j can be among the true k furthest only if its upper end reaches
                // the k-th largest lower end.
                let mut lb: Vec<f64> = lo.iter().map(|l| l.0).collect();
                let kth_lb = *lb.select_nth_unstable_by(k - 1, |a, b| b.total_cmp(a)).1;
                let far: Vec<usize> = hi
                    .iter()
                    .filter(|(h, _)| *h >= kth_lb)
                    .map(|(_, j)| *j)
                    .collect();
                let exact_of = |js: Vec<usize>| -> Vec<(usize, f64)> {
                    js.into_iter()
                        .map(|j| (j, distance2_f64(&rows[i], &rows[j])))
                        .collect()
                };
                let mut nearest = exact_of(near);
                nearest.sort_by(|a, b| a.1.total_cmp(&b.1).then(a.0.cmp(&b.0)));
                nearest.truncate(k);
                let mut furthest = exact_of(far);
                furthest.sort_by(|a, b| b.1.total_cmp(&a.1).then(a.0.cmp(&b.0)));
                furthest.truncate(k);
                Neighbours { nearest, furthest }
            })
            .collect();
        out.extend(block);
    }
    Ok(out)
}

/// The naive reference: every pair in f64, sorted; O(N²·D) time, O(N) memory per anchor.
pub fn naive(rows: &[Vec<f32>], k: usize) -> Vec<Neighbours> {
    (0..rows.len())
        .map(|i| {
            let mut d: Vec<(usize, f64)> = (0..rows.len())
                .filter(|&j| j != i)
                .map(|j| (j, distance2_f64(&rows[i], &rows[j])))
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
