//! The approximate path: PCA recovers planted low-dimensional structure, and its neighbours
//! agree with the exact path where the structure is the signal.

use nrw_knn::approx::{approximate, recall, Pca};
use nrw_knn::exact;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// N points on an 8-dimensional subspace of R^dim plus small isotropic noise.
fn structured(n: usize, dim: usize, seed: u64) -> Vec<Vec<f32>> {
    let mut r = ChaCha8Rng::seed_from_u64(seed);
    let basis: Vec<Vec<f32>> = (0..8)
        .map(|_| (0..dim).map(|_| r.random_range(-1.0f32..1.0)).collect())
        .collect();
    (0..n)
        .map(|_| {
            let c: Vec<f32> = (0..8).map(|_| r.random_range(-3.0f32..3.0)).collect();
            (0..dim)
                .map(|d| {
                    (0..8).map(|k| c[k] * basis[k][d]).sum::<f32>() + r.random_range(-0.01f32..0.01)
                })
                .collect()
        })
        .collect()
}

#[test]
fn pca_captures_planted_structure() {
    let rows = structured(400, 200, 1);
    let pca = Pca::fit(&rows, 8, 7).unwrap();
    // Orthonormal directions.
    for a in 0..8 {
        for b in 0..8 {
            let dot: f64 = (0..200)
                .map(|d| pca.basis[a * 200 + d] as f64 * pca.basis[b * 200 + d] as f64)
                .sum();
            assert!(
                (dot - if a == b { 1.0 } else { 0.0 }).abs() < 1e-3,
                "{a},{b}: {dot}"
            );
        }
    }
    // Distances in the 8-D projection equal the full ones up to the noise.
    let z = pca.project(&rows);
    let d = |v: &[Vec<f32>], i: usize, j: usize| nrw_knn::distance2_f64(&v[i], &v[j]);
    for (i, j) in [(0, 1), (5, 99), (17, 300)] {
        let (full, red) = (d(&rows, i, j), d(&z, i, j));
        assert!((full - red).abs() < 0.01 * full + 0.1, "{full} vs {red}");
    }
}

#[test]
fn approximate_neighbours_agree_with_exact_on_structured_data() {
    let rows = structured(600, 300, 3);
    let e = exact(&rows, 20).unwrap();
    let a = approximate(&rows, 20, 16, 3, 11).unwrap();
    let (near, far) = recall(&e, &a);
    assert!(
        near > 0.95 && far > 0.95,
        "recall@20 nearest {near}, furthest {far}"
    );
    // Re-ranked distances are exact ones (and the exact path's to 1e-7), so wherever ids agree
    // the distances do too.
    for (x, y) in e.iter().zip(&a) {
        for p in &y.nearest {
            if let Some(q) = x.nearest.iter().find(|q| q.0 == p.0) {
                assert!((p.1 - q.1).abs() <= 1e-7 * q.1, "{} vs {}", p.1, q.1);
            }
        }
    }
}

#[test]
fn degenerate_inputs_do_not_break_the_fit() {
    let same = vec![vec![1.5f32; 40]; 30];
    let a = approximate(&same, 5, 8, 2, 1).unwrap();
    assert_eq!(
        a[3].nearest.iter().map(|p| p.0).collect::<Vec<_>>().len(),
        5
    );
    let two = structured(2, 20, 4);
    assert_eq!(approximate(&two, 1, 8, 2, 1).unwrap()[0].nearest[0].0, 1);
}
