//! PatchMatch multi-view stereo on the CPU: per pixel a plane hypothesis (depth and normal in
//! the reference camera), scored by bilateral-weighted NCC over a strided window warped into
//! each source view by the plane's homography; hypotheses spread by red-black checkerboard
//! propagation and improve by random refinement; the cost of a pixel is the mean of its best
//! `best_k` source views (Gipuma's pixelwise view selection); coarse-to-fine over `scales`;
//! a geometric pass adds COLMAP's forward-backward reprojection error against the sources'
//! depth maps; COLMAP's filter keeps a depth only where enough views agree.
//!
//! Geometry (poses, homographies, warps, back-projection) is f64; the state is stored as the
//! f32 of COLMAP's maps (precision given up there: 6·10⁻⁸ of depth), and grey values are f32.
//! Same-coloured pixels of the checkerboard never read each other and each pixel's random
//! draws follow from (seed, view, iteration, pixel), so the maps do not depend on threads.

use glam::{DMat3, DVec2, DVec3};
use rayon::prelude::*;

use crate::ncc::{self, Samples, Warp, LANES};
use crate::rng::PixelRng;
use crate::view::StereoView;

/// Most source views one reference view is matched against.
pub const MAX_SOURCES: usize = 32;

/// The cost of a view that cannot be scored (warp leaves the image, flat source patch):
/// 1 − NCC is at most 2.
pub const MAX_COST: f32 = 2.0;

/// The kernel's settings; the defaults are COLMAP 3.8's `PatchMatchOptions` where COLMAP has
/// the setting, and Gipuma's otherwise.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PatchMatchOptions {
    /// Half the window's side in pixels (COLMAP: 5).
    pub window_radius: usize,
    /// Pixels between window samples (COLMAP: 1; Gipuma and ACMH sample every second).
    pub window_step: usize,
    /// Spatial σ of the bilateral weights, in pixels (COLMAP: the window radius).
    pub sigma_spatial: f64,
    /// Colour σ of the bilateral weights, on [0, 1] grey values (COLMAP: 0.2).
    pub sigma_color: f64,
    /// Red-black sweeps at the coarsest scale, from random hypotheses (COLMAP: 5).
    pub iterations: usize,
    /// Sweeps at each finer scale, which starts from the coarser one's hypotheses.
    pub refine_iterations: usize,
    /// Sweeps of the geometric pass, which starts from the photometric hypotheses.
    pub geom_iterations: usize,
    /// Source views whose costs are averaged at a pixel (Gipuma: 3).
    pub best_k: usize,
    /// Coarse-to-fine levels (1: the full image only; each level halves the image).
    pub scales: usize,
    /// Weight of the forward-backward reprojection error in the geometric pass (COLMAP: 0.3).
    pub geom_regularizer: f64,
    /// The reprojection error (px) at which the geometric cost saturates (COLMAP: 3).
    pub geom_max_cost: f64,
    /// Least weighted standard deviation of a reference window's grey values: flatter
    /// windows (sky, blank walls) get no depth rather than a guessed one.
    pub min_texture: f64,
    /// COLMAP's filter: least NCC for a source view to count as agreeing (0.1).
    pub filter_min_ncc: f64,
    /// COLMAP's filter: least triangulation angle, degrees (3).
    pub filter_min_angle_deg: f64,
    /// COLMAP's filter: agreeing source views needed to keep a depth (2).
    pub filter_min_consistent: usize,
    /// COLMAP's filter: largest forward-backward reprojection error, px (1).
    pub filter_geom_max_error: f64,
    /// Seed of the random initialisation and refinement.
    pub seed: u64,
}

impl Default for PatchMatchOptions {
    fn default() -> Self {
        PatchMatchOptions {
            window_radius: 5,
            window_step: 2,
            sigma_spatial: 5.0,
            sigma_color: 0.2,
            iterations: 5,
            refine_iterations: 3,
            geom_iterations: 2,
            best_k: 3,
            scales: 2,
            geom_regularizer: 0.3,
            geom_max_cost: 3.0,
            min_texture: 0.01,
            filter_min_ncc: 0.1,
            filter_min_angle_deg: 3.0,
            filter_min_consistent: 2,
            filter_geom_max_error: 1.0,
            seed: 0x5eed,
        }
    }
}

