//! The sweeps over a view: random initialisation, red-black propagation from the neighbours
//! and random refinement, and hypotheses carried from a coarser level.

use glam::DVec3;
use rayon::prelude::*;

use crate::rng::PixelRng;

use super::options::{Hypotheses, MAX_COST};
use super::problem::{
    facing, to_d, to_f, Known, Patch, Problem, Update, DIRECTIONS, NEIGHBOUR_STEPS,
};

impl Problem<'_> {
    /// One pixel's sweep: the neighbours' planes, then random refinements, compared on the
    /// pixel's selected views; the best, with its cost over every view and its new views.
    pub(super) fn update(
        &self,
        state: &Hypotheses,
        x: usize,
        y: usize,
        iteration: usize,
        view_salt: u64,
    ) -> Update {
        let i = y * state.width + x;
        let current = (
            state.depth[i],
            state.normal[i],
            state.cost[i],
            state.views[i],
        );
        let patch = self.patch(x, y);
        if patch.var.sqrt() < self.opts.min_texture {
            return (current.0, current.1, MAX_COST, current.3);
        }
        let all = if self.sources.len() >= 32 {
            u32::MAX
        } else {
            (1u32 << self.sources.len()) - 1
        };
        let mask = if current.3 == 0 { all } else { current.3 };
        let ray = self.reference.lens.pixel_ray(x, y);
        let (d_cur, n_cur) = (current.0 as f64, to_d(current.1));
        // The current plane's cost over its selected views is the mean of its best `best_k`
        // costs, which is the cost it was stored with (the selected views are its best
        // `best_k + 1`): it is not computed again (precision given up: the stored f32).
        let (start, known) = if !self.in_range(d_cur) {
            (f64::INFINITY, Known::NONE)
        } else if current.3 != 0 {
            (current.2 as f64, Known::NONE)
        } else {
            self.subset_cost(&patch, x, y, d_cur, n_cur, mask)
        };
        let mut search = Search {
            best: (d_cur, n_cur, start),
            known,
            changed: false,
        };
        for (d, n) in self
            .neighbour_planes(state, x, y, ray)
            .into_iter()
            .flatten()
        {
            self.consider(&mut search, &patch, (x, y, mask), d, n);
        }
        let mut rng = PixelRng::new(self.opts.seed, view_salt, iteration as u64 + 1, i as u64);
        for (d, n) in self.refinements(search.best, ray, iteration, &mut rng) {
            self.consider(&mut search, &patch, (x, y, mask), d, n);
        }
        if !search.changed && current.3 != 0 {
            return current;
        }
        let (d, n, _) = search.best;
        let (cost, views) = self.cost(&patch, x, y, d, n, &search.known);
        (d as f32, to_f(n), cost as f32, views)
    }

    /// Compare plane (d, n) with the pixel's best on its selected views (`at`: x, y, mask),
    /// and take it if it costs less.
    fn consider(
        &self,
        search: &mut Search,
        patch: &Patch,
        at: (usize, usize, u32),
        d: f64,
        n: DVec3,
    ) {
        if !self.in_range(d) {
            return;
        }
        let (x, y, mask) = at;
        let (c, known) = self.subset_cost(patch, x, y, d, n, mask);
        if c < search.best.2 {
            search.best = (d, n, c);
            search.known = known;
            search.changed = true;
        }
    }

    /// The planes of the pixel's neighbours, one for each of the four directions, taken
    /// through the pixel's ray (none where the plane does not face it). ACMH's adaptive
    /// choice, reduced: of a direction's neighbours at odd distances, the one whose plane
    /// has the lowest cost (the nearest on a tie).
    fn neighbour_planes(
        &self,
        state: &Hypotheses,
        x: usize,
        y: usize,
        ray: DVec3,
    ) -> [Option<(f64, DVec3)>; 4] {
        DIRECTIONS.map(|(dx, dy)| {
            let mut pick: Option<(usize, usize, f32)> = None;
            for step in NEIGHBOUR_STEPS {
                let (nx, ny) = (x as isize + dx * step, y as isize + dy * step);
                if nx < 0 || ny < 0 || nx >= state.width as isize || ny >= state.height as isize {
                    break;
                }
                let (nx, ny) = (nx as usize, ny as usize);
                let c = state.cost[ny * state.width + nx];
                if pick.is_none_or(|p| c < p.2) {
                    pick = Some((nx, ny, c));
                }
            }
            let (nx, ny, _) = pick?;
            let j = ny * state.width + nx;
            let n = to_d(state.normal[j]);
            let plane_point = self.reference.lens.pixel_ray(nx, ny) * state.depth[j] as f64;
            let denom = n.dot(ray);
            (denom < -1e-12).then(|| (n.dot(plane_point) / denom, n))
        })
    }

    /// Five random planes around the best so far (d0, n0): a fresh one, its depth or normal
    /// perturbed or both (by less each iteration), and its depth with a fresh normal.
    fn refinements(
        &self,
        best: (f64, DVec3, f64),
        ray: DVec3,
        iteration: usize,
        rng: &mut PixelRng,
    ) -> [(f64, DVec3); 5] {
        let shrink = 0.5f64.powi(iteration as i32);
        let (d0, n0) = (best.0, best.1);
        let perturb_d = |rng: &mut PixelRng| d0 * (1.0 + 0.05 * shrink * rng.signed());
        let perturb_n = |rng: &mut PixelRng| {
            let v = n0 + DVec3::new(rng.signed(), rng.signed(), rng.signed()) * (0.3 * shrink);
            facing(v.normalize_or(n0), ray)
        };
        [
            (self.random_depth(rng), Self::random_normal(ray, rng)),
            (perturb_d(rng), n0),
            (d0, perturb_n(rng)),
            (perturb_d(rng), perturb_n(rng)),
            (d0, Self::random_normal(ray, rng)),
        ]
    }

    /// Random hypotheses for every pixel, each with its cost.
    pub(super) fn initialise(&self, view_salt: u64) -> Hypotheses {
        let (w, h) = (self.reference.image.width, self.reference.image.height);
        let rows: Vec<Vec<Update>> = (0..h)
            .into_par_iter()
            .map(|y| {
                (0..w)
                    .map(|x| {
                        let mut rng =
                            PixelRng::new(self.opts.seed, view_salt, 0, (y * w + x) as u64);
                        let ray = self.reference.lens.pixel_ray(x, y);
                        let d = self.random_depth(&mut rng);
                        let n = Self::random_normal(ray, &mut rng);
                        let (c, v) = self.scored(x, y, d, n);
                        (d as f32, to_f(n), c, v)
                    })
                    .collect()
            })
            .collect();
        from_rows(w, h, rows)
    }

    /// The cost of a hypothesis at a pixel and its views, `MAX_COST` for a flat window.
    pub(super) fn scored(&self, x: usize, y: usize, d: f64, n: DVec3) -> (f32, u32) {
        let patch = self.patch(x, y);
        if patch.var.sqrt() < self.opts.min_texture {
            return (MAX_COST, 0);
        }
        let (c, v) = self.cost(&patch, x, y, d, n, &Known::NONE);
        (c as f32, v)
    }

    /// Every hypothesis scored again (after a change of scale or of pass).
    pub(super) fn rescored(&self, mut state: Hypotheses) -> Hypotheses {
        let w = state.width;
        let scored: Vec<(f32, u32)> = (0..state.depth.len())
            .into_par_iter()
            .map(|i| {
                let (x, y) = (i % w, i / w);
                let d = state.depth[i] as f64;
                if d.is_nan() || d <= 0.0 {
                    return (MAX_COST, 0);
                }
                self.scored(x, y, d, to_d(state.normal[i]))
            })
            .collect();
        state.cost = scored.iter().map(|s| s.0).collect();
        state.views = scored.iter().map(|s| s.1).collect();
        state
    }

    /// `iterations` red-black sweeps, the perturbations shrinking from `first`'s size on.
    pub(super) fn sweep(
        &self,
        mut state: Hypotheses,
        view_salt: u64,
        first: usize,
        iterations: usize,
    ) -> Hypotheses {
        let (w, h) = (state.width, state.height);
        for iteration in first..first + iterations {
            for colour in 0..2 {
                let updates: Vec<Vec<(usize, Update)>> = (0..h)
                    .into_par_iter()
                    .map(|y| {
                        ((y + colour) % 2..w)
                            .step_by(2)
                            .map(|x| (y * w + x, self.update(&state, x, y, iteration, view_salt)))
                            .collect()
                    })
                    .collect();
                for (i, (d, n, c, v)) in updates.into_iter().flatten() {
                    state.depth[i] = d;
                    state.normal[i] = n;
                    state.cost[i] = c;
                    state.views[i] = v;
                }
            }
        }
        state
    }
}

