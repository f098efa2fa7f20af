//! Descriptors read in passes through a scratch file give the in-memory results to the bit
//! (exact lists, approximate lists, PCA, distance rows), and a bad source is named.

use nrw_knn::approx::{approximate, approximate_spilled, Pca};
use nrw_knn::{distance_matrix, exact, exact_spilled, KnnError, Spilled, StreamError};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

fn random(n: usize, dim: usize, seed: u64, spread: f32) -> Vec<Vec<f32>> {
    let mut r = ChaCha8Rng::seed_from_u64(seed);
    let c: Vec<f32> = (0..dim).map(|_| r.random_range(-1.0f32..1.0)).collect();
    (0..n)
        .map(|_| {
            c.iter()
                .map(|c| c + spread * r.random_range(-1.0f32..1.0))
                .collect()
        })
        .collect()
}

/// The rows through a scratch file, given last row first (a source may give any order).
fn spilled(rows: &[Vec<f32>]) -> Spilled {
    Spilled::from_source(rows.len(), |sink| {
        for i in (0..rows.len()).rev() {
            sink(i, &rows[i]);
        }
        Ok::<(), std::io::Error>(())
    })
    .unwrap()
}

fn bits(v: &[nrw_knn::Neighbours]) -> Vec<Vec<(usize, u64)>> {
    v.iter()
        .flat_map(|nb| [&nb.nearest, &nb.furthest])
        .map(|l| l.iter().map(|p| (p.0, p.1.to_bits())).collect())
        .collect()
}

#[test]
fn a_scratch_file_gives_the_in_memory_lists_to_the_bit() {
    // f64 and f32 dot products, one and several chunks of 4,096 values, near-duplicates
    // (where the lists come from interval midpoints) and spread rows.
    for (n, dim, k, spread) in [
        (40, 9000, 3, 1.0),
        (40, 9000, 3, 1e-3),
        (300, 64, 20, 1.0),
        (70, 5000, 1, 1.0),
        (257, 300, 4, 1e-3),
    ] {
        let rows = random(n, dim, n as u64, spread);
        let s = spilled(&rows);
        assert_eq!(
            bits(&exact_spilled(&s, k).unwrap()),
            bits(&exact(&rows, k).unwrap()),
            "exact, n {n} dim {dim}"
        );
        if n > 50 {
            assert_eq!(
                bits(&approximate_spilled(&s, k, 8, 3, 0).unwrap()),
                bits(&approximate(&rows, k, 8, 3, 0).unwrap()),
                "approximate, n {n} dim {dim}"
            );
        }
        let (a, b) = (Pca::fit_spilled(&s, 2, 0), Pca::fit(&rows, 2, 0).unwrap());
        assert!(a
            .basis
            .iter()
            .zip(&b.basis)
            .all(|(x, y)| x.to_bits() == y.to_bits()));
        let flat = |p: Vec<Vec<f32>>| p.concat().iter().map(|v| v.to_bits()).collect::<Vec<_>>();
        assert_eq!(flat(a.project_spilled(&s)), flat(b.project(&rows)));
        let refs: Vec<&[f32]> = rows.iter().map(|r| r.as_slice()).collect();
        let whole = distance_matrix(&refs);
        let got = s.distance_rows(3..7);
        assert!(got
            .iter()
            .zip(&whole[3 * n..7 * n])
            .all(|(x, y)| x.to_bits() == y.to_bits()));
    }
}

#[test]
fn a_bad_source_is_named_by_row() {
    let rows = random(6, 10, 1, 1.0);
    let give = |bad: Option<(usize, Vec<f32>)>, skip: Option<usize>| {
        Spilled::from_source(6, |sink| {
            for (i, r) in rows.iter().enumerate() {
                match &bad {
                    _ if Some(i) == skip => {}
                    Some((j, v)) if *j == i => sink(i, v),
                    _ => sink(i, r),
                }
            }
            Ok::<(), std::io::Error>(())
        })
        .err()
        .map(|e| e.to_string())
    };
    assert_eq!(give(None, None), None);
    assert_eq!(
        give(Some((4, vec![0.0; 3])), None).unwrap(),
        KnnError::Dimension {
            row: 4,
            len: 3,
            dim: 10
        }
        .to_string()
    );
    let mut nan = rows[2].clone();
    nan[7] = f32::NAN;
    assert_eq!(
        give(Some((2, nan)), None).unwrap(),
        "row 2: descriptor value 7 is NaN (not finite)"
    );
    assert_eq!(
        give(None, Some(5)).unwrap(),
        "row 5: no descriptor was given for it"
    );
    let failed = Spilled::from_source(3, |_| Err(std::io::Error::other("part-00001: damaged")));
    assert!(
        matches!(failed, Err(StreamError::Source(e)) if e.to_string() == "part-00001: damaged")
    );
}
