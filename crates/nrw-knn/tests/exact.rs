//! The exact path equals a naive f64 double loop, including on the hard cases.

use nrw_knn::{exact, naive, KnnError};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

fn random(n: usize, dim: usize, seed: u64) -> Vec<Vec<f32>> {
    let mut r = ChaCha8Rng::seed_from_u64(seed);
    (0..n)
        .map(|_| (0..dim).map(|_| r.random_range(-1.0f32..1.0)).collect())
        .collect()
}

fn same(a: &[nrw_knn::Neighbours], b: &[nrw_knn::Neighbours]) {
    assert_eq!(a.len(), b.len());
    for (i, (x, y)) in a.iter().zip(b).enumerate() {
        let ids = |v: &[(usize, f64)]| v.iter().map(|p| p.0).collect::<Vec<_>>();
        assert_eq!(ids(&x.nearest), ids(&y.nearest), "anchor {i}: nearest");
        assert_eq!(ids(&x.furthest), ids(&y.furthest), "anchor {i}: furthest");
        for (p, q) in x
            .nearest
            .iter()
            .chain(&x.furthest)
            .zip(y.nearest.iter().chain(&y.furthest))
        {
            assert!(
                (p.1 - q.1).abs() <= 1e-6 * q.1.abs().max(f64::MIN_POSITIVE),
                "anchor {i}: {} vs {}",
                p.1,
                q.1
            );
        }
    }
}

#[test]
fn random_descriptors_match_the_naive_loop_exactly() {
    // N < 64k runs f64 dot products, N ≥ 64k f32 ones: both paths; 9,000 values are
    // three GEMM chunks (4,096 + 4,096 + 808) summed in f64, in both.
    for (n, dim, k) in [
        (300, 64, 20),
        (70, 9000, 1),
        (40, 9000, 3),
        (600, 9, 20),
        (120, 2080, 5),
        (400, 300, 5),
        (700, 9, 3),
    ] {
        let rows = random(n, dim, n as u64);
        let want = naive(&rows, k);
        same(&exact(&rows, k).unwrap(), &want);
        // The blocked path that large N takes (each pair computed twice, no N × N matrix).
        same(
            &nrw_knn::exact_with_matrix_limit(&rows, k, 0).unwrap(),
            &want,
        );
    }
}

#[test]
fn clusters_of_near_duplicates_are_ordered_right() {
    // Where f32 GEMM loses the digits: points 1e-4 apart around a centre of norm ~10.
    let mut r = ChaCha8Rng::seed_from_u64(3);
    let centre: Vec<f32> = (0..64).map(|_| r.random_range(5.0f32..6.0)).collect();
    let rows: Vec<Vec<f32>> = (0..200)
        .map(|_| {
            centre
                .iter()
                .map(|c| c + r.random_range(-1e-4f32..1e-4))
                .collect()
        })
        .collect();
    same(&exact(&rows, 20).unwrap(), &naive(&rows, 20));
}

#[test]
fn duplicates_identical_rows_and_ties_go_by_index() {
    let mut rows = random(50, 16, 9);
    rows[7] = rows[3].clone();
    rows[20] = rows[3].clone();
    let e = exact(&rows, 5).unwrap();
    assert_eq!(e[3].nearest[..2], [(7, 0.0), (20, 0.0)]);
    same(&e, &naive(&rows, 5));
    let all = vec![vec![0.25f32; 8]; 12];
    let e = exact(&all, 4).unwrap();
    assert_eq!(
        e[5].nearest.iter().map(|p| p.0).collect::<Vec<_>>(),
        [0, 1, 2, 3]
    );
    assert_eq!(
        e[0].furthest.iter().map(|p| p.0).collect::<Vec<_>>(),
        [1, 2, 3, 4]
    );
}

#[test]
fn tiny_n_and_k_equal_to_n_minus_one() {
    let two = random(2, 10, 1);
    let e = exact(&two, 1).unwrap();
    assert_eq!(
        (e[0].nearest[0].0, e[0].furthest[0].0, e[1].nearest[0].0),
        (1, 1, 0)
    );
    let rows = random(21, 10, 2);
    same(&exact(&rows, 20).unwrap(), &naive(&rows, 20));
    assert_eq!(
        exact(&rows, 21).unwrap_err(),
        KnnError::TooFew {
            k: 21,
            need: 22,
            n: 21
        }
    );
}

#[test]
fn huge_and_tiny_magnitudes_together() {
    // Night photos have orders of magnitude less Gram energy than day photos.
    let mut rows = random(150, 32, 5);
    for (i, r) in rows.iter_mut().enumerate() {
        let s = if i % 3 == 0 {
            1e6
        } else if i % 3 == 1 {
            1e-6
        } else {
            1.0
        };
        r.iter_mut().for_each(|v| *v *= s);
    }
    same(&exact(&rows, 20).unwrap(), &naive(&rows, 20));
}

#[test]
fn nan_and_ragged_rows_name_the_row() {
    let mut rows = random(10, 4, 1);
    rows[6][2] = f32::NAN;
    let e = exact(&rows, 3).unwrap_err();
    assert!(
        matches!(
            e,
            KnnError::NotFinite {
                row: 6,
                index: 2,
                ..
            }
        ),
        "{e}"
    );
    let mut rows = random(10, 4, 1);
    rows[4].pop();
    assert_eq!(
        exact(&rows, 3).unwrap_err(),
        KnnError::Dimension {
            row: 4,
            len: 3,
            dim: 4
        }
    );
}

#[test]
fn every_stored_distance_is_the_f64_sum_to_the_bit_whatever_the_gemm() {
    // The GEMM's dot products depend on the instruction set (AVX-512 and AVX2 kernels sum in
    // other orders), so a stored distance must never be one: each must equal distance2_f64 of
    // its pair bit for bit, on the f64 path (N < 64k, where lists are often proven certain by
    // their intervals alone), the f32 path, symmetric and blocked.
    for (n, dim, k, limit) in [
        (40, 300, 5, usize::MAX),
        (40, 300, 5, 0),
        (400, 64, 3, usize::MAX),
        (400, 64, 3, 0),
    ] {
        // Values over six decades, as colour statistics mix means and covariances: products
        // of f32 values this spread round in f64 sums, so a GEMM's sum is not the exact one
        // (values of one magnitude sum exactly in f64 and would hide a stored GEMM value).
        let mut r = ChaCha8Rng::seed_from_u64(11 + n as u64);
        let rows: Vec<Vec<f32>> = (0..n)
            .map(|_| {
                (0..dim)
                    .map(|_| r.random_range(-1.0f32..1.0) * 10f32.powi(r.random_range(-3..3)))
                    .collect()
            })
            .collect();
        let got = nrw_knn::exact_with_matrix_limit(&rows, k, limit).unwrap();
        for (i, a) in got.iter().enumerate() {
            for &(j, d) in a.nearest.iter().chain(&a.furthest) {
                let want = nrw_knn::distance2_f64(&rows[i], &rows[j]);
                assert_eq!(
                    d.to_bits(),
                    want.to_bits(),
                    "n {n}, limit {limit}: anchor {i}, row {j}: stored {d}, f64 sum {want}"
                );
            }
        }
        same(&got, &naive(&rows, k));
    }
}
