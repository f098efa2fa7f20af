//! The pairs of scene_info's views: for each view, the later views it shares SfM points
//! with, tallied in arrays a thread keeps between views (reset only where a view touched
//! them), so finding a view's pairs costs its points' tracks, never a fresh array of N.

use glam::DVec2;

use super::SceneInfo;
use crate::pickle::DictValue;

/// A central match candidate of a pair: (squared distance to view i's principal point, point
/// id, xy in view i, xy in view j).
type Candidate = (f64, u64, [f64; 2], [f64; 2]);

/// Two views (i < j) that share SfM points.
pub(super) struct PairInfo {
    pub(super) i: usize,
    pub(super) j: usize,
    /// The smaller of the two views' overlaps.
    pub(super) score: f64,
    /// One shared point in D2-Net's `central_match` layout: [y_i, x_i, y_j, x_j].
    pub(super) central: [f64; 4],
    /// The bounding boxes of the shared points' positions in view i and in view j.
    pub(super) boxes: [Bbox; 2],
}

/// What view i shares with one later view so far: points, the central match, the boxes.
#[derive(Clone, Copy)]
struct Shared {
    common: u64,
    central: Candidate,
    boxes: [Bbox; 2],
}

impl Shared {
    const NONE: Shared = Shared {
        common: 0,
        central: (0.0, 0, [0.0; 2], [0.0; 2]),
        boxes: [Bbox::EMPTY; 2],
    };
}

/// One tally per view, kept between views (a thread's own): a view's pairs cost the views
/// it shares points with, not a fresh array of N.
#[derive(Default)]
struct PairScratch {
    shared: Vec<Shared>,
    touched: Vec<usize>,
}

impl PairScratch {
    /// Room for `n` views.
    fn fit(&mut self, n: usize) {
        if self.shared.len() < n {
            self.shared.resize(n, Shared::NONE);
        }
    }

    /// Every tally back to none.
    fn clear(&mut self) {
        for &j in &self.touched {
            self.shared[j] = Shared::NONE;
        }
        self.touched.clear();
    }
}

thread_local! {
    static PAIR_SCRATCH: std::cell::RefCell<PairScratch> = std::cell::RefCell::default();
}

/// An axis-aligned box of image positions, grown a point at a time.
#[derive(Clone, Copy)]
pub(super) struct Bbox {
    pub(super) min: DVec2,
    pub(super) max: DVec2,
}

impl Bbox {
    /// The box of no point, which any point replaces.
    const EMPTY: Bbox = Bbox {
        min: DVec2::splat(f64::INFINITY),
        max: DVec2::splat(f64::NEG_INFINITY),
    };

    /// Grow the box to hold `p`.
    fn add(&mut self, p: [f64; 2]) {
        let p = DVec2::from_array(p);
        self.min = self.min.min(p);
        self.max = self.max.max(p);
    }

    /// The box's area in square pixels (0 for one point or a line).
    pub(super) fn area(&self) -> f64 {
        let d = self.max - self.min;
        d.x * d.y
    }
}

impl SceneInfo {
    /// View i's pairs with the views after it that share points, in view order: the smaller
    /// of the two overlaps, and the central match (the shared point nearest view i's
    /// principal point; the smaller point id on a tie). Costs the track lengths of i's points.
    pub(super) fn pairs_of(&self, i: usize) -> Vec<PairInfo> {
        PAIR_SCRATCH.with_borrow_mut(|scratch| self.pairs_with(i, scratch))
    }

    /// [`Self::pairs_of`] with the per-view tallies of `scratch`, which are left empty.
    fn pairs_with(&self, i: usize, scratch: &mut PairScratch) -> Vec<PairInfo> {
        let (cx, cy) = (self.intrinsics[i][0][2], self.intrinsics[i][1][2]);
        scratch.fit(self.len());
        for (id, v) in &self.points3d_id_to_2d[i] {
            let DictValue::Pair(p) = *v else {
                unreachable!("positions are pairs")
            };
            let d2 = (p[0] - cx) * (p[0] - cx) + (p[1] - cy) * (p[1] - cy);
            for &(j, _, q) in &self.seen[id] {
                if j <= i {
                    continue;
                }
                let s = &mut scratch.shared[j];
                if s.common == 0 {
                    scratch.touched.push(j);
                    s.central = (d2, *id, p, q);
                }
                s.common += 1;
                s.boxes[0].add(p);
                s.boxes[1].add(q);
                let b = s.central;
                if d2 < b.0 || (d2 == b.0 && *id < b.1) {
                    s.central = (d2, *id, p, q);
                }
            }
        }
        scratch.touched.sort_unstable();
        let pairs = scratch
            .touched
            .iter()
            .map(|&j| {
                let s = &scratch.shared[j];
                let (_, _, p, q) = s.central;
                let share = |k: usize| s.common as f64 / self.n_points3d[k] as f64;
                PairInfo {
                    i,
                    j,
                    score: share(i).min(share(j)),
                    central: [p[1], p[0], q[1], q[0]],
                    boxes: s.boxes,
                }
            })
            .collect();
        scratch.clear();
        pairs
    }
}