pub(super) fn from_rows(w: usize, h: usize, rows: Vec<Vec<Update>>) -> Hypotheses {
    let mut out = Hypotheses {
        width: w,
        height: h,
        depth: Vec::with_capacity(w * h),
        normal: Vec::with_capacity(w * h),
        cost: Vec::with_capacity(w * h),
        views: Vec::with_capacity(w * h),
    };
    for (d, n, c, v) in rows.into_iter().flatten() {
        out.depth.push(d);
        out.normal.push(n);
        out.cost.push(c);
        out.views.push(v);
    }
    out
}

/// Hypotheses of a coarser level carried to a `w` × `h` level (nearest pixel: depth along the
/// camera's z and normals do not change with scale).
pub(super) fn upsampled(coarse: &Hypotheses, w: usize, h: usize) -> Hypotheses {
    let mut out = Hypotheses {
        width: w,
        height: h,
        depth: Vec::with_capacity(w * h),
        normal: Vec::with_capacity(w * h),
        cost: vec![MAX_COST; w * h],
        views: vec![0; w * h],
    };
    for y in 0..h {
        let cy = (y * coarse.height / h).min(coarse.height - 1);
        for x in 0..w {
            let cx = (x * coarse.width / w).min(coarse.width - 1);
            let j = cy * coarse.width + cx;
            out.depth.push(coarse.depth[j]);
            out.normal.push(coarse.normal[j]);
        }
    }
    out
}

/// One pixel's search: its best plane (depth, normal, cost on its selected views), the
/// source costs that plane's cost was computed from, and whether it changed.
struct Search {
    best: (f64, DVec3, f64),
    known: Known,
    changed: bool,
}
