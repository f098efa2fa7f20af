//! The approximate path for large N: project descriptors onto their top principal components
//! (randomised range finder with one power iteration, Halko–Martinsson–Tropp 2011: GEMMs
//! through `gemm`, the small symmetric eigenproblem through `nalgebra`), find candidates in the
//! reduced space, and re-rank them with exact full-dimensional distances.

use nalgebra::{DMatrix, SymmetricEigen};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

use crate::{distance2_f64, exact, validate, KnnError, Neighbours};

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
        gemm::gemm(
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
            false,
            false,
            false,
            gemm::Parallelism::Rayon(0),
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

impl Pca {
    /// Fit the top `rank` principal directions of `rows` (deterministic for a seed).
    pub fn fit(rows: &[Vec<f32>], rank: usize, seed: u64) -> Result<Pca, KnnError> {
        let dim = validate(rows)?;
        let n = rows.len();
        let rank = rank.min(dim).min(n.saturating_sub(1)).max(1);
        let mut mean = vec![0f64; dim];
        for r in rows {
            for (m, v) in mean.iter_mut().zip(r) {
                *m += *v as f64;
            }
        }
        let mean: Vec<f32> = mean.iter().map(|m| (m / n as f64) as f32).collect();
        let x: Vec<f32> = rows
            .iter()
            .flat_map(|r| r.iter().zip(&mean).map(|(v, m)| v - m))
            .collect();
        let l = (rank + 10).min(dim).min(n);
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let omega: Vec<f32> = (0..dim * l).map(|_| gauss(&mut rng)).collect();
        // Range of X: Y = X Ω, one power iteration (X Xᵀ) Y for sharper directions.
        let mut y = orthonormal_columns(&matmul(&x, &omega, n, dim, l, false), n, l);
        // Z = Xᵀ Y (dim × l): X is n × dim row-major, so Xᵀ Y = (Yᵀ X)ᵀ.
        let yt: Vec<f32> = (0..l)
            .flat_map(|j| (0..n).map(move |i| (i, j)))
            .map(|(i, j)| y[i * l + j])
            .collect();
        let b0 = matmul(&yt, &x, l, n, dim, false); // l × dim
        let z: Vec<f32> = (0..dim)
            .flat_map(|d| (0..l).map(move |j| (d, j)))
            .map(|(d, j)| b0[j * dim + d])
            .collect();
        let z = orthonormal_columns(&z, dim, l);
        y = orthonormal_columns(&matmul(&x, &z, n, dim, l, false), n, l);
        let yt: Vec<f32> = (0..l)
            .flat_map(|j| (0..n).map(move |i| (i, j)))
            .map(|(i, j)| y[i * l + j])
            .collect();
        let b = matmul(&yt, &x, l, n, dim, false); // l × dim, X ≈ Y B
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
        Ok(Pca {
            mean,
            basis,
            rank,
            dim,
        })
    }

    /// Reduced coordinates of every row.
    pub fn project(&self, rows: &[Vec<f32>]) -> Vec<Vec<f32>> {
        let x: Vec<f32> = rows
            .iter()
            .flat_map(|r| r.iter().zip(&self.mean).map(|(v, m)| v - m))
            .collect();
        let z = matmul(&x, &self.basis, rows.len(), self.dim, self.rank, true);
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
    let n = rows.len();
    validate(rows)?;
    if k == 0 || k + 1 > n {
        return Err(KnnError::TooFew { k, need: k + 1, n });
    }
    let pca = Pca::fit(rows, rank, seed)?;
    let reduced = pca.project(rows);
    let c = (k * oversample.max(1)).min(n - 1);
    let cand = exact(&reduced, c)?;
    Ok(cand
        .into_iter()
        .enumerate()
        .map(|(i, nb)| {
            let rerank = |ids: Vec<(usize, f64)>, far: bool| {
                let mut v: Vec<(usize, f64)> = ids
                    .into_iter()
                    .map(|(j, _)| (j, distance2_f64(&rows[i], &rows[j])))
                    .collect();
                if far {
                    v.sort_by(|a, b| b.1.total_cmp(&a.1).then(a.0.cmp(&b.0)));
                } else {
                    v.sort_by(|a, b| a.1.total_cmp(&b.1).then(a.0.cmp(&b.0)));
                }
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
