//! The exact path over [`Spilled`] descriptors: interval bounds from blocked GEMM dot
//! products select candidates (phase 1), the pairs whose order the intervals cannot prove
//! get exact f64 distances in one more pass over the chunks (phase 2), and each anchor's
//! lists are ranked (phase 3). Memory: the N × N dot products while they fit `max_bytes`
//! (else BLOCK × N), one chunk of every row (N × KCHUNK), and the candidates.

use nrw_gemm::Parallelism;
use rayon::prelude::*;

use crate::spill::{From32, PairDistances, Spilled, KCHUNK};
use crate::Neighbours;

/// Anchors per GEMM block: memory is BLOCK × N f64 (+ the element type) for the dot products.
const BLOCK: usize = 256;

/// out (m × w, row-major) = A · Bᵀ, where A holds m rows of `kc` values `a_rs` apart and B
/// holds w rows of `kc` values `b_rs` apart. The slices' lengths are checked, so the GEMM
/// cannot read outside them.
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
        nrw_gemm::gemm(
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
            Parallelism::Rayon(0),
        );
    }
}

/// A GEMM element type: f32 (fast) or f64 (narrow error bound).
pub(crate) trait Dot: From32 + Into<f64> + nrw_gemm::Element {
    const ZERO: Self;
    const ONE: Self;
    /// Unit roundoff u = ε/2.
    const U: f64;
}

impl Dot for f32 {
    const ZERO: Self = 0.0;
    const ONE: Self = 1.0;
    const U: f64 = f32::EPSILON as f64 / 2.0;
}

impl Dot for f64 {
    const ZERO: Self = 0.0;
    const ONE: Self = 1.0;
    const U: f64 = f64::EPSILON / 2.0;
}

/// One anchor's candidates (j, interval low, interval high) before ranking, and whether each
/// list's intervals already prove its order to seven digits.
struct Pending {
    near: Vec<(usize, f64, f64)>,
    far: Vec<(usize, f64, f64)>,
    near_certain: bool,
    far_certain: bool,
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

/// Whether a list's intervals (sorted by midpoint) are disjoint and narrower than 1e-7 of
/// their distance: the intervals then prove which k come first, and only those k are
/// measured exactly. Only f64 dot products get there.
fn certain(v: &mut [(usize, f64, f64)]) -> bool {
    v.sort_by(|a, b| (a.1 + a.2).total_cmp(&(b.1 + b.2)));
    v.iter().all(|p| p.1 > 0.0 && p.2 - p.1 <= 2e-7 * p.1) && v.windows(2).all(|w| w[0].2 < w[1].1)
}

/// The rounding bounds of every dot product (see the crate's documentation).
struct Bounds {
    norm: Vec<f64>,
    eps4: Vec<f64>,
    gamma: f64,
    u: f64,
}

impl Bounds {
    fn new<T: Dot>(s: &Spilled) -> Bounds {
        // Each dot product is a sum of f64-added partial dots over ≤ KCHUNK terms, so the
        // bound is γ_KCHUNK Σ‖a_c‖‖b_c‖ ≤ γ_KCHUNK ‖a‖‖b‖ (Cauchy–Schwarz), not γ_D: for
        // reference-tier Grams (D = 305,888) the difference between re-ranking a few
        // candidates per anchor and re-ranking them all. (Adding the chunks in f64
        // contributes at most chunks·ε₆₄·‖a‖‖b‖ more.)
        let (u, dim) = (T::U, s.dim());
        let terms = dim.min(KCHUNK) as f64;
        Bounds {
            norm: s.norm2().iter().map(|v| v.sqrt()).collect(),
            eps4: s.norm2().iter().map(|v| 4.0 * f64::EPSILON * v).collect(),
            gamma: (terms * u) / (1.0 - terms * u) + dim.div_ceil(KCHUNK) as f64 * f64::EPSILON,
            u,
        }
    }

