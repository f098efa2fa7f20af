//! Point-cloud clean-up before rendering, on kiddo's k-d tree: statistical outlier removal
//! (Open3D's `remove_statistical_outlier`) and normals for clouds that have none (PCA of each
//! point's neighbours, oriented toward the cameras that see it). Both work on positions
//! re-centred in f64: a georeferenced (UTM-offset) cloud gives the result of the centred one.

use std::num::NonZero;

use glam::DVec3;
use kiddo::immutable::float::kdtree::ImmutableKdTree;
use kiddo::SquaredEuclidean;
use rayon::prelude::*;

/// What statistical outlier removal found.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct OutlierReport {
    /// Neighbours per point (the point itself included, as Open3D counts).
    pub k: usize,
    /// Standard deviations above the cloud's mean that make a point an outlier.
    pub sigma: f64,
    /// Mean over points of the mean distance to their neighbours, its standard deviation
    /// (Bessel-corrected) and the threshold mean + σ·std, in the cloud's units.
    pub mean: f64,
    pub std: f64,
    pub threshold: f64,
    pub points: usize,
    pub removed: usize,
}

/// The k-d tree: f64 positions, u64 indices, leaves of 8 points (small leaves suit the
/// bounded searches below, which visit few of them).
type Tree = ImmutableKdTree<f64, u64, 3, 8>;

/// Queries per sequential run: each run starts unbounded and then bounds every search by the
/// previous one. A fixed size keeps the bounds, so the results, independent of the thread
/// count.
const RUN: usize = 4096;

/// `f(i, neighbours)` for every point i, where `neighbours` are its k nearest (itself
/// included, nearest first, ties by index) as (distance, index): one parallel pass over an
/// immutable k-d tree of the re-centred positions, nothing stored per neighbourhood.
///
/// Queries go in Morton order, so consecutive ones are neighbours in space and walk the same
/// branches of the tree, which stay in cache; and each search is bounded by the farthest of
/// the previous query's k neighbours from this query (any k points bound the k-th nearest
/// distance), so it prunes from its first leaf instead of its k-th point. The bound only
/// prunes: the result is exactly the unbounded search's.
fn map_neighbourhoods<R: Send>(
    local: &[[f64; 3]],
    k: usize,
    f: impl Fn(usize, &[(f64, usize)]) -> R + Sync,
) -> Vec<R> {
    if local.is_empty() || k == 0 {
        return (0..local.len()).map(|i| f(i, &[])).collect();
    }
    let tree: Tree = ImmutableKdTree::new_from_slice(local);
    let k = NonZero::new(k.min(local.len())).expect("k ≥ 1");
    let order = morton_order(local);
    let mut out: Vec<(usize, R)> = order
        .par_chunks(RUN)
        .flat_map_iter(|run| {
            let mut found: Vec<(f64, usize)> = Vec::with_capacity(k.get());
            run.iter()
                .map(|&i| {
                    let q = &local[i];
                    let bound = search_bound(q, found.iter().map(|n| &local[n.1]), k.get());
                    found.clear();
                    found.extend(
                        tree.nearest_n_within::<SquaredEuclidean>(q, bound, k, false)
                            .into_iter()
                            .map(|n| (n.distance, n.item as usize)),
                    );
                    found.sort_unstable_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
                    found.iter_mut().for_each(|n| n.0 = n.0.sqrt());
                    (i, f(i, &found))
                })
                .collect::<Vec<_>>()
        })
        .collect();
    out.sort_unstable_by_key(|(i, _)| *i);
    out.into_iter().map(|(_, r)| r).collect()
}

/// The squared radius that holds `q`'s k nearest neighbours when `previous` are k points:
/// the farthest of them from `q`, widened by one part in 10⁹ so that rounding cannot exclude
/// the k-th; unbounded when there are fewer than k (a run's first query).
fn search_bound<'a>(q: &[f64; 3], previous: impl Iterator<Item = &'a [f64; 3]>, k: usize) -> f64 {
    let mut count = 0;
    let mut far = 0f64;
    for p in previous {
        let d2 = (q[0] - p[0]).powi(2) + (q[1] - p[1]).powi(2) + (q[2] - p[2]).powi(2);
        far = far.max(d2);
        count += 1;
    }
    if count < k || !far.is_finite() {
        f64::INFINITY
    } else {
        far * (1.0 + 1e-9)
    }
}

