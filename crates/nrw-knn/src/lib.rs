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
//! re-ranked with Σ(a−b)² summed in f64 unless their intervals already prove the order and
//! seven digits. The result equals a naive f64 double loop: same ids, same order, distances
//! to 1e-7 relative. Ties are broken by the lower index, so tables are deterministic.

pub mod approx;

use std::collections::HashMap;
use std::sync::Mutex;

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

/// The k smallest values pushed so far, kept sorted; `kth` is the largest of them (∞ until
/// k values arrived). Insertion is rare once the list is full, so a pass is O(N).
struct Smallest {
    v: Vec<f64>,
    k: usize,
}

impl Smallest {
    fn new(k: usize) -> Self {
        Smallest {
            v: Vec::with_capacity(k + 1),
            k,
        }
    }
    fn push(&mut self, x: f64) {
        if self.v.len() == self.k && x >= self.v[self.k - 1] {
            return;
        }
        let at = self.v.partition_point(|y| *y <= x);
        self.v.insert(at, x);
        self.v.truncate(self.k);
    }
    fn kth(&self) -> f64 {
        if self.v.len() < self.k {
            f64::INFINITY
        } else {
            self.v[self.k - 1]
        }
    }
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
        r.iter()
            .enumerate()
            .find(|(_, v)| !v.is_finite())
            .map(|(index, value)| KnnError::NotFinite {
                row,
                index,
                value: *value,
            })
    });
    match bad {
        Some(e) => Err(e),
        None => Ok(dim),
    }
}

/// Anchors per GEMM block: memory is BLOCK × N f64 (+ the element type) for the dot products.
const BLOCK: usize = 256;

/// Below this dimension a re-ranked distance is cheaper than the cache's lock and lookup
/// (with PCA-reduced 16-value vectors the cache made the approximate path 3× slower).
const CACHE_MIN_DIM: usize = 4096;

/// Largest N × N f64 dot-product matrix kept whole to compute each pair once (N ≤ 8,192).
const SYM_MAX_BYTES: usize = 512 << 20;

/// Terms per GEMM in a dot product; the partial dots are added in f64, which keeps the
/// rounding bound at γ_KCHUNK whatever the dimension. The extra additions cost
/// BLOCK·N per chunk against BLOCK·N·KCHUNK multiply-adds.
const KCHUNK: usize = 4096;

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
    let n = rows.len();
    let dim = validate(rows)?;
    if k == 0 || k + 1 > n {
        return Err(KnnError::TooFew { k, need: k + 1, n });
    }
    // Dot products in f64 when re-ranking f32 candidates would cost more than the GEMM itself
    // (small N: each anchor re-ranks ~2k candidates, each a cache-missing pass over D values,
    // measured here ≈ 36 GEMM dot products; see docs/triplets.md) and, where the blocked path
    // needs an f64 copy of the descriptors, that copy stays under 1 GiB. f64 intervals are so
    // narrow that re-ranking is rarely needed at all.
    if n < 64 * k && (n * n * 8 <= max_bytes || n * dim * 8 <= 1 << 30) {
        exact_with::<f64>(rows, k, dim, max_bytes)
    } else {
        exact_with::<f32>(rows, k, dim, max_bytes)
    }
}

/// out (m × w, row-major) = A · Bᵀ, where A holds m rows of `kc` values `a_rs` apart and B
/// holds w rows of `kc` values `b_rs` apart (rows of a descriptor matrix or of a gathered
/// chunk). The slices' lengths are checked, so the GEMM cannot read outside them.
#[allow(clippy::too_many_arguments)]
fn gemm_abt<T: Dot>(
    out: &mut [T],
    m: usize,
    w: usize,
    kc: usize,
    a: &[T],
    a_rs: usize,
    b: &[T],
    b_rs: usize,
) {
    if m == 0 || w == 0 {
        return;
    }
    assert!(out.len() >= m * w && kc <= a_rs && kc <= b_rs);
    assert!(a.len() >= (m - 1) * a_rs + kc && b.len() >= (w - 1) * b_rs + kc);
    // SAFETY: dst is m × w row-major inside `out`; lhs element (i, k) is a[i·a_rs + k] and
    // rhs element (k, j) is b[j·b_rs + k], all inside the slices by the asserts above.
    unsafe {
        gemm::gemm(
            m,
            w,
            kc,
            out.as_mut_ptr(),
            1,
            w as isize,
            false,
            a.as_ptr(),
            1,
            a_rs as isize,
            b.as_ptr(),
            b_rs as isize,
            1,
            T::ZERO,
            T::ONE,
            false,
            false,
            false,
            Parallelism::Rayon(0),
        );
    }
}

/// A GEMM element type: f32 (fast) or f64 (narrow error bound).
trait Dot: Copy + Send + Sync + Into<f64> + 'static {
    const ZERO: Self;
    const ONE: Self;
    /// Unit roundoff u = ε/2.
    const U: f64;
    fn from_f32(v: f32) -> Self;
}

