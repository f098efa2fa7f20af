//! What an export takes beyond the dataset, supplied by the caller (which owns the style
//! stage, the scene's model and densify's maps): the official layout's distance rows, the
//! scene's points and model, and a depth prior better than the render's z-buffer.

use nrw_dataset::depth::DepthMap;

/// One 3D point of the scene's initialisation cloud, for `points3D.bin` (and a PLY with
/// normals where the layout has one).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ScenePoint {
    pub id: u64,
    pub xyz: [f64; 3],
    pub rgb: [u8; 3],
    pub error: f64,
    /// The unit normal, when the cloud has normals (a dense cloud does; SfM points do not).
    pub normal: Option<[f32; 3]>,
}

/// The train views' style distance matrix (f64) for the given image ids in that order, as
/// rows: `n`, rows per block, and a function giving a block of rows (row-major); None when
/// the dataset has no official descriptors. Given by the caller, which owns the style stage;
/// rows come block by block so the n × n matrix is never held whole.
pub type DistMatrix<'a> = &'a (dyn Fn(&[u32]) -> nrw_dataset::Result<Option<DistRows>> + Sync);

/// Blocks of rows of a distance matrix: (rows per block, the block of rows in a range).
pub type DistRows = (
    usize,
    Box<dyn FnMut(std::ops::Range<usize>) -> nrw_dataset::Result<Vec<f64>>>,
);

/// What some layouts need beyond the dataset, supplied by the caller (which owns the style
/// stage and the scene's model).
#[derive(Clone, Copy, Default)]
pub struct Inputs<'a> {
    /// The official layout's `dist_NAME.pckl` (none: no pickle is written).
    pub dist: Option<DistMatrix<'a>>,
    /// The scene's 3D points, which `nerfw`, `nerfstudio` and `gsplat` carry.
    pub points: Option<&'a [ScenePoint]>,
    /// The scene's model as ingested, whose tracks `megadepth` carries.
    pub model: Option<&'a nrw_colmap::Reconstruction>,
    /// A better depth than the render's z-buffer (densify's MVS maps), for the layouts that
    /// write depth priors.
    pub depth_prior: Option<&'a DepthPrior<'a>>,
}

/// Where a view's depth prior comes from when it is not the render's z-buffer.
pub struct DepthPrior<'a> {
    /// What `export.json` names as the source.
    pub source: String,
    /// The view's depth at its stored size (0 = none), or None to fall back to the render's.
    #[allow(clippy::type_complexity)]
    pub depth:
        &'a (dyn Fn(&nrw_dataset::ViewRow) -> std::result::Result<Option<Prior>, String> + Sync),
}

/// One view's depth prior at its stored size.
pub struct Prior {
    /// Depth along the camera's z, 0 = none.
    pub depth: DepthMap,
    /// How much to trust each pixel's depth in [0, 1] (densify: the mean NCC of the agreeing
    /// source views), when the source has a measure; 0 where there is no depth.
    pub confidence: Option<Vec<f32>>,
}

/// `export.json`'s name for the render's z-buffer as a depth source.
pub const RENDER_DEPTH: &str = "the render's z-buffer";