/// A source view of a reference view, with (in the geometric pass) its photometric depths.
#[derive(Debug, Clone, Copy)]
pub struct Source<'a> {
    pub view: &'a StereoView,
    /// The source's depth map at its view's size (row-major), for the geometric pass.
    pub depth: Option<&'a [f32]>,
}

/// The per-pixel plane hypotheses of a view: depth (camera z) and unit normal facing the
/// camera, with the cost each scored.
#[derive(Debug, Clone, PartialEq)]
pub struct Hypotheses {
    pub width: usize,
    pub height: usize,
    pub depth: Vec<f32>,
    pub normal: Vec<[f32; 3]>,
    pub cost: Vec<f32>,
    /// The source views each pixel's hypothesis is scored best by (bit j: source j): the
    /// views candidates are compared on (pixelwise view selection); 0 = not yet chosen.
    pub views: Vec<u32>,
}

/// What a pass leaves of a view: depth (0 = none), normal (0 where no depth), and the
/// confidence of each kept depth: the mean NCC of the agreeing source views and their count.
#[derive(Debug, Clone, PartialEq)]
pub struct StereoMaps {
    pub width: usize,
    pub height: usize,
    pub depth: Vec<f32>,
    pub normal: Vec<[f32; 3]>,
    /// (mean NCC of the agreeing views, number of agreeing views); (0, 0) where no depth.
    pub confidence: Vec<[f32; 2]>,
}

/// A pixel's new hypothesis: depth, normal, cost, selected views.
type Update = (f32, [f32; 3], f32, u32);

/// Source costs already computed for one hypothesis at one pixel (bit j of `mask`: source
/// j's cost is `costs[j]`).
struct Known {
    mask: u32,
    costs: [f64; MAX_SOURCES],
}

impl Known {
    /// Nothing computed yet.
    const NONE: Known = Known {
        mask: 0,
        costs: [MAX_COST as f64; MAX_SOURCES],
    };
}

/// The four directions a pixel takes hypotheses from.
const DIRECTIONS: [(isize, isize); 4] = [(-1, 0), (1, 0), (0, -1), (0, 1)];

/// The distances along a direction a neighbour is picked from: odd, so a pixel never reads
/// one of its own colour.
const NEIGHBOUR_STEPS: [isize; 3] = [1, 3, 5];

/// A source as the kernel uses it: its pose relative to the reference.
struct Rel<'a> {
    view: &'a StereoView,
    /// x_src = r · x_ref + t.
    r: DMat3,
    t: DVec3,
    /// The source's centre in reference-camera coordinates.
    centre: DVec3,
    /// K_src · R · K_ref⁻¹ and K_src · t: the homography of every plane into this source is
    /// the first plus the second times a row that depends on the plane only.
    krk: DMat3,
    kt: DVec3,
    depth: Option<&'a [f32]>,
}

/// One reference view's matching problem.
struct Problem<'a> {
    reference: &'a StereoView,
    sources: Vec<Rel<'a>>,
    opts: &'a PatchMatchOptions,
    /// Window samples: (dx, dy, spatial weight).
    window: Vec<(f64, f64, f64)>,
    range: (f64, f64),
    geometric: bool,
    /// The reference's K⁻ᵀ, which turns a plane's normal into its homographies' row.
    k_inv_t: DMat3,
}

/// The reference window around one pixel: offsets, bilateral weights and centred grey
/// values, one run of `len` f32 per field in one buffer (the warp loop runs over them in f32).
/// The runs are padded to a multiple of [`LANES`] with weight 0 (and a real sample's offset,
/// so a padded sample is never outside when the real ones are inside).
struct Patch {
    /// dx, dy, weight, and weight × (grey value minus the weighted mean): `stride` apart.
    buf: Vec<f32>,
    stride: usize,
    len: usize,
    sum_w: f64,
    var: f64,
}

impl Patch {
    /// Field `field`'s run (0 dx, 1 dy, 2 weight, 3 weight × centred value).
    fn run(&self, field: usize) -> &[f32] {
        &self.buf[field * self.stride..field * self.stride + self.len]
    }