impl Dot for f32 {
    const ZERO: Self = 0.0;
    const ONE: Self = 1.0;
    const U: f64 = f32::EPSILON as f64 / 2.0;
    fn from_f32(v: f32) -> Self {
        v
    }
}

impl Dot for f64 {
    const ZERO: Self = 0.0;
    const ONE: Self = 1.0;
    const U: f64 = f64::EPSILON / 2.0;
    fn from_f32(v: f32) -> Self {
        v as f64
    }
}

fn exact_with<T: Dot>(
    rows: &[Vec<f32>],
    k: usize,
    dim: usize,
    max_bytes: usize,
) -> Result<Vec<Neighbours>, KnnError> {
    let n = rows.len();
    let norm2: Vec<f64> = rows
        .par_iter()
        .map(|r| r.iter().map(|v| (*v as f64) * (*v as f64)).sum())
        .collect();
    let norm: Vec<f64> = norm2.iter().map(|v| v.sqrt()).collect();
    let eps4: Vec<f64> = norm2.iter().map(|v| 4.0 * f64::EPSILON * v).collect();
    let u = T::U;
    // Each dot product is a sum of f64-added partial dots over ≤ KCHUNK terms, so the f32
    // bound is γ_KCHUNK Σ‖a_c‖‖b_c‖ ≤ γ_KCHUNK ‖a‖‖b‖ (Cauchy–Schwarz), not γ_D: for
    // reference-tier Grams (D = 305,888) that is 2.4·10⁻⁴ instead of 1.8·10⁻², the
    // difference between re-ranking a few candidates per anchor and re-ranking them all.
    // (Adding the chunks in f64 contributes at most chunks·ε₆₄·‖a‖‖b‖ more.)
    let terms = dim.min(KCHUNK) as f64;
    let gamma = (terms * u) / (1.0 - terms * u) + dim.div_ceil(KCHUNK) as f64 * f64::EPSILON;
    let mut out = Vec::with_capacity(n);
    // Exact distances already computed for another anchor (long rows only): neighbour
    // relations are often mutual, and at reference-tier size each distance streams 2.4 MB.
    // distance2_f64 is symmetric to the bit ((a−b)² = (b−a)²), so the cache changes no result.
    let known: Mutex<HashMap<(u32, u32), f64>> = Mutex::new(HashMap::new());
    let exact_distance = |i: usize, j: usize| -> f64 {
        if dim < CACHE_MIN_DIM {
            return distance2_f64(&rows[i], &rows[j]);
        }
        let key = (i.min(j) as u32, i.max(j) as u32);
        if let Some(d) = known.lock().expect("no panic holds the lock").get(&key) {
            return *d;
        }
        let d = distance2_f64(&rows[i], &rows[j]);
        known
            .lock()
            .expect("no panic holds the lock")
            .insert(key, d);
        d
    };
    // Symmetry: while the whole N × N matrix fits in `max_bytes`, it is filled chunk by chunk
    // (a K-chunk of every row gathered at a time, n × 4,096 values, never a second copy of the
    // descriptors), each block computing only the columns from its own first row on, then
    // mirrored: every dot product is computed once. Beyond that, blocks compute full rows from
    // a contiguous copy and memory for dot products stays O(BLOCK · N).
    let sym = n * n * 8 <= max_bytes;
    let mut full = vec![0f64; if sym { n * n } else { BLOCK.min(n) * n }];
    let mut part = vec![T::ZERO; BLOCK.min(n) * n];
    if sym {
        let mut buf = vec![T::ZERO; n * KCHUNK.min(dim)];
        for k0 in (0..dim).step_by(KCHUNK) {
            let kc = KCHUNK.min(dim - k0);
            let buf = &mut buf[..n * kc];
            buf.par_chunks_mut(kc)
                .zip(rows.par_iter())
                .for_each(|(d, r)| {
                    d.iter_mut()
                        .zip(&r[k0..k0 + kc])
                        .for_each(|(d, v)| *d = T::from_f32(*v))
                });
            for start in (0..n).step_by(BLOCK) {
                let (b, width) = (BLOCK.min(n - start), n - start);
                let part = &mut part[..b * width];
                let rest = &buf[start * kc..];
                gemm_abt(part, b, width, kc, rest, kc, rest, kc);
                for (r, src) in part.chunks_exact(width).enumerate() {
                    let dst = &mut full[(start + r) * n + start..(start + r + 1) * n];
                    dst.iter_mut().zip(src).for_each(|(d, p)| *d += (*p).into());
                }
            }
        }
        for start in (0..n).step_by(BLOCK) {
            let b = BLOCK.min(n - start);
            for r in start..start + b {
                for j in start + b..n {
                    full[j * n + r] = full[r * n + j];
                }
            }
        }
    }
    let mut flat: Vec<T> = Vec::new();
    if !sym {
        flat = vec![T::ZERO; n * dim];
        flat.par_chunks_mut(dim.max(1))
            .zip(rows.par_iter())
            .for_each(|(dst, r)| {
                dst.iter_mut()
                    .zip(r)
                    .for_each(|(d, v)| *d = T::from_f32(*v))
            });
    }
    for start in (0..n).step_by(BLOCK) {
        let b = BLOCK.min(n - start);
        if !sym {
            full[..b * n].fill(0.0);
            for k0 in (0..dim).step_by(KCHUNK) {
                let kc = KCHUNK.min(dim - k0);
                let part = &mut part[..b * n];
                gemm_abt(
                    part,
                    b,
                    n,
                    kc,
                    &flat[start * dim + k0..],
                    dim,
                    &flat[k0..],
                    dim,
                );
                for (r, src) in part.chunks_exact(n).enumerate() {
                    let dst = &mut full[r * n..(r + 1) * n];
                    dst.iter_mut().zip(src).for_each(|(d, p)| *d += (*p).into());
                }
            }
        }
        let dots = if sym {
            &full[start * n..(start + b) * n]
        } else {
            &full[..b * n]
        };
        let block: Vec<Neighbours> = (0..b)
            .into_par_iter()
            .map_init(
                || (vec![0f64; n], vec![0f64; n]),
                |(lo, hi), r| {
                    let i = start + r;
                    let row = &dots[r * n..(r + 1) * n];
                    // Interval of every distance: approx ± bound (bound also covers rounding of
                    // the approximate sum itself, at 4 ulps of its largest term). One straight
                    // loop over arrays, so it vectorises.
                    let (gi, ei) = (2.0 * gamma * norm[i], 4.0 * f64::EPSILON * norm2[i]);
                    for j in 0..n {
                        let d: f64 = row[j];
                        let approx = norm2[i] + norm2[j] - 2.0 * d;
                        let bound = gi * norm[j] + ei + eps4[j] + 2.0 * u * d.abs();
                        lo[j] = approx - bound;
                        hi[j] = approx + bound;
                    }
                    let others = || (0..i).chain(i + 1..n);
                    // Pass 1: the k-th smallest upper end and the k-th largest lower end.
                    let mut low_hi = Smallest::new(k);
                    let mut high_lo = Smallest::new(k);
                    for j in others() {
                        low_hi.push(hi[j]);
                        high_lo.push(-lo[j]);
                    }
                    let (kth_ub, kth_lb) = (low_hi.kth(), -high_lo.kth());
                    // Pass 2: j can be among the true k nearest only if its lower end does not
                    // exceed the k-th smallest upper end; among the k furthest only if its upper
                    // end reaches the k-th largest lower end.
                    let near: Vec<usize> = others().filter(|&j| lo[j] <= kth_ub).collect();
                    let far: Vec<usize> = others().filter(|&j| hi[j] >= kth_lb).collect();
                    // Re-rank with exact distances, each computed once: once the lists are
                    // drawn, lo/hi are free, so lo[j] caches j's distance and a NaN in hi[j]
                    // marks it cached (small N makes the two lists overlap). A list whose
                    // intervals are disjoint (its order is certain) and narrower than 1e-7 of
                    // their distance keeps the midpoints: re-ranking could change nothing
                    // beyond the seventh digit. Only f64 dot products get there.
                    let mut rank = |js: Vec<usize>, furthest: bool| -> Vec<(usize, f64)> {
                        let mut v: Vec<(usize, f64, f64)> =
                            js.iter().map(|&j| (j, lo[j], hi[j])).collect();
                        v.sort_by(|a, b| (a.1 + a.2).total_cmp(&(b.1 + b.2)));
                        let certain = v.iter().all(|p| p.1 > 0.0 && p.2 - p.1 <= 2e-7 * p.1)
                            && v.windows(2).all(|w| w[0].2 < w[1].1);
                        let mut out: Vec<(usize, f64)> = if certain {
                            v.iter().map(|p| (p.0, 0.5 * (p.1 + p.2))).collect()
                        } else {
                            js.into_iter()
                                .map(|j| {
                                    if !hi[j].is_nan() {
                                        lo[j] = exact_distance(i, j);
                                        hi[j] = f64::NAN;
                                    }
                                    (j, lo[j])
                                })
                                .collect()
                        };
                        if furthest {
                            out.sort_by(|a, b| b.1.total_cmp(&a.1).then(a.0.cmp(&b.0)));
                        } else {
                            out.sort_by(|a, b| a.1.total_cmp(&b.1).then(a.0.cmp(&b.0)));
                        }
                        out.truncate(k);
                        out
                    };
                    let nearest = rank(near, false);
                    let furthest = rank(far, true);
                    Neighbours { nearest, furthest }
                },
            )
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