    /// Anchor i's candidates from its row of dot products; `lo`/`hi` are scratch of N.
    fn pending(
        &self,
        norm2: &[f64],
        i: usize,
        row: &[f64],
        k: usize,
        lo: &mut [f64],
        hi: &mut [f64],
    ) -> Pending {
        let n = row.len();
        // Interval of every distance: approx ± bound (bound also covers rounding of the
        // approximate sum itself, at 4 ulps of its largest term). One straight loop over
        // arrays, so it vectorises.
        let (gi, ei) = (
            2.0 * self.gamma * self.norm[i],
            4.0 * f64::EPSILON * norm2[i],
        );
        for j in 0..n {
            let d: f64 = row[j];
            let approx = norm2[i] + norm2[j] - 2.0 * d;
            let bound = gi * self.norm[j] + ei + self.eps4[j] + 2.0 * self.u * d.abs();
            lo[j] = approx - bound;
            hi[j] = approx + bound;
        }
        let others = || (0..i).chain(i + 1..n);
        // The k-th smallest upper end and the k-th largest lower end.
        let mut low_hi = Smallest::new(k);
        let mut high_lo = Smallest::new(k);
        for j in others() {
            low_hi.push(hi[j]);
            high_lo.push(-lo[j]);
        }
        let (kth_ub, kth_lb) = (low_hi.kth(), -high_lo.kth());
        // j can be among the true k nearest only if its lower end does not exceed the k-th
        // smallest upper end; among the k furthest only if its upper end reaches the k-th
        // largest lower end.
        let mut near: Vec<_> = others()
            .filter(|&j| lo[j] <= kth_ub)
            .map(|j| (j, lo[j], hi[j]))
            .collect();
        let mut far: Vec<_> = others()
            .filter(|&j| hi[j] >= kth_lb)
            .map(|j| (j, lo[j], hi[j]))
            .collect();
        let near_certain = certain(&mut near);
        // The nearest list is ranked first: when it is re-ranked, a point on both lists
        // counts as exact in the furthest list too (its interval is gone), so that list is
        // certain only if the nearest was or they share no point (marked in `lo`, free now).
        near.iter().for_each(|p| lo[p.0] = f64::NAN);
        let far_certain =
            certain(&mut far) && (near_certain || far.iter().all(|f| !lo[f.0].is_nan()));
        Pending {
            near,
            far,
            near_certain,
            far_certain,
        }
    }
}

/// Phase 1: every anchor's candidates, from GEMM dot products of `T` chunk by chunk.
fn candidates<T: Dot>(s: &Spilled, k: usize, max_bytes: usize) -> Vec<Pending> {
    let (n, dim) = (s.len(), s.dim());
    let b = Bounds::new::<T>(s);
    let norm2 = s.norm2();
    let sym = n * n * 8 <= max_bytes;
    let mut full = vec![0f64; if sym { n * n } else { BLOCK.min(n) * n }];
    let mut part = vec![T::ZERO; BLOCK.min(n) * n];
    let mut buf = vec![T::ZERO; n * KCHUNK.min(dim)];
    // Symmetry: while the whole N × N matrix fits in `max_bytes`, it is filled chunk by
    // chunk, each block computing only the columns from its own first row on, then
    // mirrored: every dot product is computed once. Beyond that, each block of anchors
    // computes full rows, reading every chunk again.
    if sym {
        for k0 in (0..dim).step_by(KCHUNK) {
            let kc = KCHUNK.min(dim - k0);
            s.chunk(k0, kc, &mut buf);
            for start in (0..n).step_by(BLOCK) {
                let (bl, width) = (BLOCK.min(n - start), n - start);
                let part = &mut part[..bl * width];
                let rest = &buf[start * kc..n * kc];
                gemm_abt(part, bl, width, kc, rest, kc, rest, kc);
                for (r, src) in part.chunks_exact(width).enumerate() {
                    let dst = &mut full[(start + r) * n + start..(start + r + 1) * n];
                    dst.iter_mut().zip(src).for_each(|(d, p)| *d += (*p).into());
                }
            }
        }
        for start in (0..n).step_by(BLOCK) {
            let bl = BLOCK.min(n - start);
            for r in start..start + bl {
                for j in start + bl..n {
                    full[j * n + r] = full[r * n + j];
                }
            }
        }
    }
    let mut out = Vec::with_capacity(n);
    for start in (0..n).step_by(BLOCK) {
        let bl = BLOCK.min(n - start);
        if !sym {
            full[..bl * n].fill(0.0);
            for k0 in (0..dim).step_by(KCHUNK) {
                let kc = KCHUNK.min(dim - k0);
                s.chunk(k0, kc, &mut buf);
                let part = &mut part[..bl * n];
                let all = &buf[..n * kc];
                gemm_abt(part, bl, n, kc, &all[start * kc..], kc, all, kc);
                for (r, src) in part.chunks_exact(n).enumerate() {
                    let dst = &mut full[r * n..(r + 1) * n];
                    dst.iter_mut().zip(src).for_each(|(d, p)| *d += (*p).into());
                }
            }
        }
        let dots = if sym {
            &full[start * n..(start + bl) * n]
        } else {
            &full[..bl * n]
        };
        let block: Vec<Pending> = (0..bl)
            .into_par_iter()
            .map_init(
                || (vec![0f64; n], vec![0f64; n]),
                |(lo, hi), r| b.pending(norm2, start + r, &dots[r * n..(r + 1) * n], k, lo, hi),
            )
            .collect();
        out.extend(block);
    }
    out
}

/// The part of a list phase 3 ranks: all of an uncertain list's candidates, only the k a
/// certain list's disjoint intervals already put first (`certain` left it sorted by
/// midpoint, so the nearest are at its start and the furthest at its end).
fn ranked_part(
    list: &[(usize, f64, f64)],
    sure: bool,
    furthest: bool,
    k: usize,
) -> &[(usize, f64, f64)] {
    match (sure, furthest) {
        (false, _) => list,
        (true, false) => &list[..k.min(list.len())],
        (true, true) => &list[list.len().saturating_sub(k)..],
    }
}

/// The pairs phase 3 measures exactly: every candidate it ranks. Even a certain list's
/// distances are measured, because its midpoints come from GEMM dot products whose
/// summation order depends on the instruction set: stored distances must not.
fn pairs_to_measure(pending: &[Pending], k: usize) -> impl Iterator<Item = (usize, usize)> + '_ {
    pending.iter().enumerate().flat_map(move |(i, p)| {
        let lists = [
            ranked_part(&p.near, p.near_certain, false, k),
            ranked_part(&p.far, p.far_certain, true, k),
        ];
        lists
            .into_iter()
            .flat_map(move |list| list.iter().map(move |c| (i, c.0)))
    })
}