    /// The samples as the NCC kernel reads them.
    fn samples(&self) -> Samples<'_> {
        Samples {
            dx: self.run(0),
            dy: self.run(1),
            w: self.run(2),
            wa: self.run(3),
        }
    }
}

impl<'a> Problem<'a> {
    fn new(
        reference: &'a StereoView,
        sources: &[Source<'a>],
        opts: &'a PatchMatchOptions,
        range: (f64, f64),
        geometric: bool,
    ) -> Problem<'a> {
        let r_ref_t = reference.rotation.transpose();
        let sources = sources
            .iter()
            .take(MAX_SOURCES)
            .map(|s| {
                let r = s.view.rotation * r_ref_t;
                let t = s.view.translation - r * reference.translation;
                let k = s.view.lens.matrix();
                Rel {
                    view: s.view,
                    r,
                    t,
                    centre: -(r.transpose() * t),
                    krk: k * r * reference.lens.inverse(),
                    kt: k * t,
                    depth: s.depth,
                }
            })
            .collect();
        let rad = opts.window_radius as isize;
        let step = opts.window_step.max(1);
        let mut window = Vec::new();
        for dy in (-rad..=rad).step_by(step) {
            for dx in (-rad..=rad).step_by(step) {
                let d2 = (dx * dx + dy * dy) as f64;
                let w = (-d2 / (2.0 * opts.sigma_spatial * opts.sigma_spatial)).exp();
                window.push((dx as f64, dy as f64, w));
            }
        }
        Problem {
            reference,
            sources,
            opts,
            window,
            range,
            geometric,
            k_inv_t: reference.lens.inverse().transpose(),
        }
    }

    fn patch(&self, x: usize, y: usize) -> Patch {
        let img = &self.reference.image;
        let centre = img.at(x, y) as f64;
        let sc2 = 2.0 * self.opts.sigma_color * self.opts.sigma_color;
        let stride = self.window.len().next_multiple_of(LANES);
        // One allocation a pixel: the four runs (the last holds the grey values until the
        // mean is known; f32 holds them exactly).
        let mut buf = vec![0.0f32; 4 * stride];
        let (dxs, rest) = buf.split_at_mut(stride);
        let (dys, rest) = rest.split_at_mut(stride);
        let (ws, was) = rest.split_at_mut(stride);
        let (mut count, mut sum_w, mut sum_a) = (0, 0.0, 0.0);
        for &(dx, dy, spatial) in &self.window {
            let (sx, sy) = (x as isize + dx as isize, y as isize + dy as isize);
            if sx < 0 || sy < 0 || sx >= img.width as isize || sy >= img.height as isize {
                continue;
            }
            let a = img.at(sx as usize, sy as usize);
            let d = a as f64 - centre;
            let w = (spatial * (-d * d / sc2).exp()) as f32;
            (dxs[count], dys[count], ws[count], was[count]) = (dx as f32, dy as f32, w, a);
            sum_w += w as f64;
            sum_a += w as f64 * a as f64;
            count += 1;
        }
        let mean = sum_a / sum_w;
        let mut var = 0.0;
        for (wa, w) in was[..count].iter_mut().zip(&ws[..count]) {
            let c = *wa as f64 - mean;
            *wa = *w * c as f32;
            var += *w as f64 * c * c;
        }
        let len = count.next_multiple_of(LANES);
        for k in count..len {
            (dxs[k], dys[k]) = (dxs[0], dys[0]);
        }
        Patch {
            buf,
            stride,
            len,
            sum_w,
            var: var / sum_w,
        }
    }

