//! The cost of a plane hypothesis at a pixel: the reference window, its bilateral-weighted NCC
//! through each source's homography, the geometric pass's forward-backward error, and the
//! mean of the best views.

use glam::{DMat3, DVec2, DVec3};

use crate::ncc::{self, Warp, LANES};

use super::options::{MAX_COST, MAX_SOURCES};
use super::problem::{Known, Patch, Plane, Problem, Rel};

impl Problem<'_> {
    pub(super) fn patch(&self, x: usize, y: usize) -> Patch {
        let img = &self.reference.image;
        let centre = img.at(x, y) as f64;
        let sc2 = 2.0 * self.opts.sigma_color * self.opts.sigma_color;
        let stride = self.window.len().next_multiple_of(LANES);
        // The four runs in one pooled buffer (the last holds the grey values until the mean
        // is known; f32 holds them exactly).
        let mut buf = super::problem::pooled(4 * stride);
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
            (dxs[k], dys[k], ws[k], was[k]) = (dxs[0], dys[0], 0.0, 0.0);
        }
        Patch {
            buf,
            stride,
            len,
            count,
            sum_w,
            var: var / sum_w,
        }
    }

    /// 1 − the bilateral-weighted NCC of the window warped into `src` by `h`.
    ///
    /// Precision given up here: the warp of the window's samples runs in f32 (image
    /// coordinates below 10⁴ px keep a thousandth of a pixel), the homography itself is f64.
    pub(super) fn ncc_cost(&self, patch: &Patch, src: &Rel, h: &DMat3, x: usize, y: usize) -> f64 {
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

    /// A hypothesis at pixel (x, y) as every source's cost uses it: its point and the row of
    /// its homographies, computed once for all the sources.
    pub(super) fn plane(&self, x: usize, y: usize, depth: f64, n: DVec3) -> Plane {
        let point = self.reference.lens.pixel_ray(x, y) * depth;
        let dp = n.dot(point);
        // K (R + t nᵀ / dp) K⁻¹ = K R K⁻¹ + (K t) (K⁻ᵀ n / dp)ᵀ: a rank-one update whose
        // row does not depend on the source.
        // Through the centre when dp ≥ −10⁻¹² |point|; a NaN dp is not counted as through it.
        let through_centre = matches!(
            dp.partial_cmp(&(-1e-12 * point.length())),
            Some(std::cmp::Ordering::Greater | std::cmp::Ordering::Equal)
        );
        let row = (!through_centre).then(|| self.k_inv_t * n / dp);
        Plane { x, y, point, row }
    }

    /// The homography of `plane` into `src`, or `None` when the plane passes through the
    /// reference centre.
    pub(super) fn homography(&self, src: &Rel, plane: &Plane) -> Option<DMat3> {
        let m = plane.row?;
        Some(src.krk + DMat3::from_cols(src.kt * m.x, src.kt * m.y, src.kt * m.z))
    }

    /// The forward-backward reprojection error (px) of the reference point `point` through
    /// `src`'s depth map, or `None` where the source has no depth for it.
    pub(super) fn fb_error(&self, src: &Rel, point: DVec3, x: usize, y: usize) -> Option<f64> {
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
    pub(super) fn source_cost(&self, patch: &Patch, src: &Rel, plane: &Plane) -> f64 {
        let Some(h) = self.homography(src, plane) else {
            return MAX_COST as f64;
        };
        let (x, y) = (plane.x, plane.y);
        let mut c = self.ncc_cost(patch, src, &h, x, y);
        if self.geometric {
            let e = self
                .fb_error(src, plane.point, x, y)
                .unwrap_or(f64::INFINITY);
            c += self.opts.geom_regularizer * e.min(self.opts.geom_max_cost);
        }
        c
    }

    /// Each source's cost of a hypothesis, taking the costs `known` already holds instead of
    /// computing them again (the same numbers: a source's cost is a function of its inputs).
    pub(super) fn source_costs(
        &self,
        patch: &Patch,
        x: usize,
        y: usize,
        depth: f64,
        n: DVec3,
        known: &Known,
    ) -> [f64; MAX_SOURCES] {
        let mut costs = known.costs;
        let plane = self.plane(x, y, depth, n);
        for (j, src) in self.sources.iter().enumerate() {
            if known.mask & (1 << j) == 0 {
                costs[j] = self.source_cost(patch, src, &plane);
            }
        }
        costs
    }

    /// The pixel's cost of a hypothesis over every source (those `known` holds taken from
    /// it): the mean of its best `best_k` source costs, and the views selected for it (the
    /// best `best_k + 1`).
    pub(super) fn cost(
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
        let mut order: [usize; MAX_SOURCES] = std::array::from_fn(|j| j);
        let order = &mut order[..m];
        order.sort_unstable_by(|&a, &b| costs[a].total_cmp(&costs[b]).then(a.cmp(&b)));
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
    pub(super) fn subset_cost(
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
        let plane = self.plane(x, y, depth, n);
        for (j, src) in self.sources.iter().enumerate() {
            if mask & (1 << j) == 0 {
                continue;
            }
            known.costs[j] = self.source_cost(patch, src, &plane);
            costs[count] = known.costs[j];
            count += 1;
        }
        let costs = &mut costs[..count.max(1)];
        costs.sort_unstable_by(f64::total_cmp);
        let k = self.opts.best_k.clamp(1, costs.len());
        (costs[..k].iter().sum::<f64>() / k as f64, known)
    }
}