/// Phase 3: one list ranked by exact distances (ties by the lower index), cut to k; a
/// certain list's intervals have already chosen its k.
fn rank(
    i: usize,
    list: &[(usize, f64, f64)],
    sure: bool,
    furthest: bool,
    k: usize,
    exact: &dyn Fn(usize, usize) -> f64,
) -> Vec<(usize, f64)> {
    let mut out: Vec<(usize, f64)> = ranked_part(list, sure, furthest, k)
        .iter()
        .map(|p| (p.0, exact(i, p.0)))
        .collect();
    crate::sort_list(&mut out, furthest);
    out.truncate(k);
    out
}

/// Exact k nearest and k furthest of every row of `s` with dot products in `T`.
pub(crate) fn exact_in<T: Dot>(s: &Spilled, k: usize, max_bytes: usize) -> Vec<Neighbours> {
    let pending = candidates::<T>(s, k, max_bytes);
    let measured = PairDistances::measure(s, pairs_to_measure(&pending, k));
    let exact = |i: usize, j: usize| measured.get(i, j);
    pending
        .par_iter()
        .enumerate()
        .map(|(i, p)| Neighbours {
            nearest: rank(i, &p.near, p.near_certain, false, k, &exact),
            furthest: rank(i, &p.far, p.far_certain, true, k, &exact),
        })
        .collect()
}