/// Point indices sorted by the Morton code of their position on a 2²¹ grid over the bounds.
fn morton_order(local: &[[f64; 3]]) -> Vec<usize> {
    let (mut lo, mut hi) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
    for p in local {
        for a in 0..3 {
            lo[a] = lo[a].min(p[a]);
            hi[a] = hi[a].max(p[a]);
        }
    }
    let cell = |p: &[f64; 3], a: usize| -> u64 {
        let span = (hi[a] - lo[a]).max(f64::MIN_POSITIVE);
        (((p[a] - lo[a]) / span) * ((1u64 << 21) - 1) as f64) as u64
    };
    let spread = |mut v: u64| {
        v &= 0x1f_ffff;
        v = (v | v << 32) & 0x1f00000000ffff;
        v = (v | v << 16) & 0x1f0000ff0000ff;
        v = (v | v << 8) & 0x100f00f00f00f00f;
        v = (v | v << 4) & 0x10c30c30c30c30c3;
        (v | v << 2) & 0x1249249249249249
    };
    let mut keyed: Vec<(u64, usize)> = local
        .iter()
        .enumerate()
        .map(|(i, p)| {
            (
                spread(cell(p, 0)) | spread(cell(p, 1)) << 1 | spread(cell(p, 2)) << 2,
                i,
            )
        })
        .collect();
    keyed.par_sort_unstable();
    keyed.into_iter().map(|(_, i)| i).collect()
}

/// Positions relative to `origin`, in f64 (no precision is given up here).
fn recentred(world: &[DVec3], origin: DVec3) -> Vec<[f64; 3]> {
    world.iter().map(|p| (*p - origin).to_array()).collect()
}

/// Which points to keep: a point is an outlier when the mean distance to its k nearest
/// neighbours (itself included) exceeds the cloud's mean of that by `sigma` standard
/// deviations — Open3D's definition, with one change: Open3D also drops every point whose
/// neighbours all coincide with it (mean distance 0), and this keeps them (duplicates are not
/// outliers). Fewer points than k: all of them are the neighbourhood.
pub fn statistical_outliers(
    world: &[DVec3],
    origin: DVec3,
    k: usize,
    sigma: f64,
) -> (Vec<bool>, OutlierReport) {
    let local = recentred(world, origin);
    let means: Vec<f64> = map_neighbourhoods(&local, k, |_, ns| {
        ns.iter().map(|n| n.0).sum::<f64>() / ns.len().max(1) as f64
    });
    let n = means.len();
    let mean = means.iter().sum::<f64>() / n.max(1) as f64;
    let var = means.iter().map(|m| (m - mean).powi(2)).sum::<f64>() / (n.max(2) - 1) as f64;
    let std = var.sqrt();
    let threshold = mean + sigma * std;
    let keep: Vec<bool> = means.iter().map(|m| *m <= threshold).collect();
    let removed = keep.iter().filter(|k| !**k).count();
    (
        keep,
        OutlierReport {
            k,
            sigma,
            mean,
            std,
            threshold,
            points: n,
            removed,
        },
    )
}

/// Unit normals by PCA of each point's k nearest neighbours (itself included): the
/// eigenvector of the smallest eigenvalue of their covariance, turned to face `toward(i)`
/// (a point the surface is seen from: the cameras observing point i, or the scene's cameras
/// on average). Where the neighbourhood has fewer than 3 distinct points, or spans no plane,
/// the normal points at `toward(i)`. f64 throughout; rounded to f32 once at the end.
pub fn estimate_normals(
    world: &[DVec3],
    origin: DVec3,
    k: usize,
    toward: &(dyn Fn(usize) -> DVec3 + Sync),
) -> Vec<[f32; 3]> {
    let local = recentred(world, origin);
    map_neighbourhoods(&local, k.max(3), |i, ns| {
        let view = (toward(i) - world[i]).normalize_or(DVec3::Z);
        let normal = pca_normal(ns.iter().map(|n| DVec3::from(local[n.1]))).unwrap_or(view);
        let oriented = if normal.dot(view) < 0.0 {
            -normal
        } else {
            normal
        };
        oriented.as_vec3().to_array()
    })
}

