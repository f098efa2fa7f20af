//! Exports of a dataset as files other tools read: the paper's published code (`official`
//! PNG folders and `tfrecord`), one folder per photo (`files`), NeRF-W's Phototourism layout
//! (`nerfw`), nerfstudio's `transforms.json` (`nerfstudio`) and the COLMAP folder the 3DGS
//! family reads (`gsplat`: image, mask and depth pyramids, graphdeco's depth priors) and
//! MegaDepth's (`megadepth`: depth `.h5`, the undistorted text model, D2-Net's `scene_info`).
//!
//! One entry point, [`export`]; one seam per layout, [`writer::LayoutWriter`] (the layouts of one
//! file set per view share [`stream`]). Every file is claimed in a hidden staging folder
//! ([`staging::Staged`]: the name check and the collision check) and the export is published
//! whole, to a local folder or under an object-store URL.

mod colmap_model;
pub mod encoders;
pub mod error;
pub mod layout;
pub mod layouts;
pub mod staging;
pub mod stream;
pub mod summary;
pub mod writer;

// The layouts and encoders by their short names (one path per module, whatever its folder).
pub use encoders::{hdf5, inverse_depth, pyramid, record};
pub use layouts::megadepth::{self, imc};
pub use layouts::paper::{self, official, published, tfrecord};
pub use layouts::{files, gsplat, nerfbaselines, nerfstudio, nerfw};
pub use nrw_npy::{npz, pickle};

pub use error::{ExportError, Result};
pub use layout::Layout;
pub use staging::{join_under, EXPORT_JSON};
pub use stream::index_width;
pub use summary::{DepthRecord, ExportConfig, ExportSummary, Skipped, SplitExport};
pub use tfrecord::tfrecord_name;
pub use writer::ScenePoint;

use nrw_dataset::depth::DepthMap;
use nrw_dataset::reader::Dataset;

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

/// Export `ds` as `cfg` says into `cfg.out` (a folder or an object-store URL), replacing an
/// earlier export there whole; `tick` is called once per view done.
pub fn export(
    ds: &Dataset,
    cfg: &ExportConfig,
    inputs: &Inputs,
    tick: &(dyn Fn() + Sync),
) -> Result<ExportSummary> {
    let job = writer::Job {
        ds,
        cfg,
        splits: ds.splits(),
        inputs,
        tick,
    };
    let layout = layouts::writer_of(cfg.layout);
    layout.check(&job)?;
    let staged = staging::Staged::new(&cfg.out)?;
    let mut summary = ExportSummary::begin(&ds.dir.to_string(), cfg);
    let written = layout.write(&job, &staged, &mut summary).and_then(|()| {
        staged.write(
            EXPORT_JSON,
            &serde_json::to_vec_pretty(&summary).expect("json"),
        )
    });
    match written {
        Ok(()) => {
            staged.publish()?;
            Ok(summary)
        }
        Err(e) => {
            staged.abandon();
            Err(e)
        }
    }
}
