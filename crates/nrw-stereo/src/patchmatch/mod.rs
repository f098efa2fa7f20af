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

mod cost;
mod options;
mod problem;
mod sweep;

use rayon::prelude::*;

use crate::view::StereoView;

pub use options::{Hypotheses, PatchMatchOptions, Source, StereoMaps, MAX_COST, MAX_SOURCES};
use problem::{to_d, Known, Problem};
use sweep::upsampled;

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