    /// 1 − the bilateral-weighted NCC of the window warped into `src` by `h`.
    ///
    /// Precision given up here: the warp of the window's samples runs in f32 (image
    /// coordinates below 10⁴ px keep a thousandth of a pixel), the homography itself is f64.
    fn ncc_cost(&self, patch: &Patch, src: &Rel, h: &DMat3, x: usize, y: usize) -> f64 {
        // H · (cx + dx, cy + dy, 1) = base + dx · H₀ + dy · H₁.
        let base = (*h * DVec3::new(x as f64 + 0.5, y as f64 + 0.5, 1.0)).as_vec3();
        let warp = Warp {
            base,
            hx: h.x_axis.as_vec3(),
            hy: h.y_axis.as_vec3(),
        };
        let samples = patch.samples();
        // Sums in LANES independent lanes, added up in lane order here: a fixed order (the
        // same bits on every machine and thread count).
        let Some([s_b, s_bb, s_ab]) = ncc::sums(&warp, &samples, &src.view.image) else {
            return MAX_COST as f64;
        };
        let lanes = |s: [f32; LANES]| s.iter().fold(0.0f64, |acc, v| acc + *v as f64);
        let (s_b, s_bb, s_ab) = (lanes(s_b), lanes(s_bb), lanes(s_ab));
        let sum_w = patch.sum_w;
        let mean_b = s_b / sum_w;
        let var_b = s_bb / sum_w - mean_b * mean_b;
        let min_var = self.opts.min_texture * self.opts.min_texture * 0.01;
        if var_b < min_var {
            return MAX_COST as f64;
        }
        let ncc = (s_ab / sum_w) / (patch.var * var_b).sqrt();
        (1.0 - ncc).clamp(0.0, MAX_COST as f64)
    }

    /// The homography of the plane (depth, normal) at pixel (x, y) into `src`, or `None` when
    /// the plane passes through the reference centre.
    fn homography(&self, src: &Rel, x: usize, y: usize, depth: f64, n: DVec3) -> Option<DMat3> {
        let point = self.reference.lens.pixel_ray(x, y) * depth;
        let dp = n.dot(point);
        if dp >= -1e-12 * point.length() {
            return None;
        }
        // K (R + t nᵀ / dp) K⁻¹ = K R K⁻¹ + (K t) (K⁻ᵀ n / dp)ᵀ: a rank-one update.
        let m = self.k_inv_t * n / dp;
        Some(src.krk + DMat3::from_cols(src.kt * m.x, src.kt * m.y, src.kt * m.z))
    }

    /// The forward-backward reprojection error (px) of the reference point `point` through
    /// `src`'s depth map, or `None` where the source has no depth for it.
    fn fb_error(&self, src: &Rel, point: DVec3, x: usize, y: usize) -> Option<f64> {
        let depth = src.depth?;
        let ps = src.r * point + src.t;
        if ps.z <= 0.0 {
            return None;
        }
        let u = src.view.lens.project(ps);
        let (w, h) = (src.view.image.width, src.view.image.height);
        if !(u.x >= 0.0 && u.y >= 0.0 && u.x < w as f64 && u.y < h as f64) {
            return None;
        }
        let d = depth[u.y as usize * w + u.x as usize] as f64;
        if d <= 0.0 {
            return None;
        }
        let back = src.view.lens.ray(u) * d;
        let in_ref = src.r.transpose() * (back - src.t);
        if in_ref.z <= 0.0 {
            return None;
        }
        let v = self.reference.lens.project(in_ref);
        Some((v - DVec2::new(x as f64 + 0.5, y as f64 + 0.5)).length())
    }

    /// One source's cost of a hypothesis (photometric, plus the weighted reprojection error
    /// in the geometric pass).
    fn source_cost(
        &self,
        patch: &Patch,
        src: &Rel,
        x: usize,
        y: usize,
        depth: f64,
        n: DVec3,
    ) -> f64 {
        let Some(h) = self.homography(src, x, y, depth, n) else {
            return MAX_COST as f64;
        };
        let mut c = self.ncc_cost(patch, src, &h, x, y);
        if self.geometric {
            let point = self.reference.lens.pixel_ray(x, y) * depth;
            let e = self.fb_error(src, point, x, y).unwrap_or(f64::INFINITY);
            c += self.opts.geom_regularizer * e.min(self.opts.geom_max_cost);
        }
        c
    }

    /// Each source's cost of a hypothesis, taking the costs `known` already holds instead of
    /// computing them again (the same numbers: a source's cost is a function of its inputs).
    fn source_costs(
        &self,
        patch: &Patch,
        x: usize,
        y: usize,
        depth: f64,
        n: DVec3,
        known: &Known,
    ) -> [f64; MAX_SOURCES] {
        let mut costs = known.costs;
        for (j, src) in self.sources.iter().enumerate() {
            if known.mask & (1 << j) == 0 {
                costs[j] = self.source_cost(patch, src, x, y, depth, n);
            }
        }
        costs
    }

