//! The approximate path for large N: project descriptors onto their top principal components
//! (randomised range finder with one power iteration, Halko–Martinsson–Tropp 2011: GEMMs
//! through `gemm`, the small symmetric eigenproblem through `nalgebra`), find candidates in the
//! reduced space, and re-rank them with exact full-dimensional distances.

use nalgebra::{DMatrix, SymmetricEigen};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

use crate::spill::{PairDistances, Spilled, KCHUNK};
use crate::{exact, KnnError, Neighbours};

/// A linear map to `rank` dimensions: x ↦ Vᵀ (x − mean).
#[derive(Debug, Clone)]
pub struct Pca {
    pub mean: Vec<f32>,
    /// rank × dim, row-major (rows are orthonormal principal directions).
    pub basis: Vec<f32>,
    pub rank: usize,
    pub dim: usize,
}

fn gauss(rng: &mut ChaCha8Rng) -> f32 {
    use rand::Rng;
    let u1: f64 = rng.random_range(f64::MIN_POSITIVE..1.0);
    let u2: f64 = rng.random();
    ((-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()) as f32
}

/// C (m × n) = A (m × k) · B (k × n), all row-major f32 (`tb`: B given transposed, n × k).
fn matmul(a: &[f32], b: &[f32], m: usize, k: usize, n: usize, tb: bool) -> Vec<f32> {
    let mut c = vec![0f32; m * n];
    let (b_rs, b_cs) = if tb { (1, k as isize) } else { (n as isize, 1) };
    // SAFETY: c is m × n row-major, a is m × k row-major, b is k × n with the strides given.
    unsafe {
        nrw_gemm::gemm(
            m,
            n,
            k,
            c.as_mut_ptr(),
            1,
            n as isize,
            false,
            a.as_ptr(),
            1,
            k as isize,
            b.as_ptr(),
            b_cs,
            b_rs,
            0.0,
            1.0,
            nrw_gemm::Parallelism::Rayon(0),
        );
    }
    c
}

/// Orthonormalise the l columns of an m × l row-major matrix (QR via nalgebra, in f64).
fn orthonormal_columns(y: &[f32], m: usize, l: usize) -> Vec<f32> {
    let mat = DMatrix::from_fn(m, l, |i, j| y[i * l + j] as f64);
    let q = mat.qr().q();
    let mut out = vec![0f32; m * l];
    for i in 0..m {
        for j in 0..l {
            out[i * l + j] = q[(i, j)] as f32;
        }
    }
    out
}

/// Rows per block of a row-major pass times a matrix of `cols` columns: about 64 MiB of f32,
/// and never fewer rows than GEMM needs to block a product as it blocks one call over every
/// row (above 64 rows and above 256 products a row block; it picks its kernel from the
/// shape), unless that is all of them.
fn row_blocks(n: usize, dim: usize, cols: usize) -> Vec<std::ops::Range<usize>> {
    let least = 65.max(256 / cols.max(1) + 1);
    let size = ((64 << 20) / (4 * dim.max(1))).max(least);
    let mut out: Vec<std::ops::Range<usize>> =
        (0..n).step_by(size).map(|s| s..(s + size).min(n)).collect();
    if out.len() > 1 && out.last().is_some_and(|r| r.len() < least) {
        let last = out.pop().expect("two blocks");
        out.last_mut().expect("one block").end = last.end;
    }
    out
}

/// (x − shift) · M for every row x of `s`, M given as `cols` × dim (`tb`) or dim × `cols`,
/// block of rows by block: n × cols, row-major.
fn times(s: &Spilled, shift: &[f32], m: &[f32], cols: usize, tb: bool) -> Vec<f32> {
    let (n, dim) = (s.len(), s.dim());
    let mut out = Vec::with_capacity(n * cols);
    let mut x = Vec::new();
    for rows in row_blocks(n, dim, cols) {
        x.resize(rows.len() * dim, 0f32);
        s.rows_into(rows.clone(), shift, &mut x);
        out.extend(matmul(&x, m, rows.len(), dim, cols, tb));
    }
    out
}

/// Yᵀ (X − shift) for Y (n × l, row-major), chunk of dimensions by chunk: l × dim,
/// row-major. Each value sums over every row in one GEMM.
fn transposed_times(s: &Spilled, shift: &[f32], y: &[f32], l: usize) -> Vec<f32> {
    let (n, dim) = (s.len(), s.dim());
    let yt: Vec<f32> = (0..l)
        .flat_map(|j| (0..n).map(move |i| (i, j)))
        .map(|(i, j)| y[i * l + j])
        .collect();
    let mut out = vec![0f32; l * dim];
    let mut chunk = vec![0f32; n * KCHUNK.min(dim)];
    for k0 in (0..dim).step_by(KCHUNK) {
        let kc = KCHUNK.min(dim - k0);
        let c = &mut chunk[..n * kc];
        s.chunk(k0, kc, c);
        c.chunks_exact_mut(kc).for_each(|r| {
            r.iter_mut()
                .zip(&shift[k0..k0 + kc])
                .for_each(|(v, m)| *v -= m)
        });
        let part = matmul(&yt, c, l, n, kc, false);
        for j in 0..l {
            out[j * dim + k0..j * dim + k0 + kc].copy_from_slice(&part[j * kc..(j + 1) * kc]);
        }
    }
    out
}

/// Mean of every dimension, summed in f64 over the rows in order.
fn mean_of(s: &Spilled) -> Vec<f32> {
    let (n, dim) = (s.len(), s.dim());
    let mut mean = vec![0f64; dim];
    let mut chunk = vec![0f32; n * KCHUNK.min(dim)];
    for k0 in (0..dim).step_by(KCHUNK) {
        let kc = KCHUNK.min(dim - k0);
        s.chunk(k0, kc, &mut chunk);
        for r in chunk[..n * kc].chunks_exact(kc) {
            mean[k0..k0 + kc]
                .iter_mut()
                .zip(r)
                .for_each(|(m, v)| *m += *v as f64);
        }
    }
    mean.iter().map(|m| (m / n as f64) as f32).collect()
}

impl Pca {
    /// Fit the top `rank` principal directions of `rows` (deterministic for a seed).
    pub fn fit(rows: &[Vec<f32>], rank: usize, seed: u64) -> Result<Pca, KnnError> {
        Ok(Pca::fit_spilled(&Spilled::from_rows(rows)?, rank, seed))
    }

    /// [`Pca::fit`] of descriptors read in passes: six passes over the chunks, memory
    /// O((N + D) · (rank + 10)) beside a block of rows.
    pub fn fit_spilled(s: &Spilled, rank: usize, seed: u64) -> Pca {
        let (n, dim) = (s.len(), s.dim());
        let rank = rank.min(dim).min(n.saturating_sub(1)).max(1);
        let mean = mean_of(s);
        let l = (rank + 10).min(dim).min(n);
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let omega: Vec<f32> = (0..dim * l).map(|_| gauss(&mut rng)).collect();
        // Range of X: Y = X Ω, one power iteration (X Xᵀ) Y for sharper directions.
        let y = orthonormal_columns(&times(s, &mean, &omega, l, false), n, l);
        // Z = Xᵀ Y (dim × l) = (Yᵀ X)ᵀ.
        let b0 = transposed_times(s, &mean, &y, l); // l × dim
        let z: Vec<f32> = (0..dim)
            .flat_map(|d| (0..l).map(move |j| (d, j)))
            .map(|(d, j)| b0[j * dim + d])
            .collect();
        drop(b0);
        let z = orthonormal_columns(&z, dim, l);
        let y = orthonormal_columns(&times(s, &mean, &z, l, false), n, l);
        drop(z);
        let b = transposed_times(s, &mean, &y, l); // l × dim, X ≈ Y B
                                                   // B Bᵀ = U Σ² Uᵀ; principal directions V = Bᵀ U Σ⁻¹.
        let bbt = matmul(&b, &b, l, dim, l, true);
        let eig = SymmetricEigen::new(DMatrix::from_fn(l, l, |i, j| bbt[i * l + j] as f64));
        let mut order: Vec<usize> = (0..l).collect();
        order.sort_by(|&i, &j| eig.eigenvalues[j].total_cmp(&eig.eigenvalues[i]));
        let mut basis = vec![0f32; rank * dim];
        for (r, &e) in order.iter().take(rank).enumerate() {
            let s = eig.eigenvalues[e].max(0.0).sqrt();
            if s <= 0.0 {
                continue; // a degenerate direction (constant data): leave it zero
            }
            for d in 0..dim {
                let mut acc = 0f64;
                for i in 0..l {
                    acc += b[i * dim + d] as f64 * eig.eigenvectors[(i, e)];
                }
                basis[r * dim + d] = (acc / s) as f32;
            }
        }
        Pca {
            mean,
            basis,
            rank,
            dim,
        }
    }

    /// Reduced coordinates of every row.
    pub fn project(&self, rows: &[Vec<f32>]) -> Vec<Vec<f32>> {
        match Spilled::from_rows(rows) {
            Ok(s) => self.project_spilled(&s),
            Err(_) => Vec::new(),
        }
    }

    /// Reduced coordinates of every row of descriptors read in passes.
    pub fn project_spilled(&self, s: &Spilled) -> Vec<Vec<f32>> {
        let z = times(s, &self.mean, &self.basis, self.rank, true);
        z.chunks(self.rank).map(|c| c.to_vec()).collect()
    }
}

/// Approximate neighbours: candidates from the reduced space (`oversample`·k of them for
/// each list), re-ranked with exact full-dimensional distances.
pub fn approximate(
    rows: &[Vec<f32>],
    k: usize,
    rank: usize,
    oversample: usize,
    seed: u64,
) -> Result<Vec<Neighbours>, KnnError> {
    approximate_spilled(&Spilled::from_rows(rows)?, k, rank, oversample, seed)
}

/// [`approximate`] of descriptors read in passes: the same lists, to the bit.
pub fn approximate_spilled(
    s: &Spilled,
    k: usize,
    rank: usize,
    oversample: usize,
    seed: u64,
) -> Result<Vec<Neighbours>, KnnError> {
    let n = s.len();
    if k == 0 || k + 1 > n {
        return Err(KnnError::TooFew { k, need: k + 1, n });
    }
    let pca = Pca::fit_spilled(s, rank, seed);
    let reduced = pca.project_spilled(s);
    let c = (k * oversample.max(1)).min(n - 1);
    let cand = exact(&reduced, c)?;
    let measured = PairDistances::measure(
        s,
        cand.iter()
            .enumerate()
            .flat_map(|(i, nb)| nb.nearest.iter().chain(&nb.furthest).map(move |p| (i, p.0))),
    );
    Ok(cand
        .into_iter()
        .enumerate()
        .map(|(i, nb)| {
            let rerank = |ids: Vec<(usize, f64)>, far: bool| {
                let mut v: Vec<(usize, f64)> = ids
                    .into_iter()
                    .map(|(j, _)| (j, measured.get(i, j)))
                    .collect();
                crate::sort_list(&mut v, far);
                v.truncate(k);
                v
            };
            Neighbours {
                nearest: rerank(nb.nearest, false),
                furthest: rerank(nb.furthest, true),
            }
        })
        .collect())
}

/// Fraction of the exact lists' ids the approximate lists also hold (nearest and furthest).
pub fn recall(exact: &[Neighbours], approx: &[Neighbours]) -> (f64, f64) {
    let frac = |get: fn(&Neighbours) -> &Vec<(usize, f64)>| {
        let (mut hit, mut all) = (0usize, 0usize);
        for (e, a) in exact.iter().zip(approx) {
            let ids: Vec<usize> = get(a).iter().map(|p| p.0).collect();
            hit += get(e).iter().filter(|p| ids.contains(&p.0)).count();
            all += get(e).len();
        }
        hit as f64 / all.max(1) as f64
    };
    (frac(|n| &n.nearest), frac(|n| &n.furthest))
}
