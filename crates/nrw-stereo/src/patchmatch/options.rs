//! The kernel's settings and the hypotheses and maps it works on.

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