    /// The pixel's cost of a hypothesis over every source (those `known` holds taken from
    /// it): the mean of its best `best_k` source costs, and the views selected for it (the
    /// best `best_k + 1`).
    fn cost(
        &self,
        patch: &Patch,
        x: usize,
        y: usize,
        depth: f64,
        n: DVec3,
        known: &Known,
    ) -> (f64, u32) {
        let m = self.sources.len();
        let costs = self.source_costs(patch, x, y, depth, n, known);
        let mut order: Vec<usize> = (0..m).collect();
        order.sort_by(|&a, &b| costs[a].total_cmp(&costs[b]).then(a.cmp(&b)));
        let k = self.opts.best_k.clamp(1, m);
        let mean = order[..k].iter().map(|&j| costs[j]).sum::<f64>() / k as f64;
        let mask = order[..(k + 1).min(m)]
            .iter()
            .fold(0u32, |acc, &j| acc | 1 << j);
        (mean, mask)
    }

    /// The cost of a hypothesis over the selected views only (the mean of their best
    /// `best_k`): what the candidates of one pixel are compared by; with the source costs it
    /// computed.
    fn subset_cost(
        &self,
        patch: &Patch,
        x: usize,
        y: usize,
        depth: f64,
        n: DVec3,
        mask: u32,
    ) -> (f64, Known) {
        let mut known = Known {
            mask,
            costs: [MAX_COST as f64; MAX_SOURCES],
        };
        let mut costs = [MAX_COST as f64; MAX_SOURCES];
        let mut count = 0;
        for (j, src) in self.sources.iter().enumerate() {
            if mask & (1 << j) == 0 {
                continue;
            }
            known.costs[j] = self.source_cost(patch, src, x, y, depth, n);
            costs[count] = known.costs[j];
            count += 1;
        }
        let costs = &mut costs[..count.max(1)];
        costs.sort_unstable_by(f64::total_cmp);
        let k = self.opts.best_k.clamp(1, costs.len());
        (costs[..k].iter().sum::<f64>() / k as f64, known)
    }

    fn in_range(&self, d: f64) -> bool {
        d >= self.range.0 && d <= self.range.1
    }

    fn random_depth(&self, rng: &mut PixelRng) -> f64 {
        // Uniform in inverse depth: equal steps in disparity.
        let (lo, hi) = (1.0 / self.range.1, 1.0 / self.range.0);
        1.0 / (lo + (hi - lo) * rng.uniform())
    }

    /// A random unit normal facing the camera along `ray`.
    fn random_normal(ray: DVec3, rng: &mut PixelRng) -> DVec3 {
        loop {
            let v = DVec3::new(rng.signed(), rng.signed(), rng.signed());
            let l = v.length_squared();
            if l > 1e-6 && l <= 1.0 {
                return facing(v / l.sqrt(), ray);
            }
        }
    }