/// The direction of least spread of a point set, or None when it spans no plane.
fn pca_normal(pts: impl Iterator<Item = DVec3> + Clone) -> Option<DVec3> {
    let n = pts.clone().count();
    if n < 3 {
        return None;
    }
    let c = pts.clone().sum::<DVec3>() / n as f64;
    let mut m = [[0.0f64; 3]; 3];
    for p in pts {
        let d = (p - c).to_array();
        for (r, row) in m.iter_mut().enumerate() {
            for (col, v) in row.iter_mut().enumerate() {
                *v += d[r] * d[col];
            }
        }
    }
    let (values, vectors) = jacobi_eigen(m);
    let scale = values.iter().fold(0f64, |a, v| a.max(v.abs()));
    // A line or a point: the two smallest eigenvalues are both ~0, no plane.
    let mut order = [0usize, 1, 2];
    order.sort_by(|a, b| values[*a].total_cmp(&values[*b]));
    if scale <= 0.0 || values[order[1]] <= 1e-12 * scale {
        return None;
    }
    let v = vectors[order[0]];
    Some(DVec3::from(v).normalize())
}

/// Eigenvalues and unit eigenvectors of a symmetric 3 × 3 matrix by cyclic Jacobi rotations
/// (converges to f64 precision in a few sweeps).
fn jacobi_eigen(mut a: [[f64; 3]; 3]) -> ([f64; 3], [[f64; 3]; 3]) {
    let mut v = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    for _ in 0..50 {
        let off = a[0][1].powi(2) + a[0][2].powi(2) + a[1][2].powi(2);
        if off <= 1e-30 * (a[0][0].powi(2) + a[1][1].powi(2) + a[2][2].powi(2)) {
            break;
        }
        for (p, q) in [(0, 1), (0, 2), (1, 2)] {
            if a[p][q] == 0.0 {
                continue;
            }
            let theta = (a[q][q] - a[p][p]) / (2.0 * a[p][q]);
            // signum(0) = 1: a zero θ rotates by 45°.
            let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
            let c = 1.0 / (t * t + 1.0).sqrt();
            let s = t * c;
            // A ← Jᵀ A J on rows/columns p, q.
            for row in a.iter_mut() {
                let (arp, arq) = (row[p], row[q]);
                row[p] = c * arp - s * arq;
                row[q] = s * arp + c * arq;
            }
            let (rp, rq) = (a[p], a[q]);
            for col in 0..3 {
                a[p][col] = c * rp[col] - s * rq[col];
                a[q][col] = s * rp[col] + c * rq[col];
            }
            for row in v.iter_mut() {
                let (vp, vq) = (row[p], row[q]);
                row[p] = c * vp - s * vq;
                row[q] = s * vp + c * vq;
            }
        }
    }
    // Column j of v is the eigenvector of a[j][j].
    let vectors = std::array::from_fn(|j| [v[0][j], v[1][j], v[2][j]]);
    ([a[0][0], a[1][1], a[2][2]], vectors)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid(n: usize, offset: DVec3) -> Vec<DVec3> {
        // A planar grid in z = 0 with a gentle ripple, spacing 0.1.
        (0..n * n)
            .map(|i| {
                let (x, y) = ((i % n) as f64 * 0.1, (i / n) as f64 * 0.1);
                offset + DVec3::new(x, y, 0.0)
            })
            .collect()
    }

    /// `n` points in 7 thin clusters, from a fixed xorshift sequence.
    fn clusters(n: usize) -> Vec<DVec3> {
        let mut state = 0x2545_f491_4f6c_dd1d_u64;
        let mut next = || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        (0..n)
            .map(|i| {
                let c = (i % 7) as f64 * 3.0;
                DVec3::new(c + next(), c * 0.5 + next() * 0.2, next() * 0.01)
            })
            .collect()
    }

    #[test]
    fn a_utm_offset_cloud_gives_the_centred_clouds_results() {
        let centred = clusters(3000);
        let utm = DVec3::new(4.5e5, 5.4e6, 120.0);
        let far: Vec<DVec3> = centred.iter().map(|p| *p + utm).collect();
        let mid = DVec3::new(9.0, 4.5, 0.0);
        let (keep_a, a) = statistical_outliers(&centred, mid, 16, 1.0);
        let (keep_b, b) = statistical_outliers(&far, mid + utm, 16, 1.0);
        assert!(a.removed > 0, "{a:?}");
        assert_eq!(keep_a, keep_b);
        assert!(
            (a.threshold - b.threshold).abs() < 1e-9 * a.threshold,
            "{a:?} {b:?}"
        );
        let view = |pts: &[DVec3]| estimate_normals(pts, pts[0], 16, &|i| pts[i] + DVec3::Z);
        for (n, m) in view(&centred).iter().zip(&view(&far)) {
            let (n, m) = (glam::Vec3::from(*n), glam::Vec3::from(*m));
            assert!(n.dot(m) > 1.0 - 1e-6, "{n} {m}");
        }
    }

    #[test]
    fn bounded_searches_find_exactly_the_k_nearest_distances() {
        // Clustered points with exact duplicates, more than one run
        // of queries long: every neighbourhood's distances equal a brute-force search's.
        let mut local: Vec<[f64; 3]> = clusters(RUN + 1500).iter().map(|p| p.to_array()).collect();
        local.extend_from_within(..300);
        let k = 9;
        let got = map_neighbourhoods(&local, k, |_, ns| {
            ns.iter().map(|n| n.0).collect::<Vec<_>>()
        });
        for (i, q) in local.iter().enumerate().step_by(7) {
            let mut all: Vec<f64> = local
                .iter()
                .map(|p| {
                    ((q[0] - p[0]).powi(2) + (q[1] - p[1]).powi(2) + (q[2] - p[2]).powi(2)).sqrt()
                })
                .collect();
            all.sort_by(f64::total_cmp);
            assert_eq!(got[i], all[..k], "point {i}");
        }
        // The same neighbours, ties included, whatever the thread count.
        let with = |threads: usize| {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            pool.install(|| map_neighbourhoods(&local, k, |_, ns| ns.to_vec()))
        };
        assert_eq!(with(1), with(3));
    }

    #[test]
    fn eigen_decomposition_of_a_known_matrix() {
        let (vals, vecs) = jacobi_eigen([[2.0, 1.0, 0.0], [1.0, 2.0, 0.0], [0.0, 0.0, 5.0]]);
        let mut sorted = vals;
        sorted.sort_by(f64::total_cmp);
        assert!((sorted[0] - 1.0).abs() < 1e-12 && (sorted[1] - 3.0).abs() < 1e-12);
        for j in 0..3 {
            let v = DVec3::from(vecs[j]);
            let m = glam::DMat3::from_cols_array(&[2.0, 1.0, 0.0, 1.0, 2.0, 0.0, 0.0, 0.0, 5.0]);
            assert!((m * v - v * vals[j]).length() < 1e-12, "eigenpair {j}");
        }
    }

    #[test]
    fn a_far_point_is_an_outlier_and_a_plane_has_no_outliers_far_from_the_origin() {
        for offset in [DVec3::ZERO, DVec3::new(4.5e5, 5.4e6, 120.0)] {
            let mut pts = grid(30, offset);
            pts.push(offset + DVec3::new(1.5, 1.5, 5.0));
            let origin = offset + DVec3::new(1.0, 1.0, 0.0);
            let (keep, r) = statistical_outliers(&pts, origin, 8, 2.0);
            assert!(!keep[900], "the floating point goes");
            assert_eq!(r.removed, 1, "{r:?}");
            let normals = estimate_normals(&pts[..900], origin, 8, &|i| pts[i] + DVec3::Z);
            assert!(
                normals.iter().all(|n| (n[2] - 1.0).abs() < 1e-6),
                "plane normals face the viewer"
            );
        }
    }

    #[test]
    fn duplicates_tiny_and_empty_clouds_stay_finite() {
        // Every point at the same place: nothing is an outlier (Open3D would drop them all),
        // and the normals fall back to the viewing direction.
        let same = vec![DVec3::new(1.0, 2.0, 3.0); 20];
        let (keep, r) = statistical_outliers(&same, DVec3::ZERO, 8, 1.0);
        assert!(keep.iter().all(|k| *k) && r.std == 0.0, "{r:?}");
        let n = estimate_normals(&same, DVec3::ZERO, 8, &|_| DVec3::new(1.0, 2.0, 10.0));
        assert!(n.iter().all(|v| *v == [0.0, 0.0, 1.0]));
        // Fewer points than k: the whole cloud is each neighbourhood.
        let two = vec![DVec3::ZERO, DVec3::X];
        let (keep, r) = statistical_outliers(&two, DVec3::ZERO, 16, 2.0);
        assert_eq!((keep, r.removed), (vec![true, true], 0));
        // Empty.
        let (keep, r) = statistical_outliers(&[], DVec3::ZERO, 16, 2.0);
        assert!(keep.is_empty() && r.removed == 0 && r.mean == 0.0);
        assert!(estimate_normals(&[], DVec3::ZERO, 16, &|_| DVec3::Z).is_empty());
    }
}