    /// One pixel's sweep: the neighbours' planes, then random refinements, compared on the
    /// pixel's selected views; the best, with its cost over every view and its new views.
    fn update(
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
        let (start, mut best_known) = if !self.in_range(d_cur) {
            (f64::INFINITY, Known::NONE)
        } else if current.3 != 0 {
            (current.2 as f64, Known::NONE)
        } else {
            self.subset_cost(&patch, x, y, d_cur, n_cur, mask)
        };
        let mut best = (d_cur, n_cur, start);
        let mut changed = false;
        let mut consider = |d: f64, n: DVec3, best: &mut (f64, DVec3, f64)| {
            if !self.in_range(d) {
                return;
            }
            let (c, known) = self.subset_cost(&patch, x, y, d, n, mask);
            if c < best.2 {
                *best = (d, n, c);
                best_known = known;
                changed = true;
            }
        };
        for (dx, dy) in DIRECTIONS {
            // ACMH's adaptive choice, reduced: of the direction's neighbours at odd
            // distances, the one whose plane has the lowest cost (the nearest on a tie).
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
            let Some((nx, ny, _)) = pick else {
                continue;
            };
            let j = ny * state.width + nx;
            let n = to_d(state.normal[j]);
            let plane_point = self.reference.lens.pixel_ray(nx, ny) * state.depth[j] as f64;
            let denom = n.dot(ray);
            if denom >= -1e-12 {
                continue;
            }
            consider(n.dot(plane_point) / denom, n, &mut best);
        }
        let mut rng = PixelRng::new(self.opts.seed, view_salt, iteration as u64 + 1, i as u64);
        let shrink = 0.5f64.powi(iteration as i32);
        let (d0, n0) = (best.0, best.1);
        let perturb_d = |rng: &mut PixelRng| d0 * (1.0 + 0.05 * shrink * rng.signed());
        let perturb_n = |rng: &mut PixelRng| {
            let v = n0 + DVec3::new(rng.signed(), rng.signed(), rng.signed()) * (0.3 * shrink);
            facing(v.normalize_or(n0), ray)
        };
        let candidates = [
            (
                self.random_depth(&mut rng),
                Self::random_normal(ray, &mut rng),
            ),
            (perturb_d(&mut rng), n0),
            (d0, perturb_n(&mut rng)),
            (perturb_d(&mut rng), perturb_n(&mut rng)),
            (d0, Self::random_normal(ray, &mut rng)),
        ];
        for (d, n) in candidates {
            consider(d, n, &mut best);
        }
        if !changed && current.3 != 0 {
            return current;
        }
        let (cost, views) = self.cost(&patch, x, y, best.0, best.1, &best_known);
        (best.0 as f32, to_f(best.1), cost as f32, views)
    }

    /// Random hypotheses for every pixel, each with its cost.
    fn initialise(&self, view_salt: u64) -> Hypotheses {
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
    fn scored(&self, x: usize, y: usize, d: f64, n: DVec3) -> (f32, u32) {
        let patch = self.patch(x, y);
        if patch.var.sqrt() < self.opts.min_texture {
            return (MAX_COST, 0);
        }
        let (c, v) = self.cost(&patch, x, y, d, n, &Known::NONE);
        (c as f32, v)
    }

    /// Every hypothesis scored again (after a change of scale or of pass).
    fn rescored(&self, mut state: Hypotheses) -> Hypotheses {
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
    fn sweep(
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

fn to_d(n: [f32; 3]) -> DVec3 {
    DVec3::new(n[0] as f64, n[1] as f64, n[2] as f64)
}

fn to_f(n: DVec3) -> [f32; 3] {
    [n.x as f32, n.y as f32, n.z as f32]
}

/// `n` turned to face the camera along `ray` (n · ray < 0).
fn facing(n: DVec3, ray: DVec3) -> DVec3 {
    if n.dot(ray) > 0.0 {
        -n
    } else {
        n
    }
}

fn from_rows(w: usize, h: usize, rows: Vec<Vec<Update>>) -> Hypotheses {
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
fn upsampled(coarse: &Hypotheses, w: usize, h: usize) -> Hypotheses {
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

/// A salt that keeps one view's random draws apart from another's.
fn salt(reference: &StereoView) -> u64 {
    reference
        .id
        .wrapping_mul(0x9e37_79b9_7f4a_7c15)
        .rotate_left(29)
}

/// The photometric pass over one reference view: hypotheses at the full size (unfiltered,
/// as COLMAP keeps them for a geometric pass), or `None` with no source view.
pub fn photometric(
    reference: &StereoView,
    sources: &[Source],
    range: (f64, f64),
    opts: &PatchMatchOptions,
) -> Option<Hypotheses> {
    if sources.is_empty() || !(range.0 > 0.0 && range.1 > range.0) {
        return None;
    }
    let view_salt = salt(reference);
    // The coarser levels, finest first: level k halves the image k times. The full-size
    // level is the caller's views themselves.
    let mut coarse: Vec<(StereoView, Vec<StereoView>)> = Vec::new();
    for _ in 1..opts.scales.max(1) {
        let (r, s) = match coarse.last() {
            Some((r, s)) => (r, s.iter().collect::<Vec<_>>()),
            None => (reference, sources.iter().map(|s| s.view).collect()),
        };
        if r.image.width < 32 || r.image.height < 32 {
            break;
        }
        coarse.push((r.halved(), s.into_iter().map(StereoView::halved).collect()));
    }
    let levels = coarse
        .iter()
        .rev()
        .map(|(r, s)| (r, s.iter().collect::<Vec<_>>()))
        .chain(std::iter::once((
            reference,
            sources.iter().map(|s| s.view).collect(),
        )));
    let mut state: Option<Hypotheses> = None;
    for (r, s) in levels {
        let srcs: Vec<Source> = s
            .into_iter()
            .map(|v| Source {
                view: v,
                depth: None,
            })
            .collect();
        let problem = Problem::new(r, &srcs, opts, range, false);
        state = Some(match state.take() {
            None => problem.sweep(problem.initialise(view_salt), view_salt, 0, opts.iterations),
            Some(coarse) => {
                let start = problem.rescored(upsampled(&coarse, r.image.width, r.image.height));
                // The finer scale refines: its perturbations start where the coarse ones ended.
                problem.sweep(
                    start,
                    view_salt,
                    opts.iterations.saturating_sub(opts.refine_iterations),
                    opts.refine_iterations,
                )
            }
        });
    }
    state
}

/// The geometric pass: the photometric hypotheses refined with the forward-backward
/// reprojection error through each source's depth map (`Source::depth`) added to its cost.
pub fn geometric(
    reference: &StereoView,
    sources: &[Source],
    range: (f64, f64),
    start: Hypotheses,
    opts: &PatchMatchOptions,
) -> Hypotheses {
    let problem = Problem::new(reference, sources, opts, range, true);
    let state = problem.rescored(start);
    let first = opts.iterations.saturating_sub(opts.geom_iterations);
    problem.sweep(state, salt(reference) ^ 0x9e0, first, opts.geom_iterations)
}

/// COLMAP's filter: a depth is kept where at least `filter_min_consistent` source views
/// agree: NCC at least `filter_min_ncc`, triangulation angle at least `filter_min_angle_deg`,
/// and (with `geometric`) forward-backward error at most `filter_geom_max_error`.
pub fn filter(
    reference: &StereoView,
    sources: &[Source],
    range: (f64, f64),
    state: &Hypotheses,
    geometric: bool,
    opts: &PatchMatchOptions,
) -> StereoMaps {
    let problem = Problem::new(reference, sources, opts, range, false);
    let min_angle = opts.filter_min_angle_deg.to_radians();
    let w = state.width;
    let kept: Vec<(f32, [f32; 3], [f32; 2])> = (0..state.depth.len())
        .into_par_iter()
        .map(|i| {
            let none = (0.0, [0.0; 3], [0.0; 2]);
            let (x, y) = (i % w, i / w);
            let d = state.depth[i] as f64;
            if d.is_nan() || d <= 0.0 || state.cost[i] >= MAX_COST {
                return none;
            }
            let patch = problem.patch(x, y);
            if patch.var.sqrt() < opts.min_texture {
                return none;
            }
            let n = to_d(state.normal[i]);
            let point = reference.lens.pixel_ray(x, y) * d;
            let costs = problem.source_costs(&patch, x, y, d, n, &Known::NONE);
            let (mut count, mut ncc_sum) = (0usize, 0.0);
            for (j, src) in problem.sources.iter().enumerate() {
                let ncc = 1.0 - costs[j];
                let angle = crate::fusion::angle_between(point, point - src.centre);
                let consistent_geom = !geometric
                    || problem
                        .fb_error(src, point, x, y)
                        .is_some_and(|e| e <= opts.filter_geom_max_error);
                if ncc >= opts.filter_min_ncc && angle >= min_angle && consistent_geom {
                    count += 1;
                    ncc_sum += ncc;
                }
            }
            if count < opts.filter_min_consistent.max(1) {
                return none;
            }
            (
                d as f32,
                state.normal[i],
                [(ncc_sum / count as f64) as f32, count as f32],
            )
        })
        .collect();
    StereoMaps {
        width: state.width,
        height: state.height,
        depth: kept.iter().map(|k| k.0).collect(),
        normal: kept.iter().map(|k| k.1).collect(),
        confidence: kept.iter().map(|k| k.2).collect(),
    }
}
