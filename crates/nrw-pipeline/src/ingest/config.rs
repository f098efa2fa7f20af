//! Ingest's settings, and what a unit prepares before its groups run: what every file of
//! the stage reads, in a file of its own so they import it and not each other.

use std::collections::BTreeMap;
use std::path::PathBuf;

use nrw_colmap::{Format, Reconstruction, UndistortOptions};
use nrw_dataset::units::UnitRecord;
use nrw_render::{Filters, RenderCloud};

/// Largest splat radius accepted: wider splats smear a render into a few blobs, and each
/// point would touch thousands of pixels.
pub const MAX_RADIUS: f32 = 32.0;

/// Ingest's settings; [`IngestConfig::new`] fills in the paper's.
#[derive(Debug, Clone)]
pub struct IngestConfig {
    /// Scene folder (COLMAP layout) or a model folder itself.
    pub scene: PathBuf,
    /// Dataset folder to write.
    pub out: nrw_dataset::Location,
    /// Photo folder [default: images/ next to the model].
    pub images: Option<PathBuf>,
    /// Model encoding to read [default: bin when present].
    pub format: Option<Format>,
    /// Sub-model `sparse/N` to read [default: the one with the most registered images].
    pub model: Option<u32>,
    /// Point cloud [default: dense/fused.ply, else the sparse points].
    pub points: Option<PathBuf>,
    /// Folder of per-photo ADE20K label maps.
    pub semantics: Option<PathBuf>,
    /// CSV or JSON Lines file of each photo's licence, author and source, keyed by image
    /// name ([`nrw_dataset::photo_info`]).
    pub photo_info: Option<PathBuf>,
    /// Segment each kept photo with this model instead of reading label maps.
    pub segment: Option<InlineSegment>,
    /// Store every view as COLMAP's `image_undistorter` would: the PINHOLE camera it computes
    /// and the photo resampled to it (`ingest --undistort`).
    pub undistort: Option<UndistortOptions>,
    /// Statistical outlier removal before rendering: (k neighbours, σ) (`ingest --denoise`).
    pub denoise: Option<(usize, f64)>,
    /// Normals by PCA of k neighbours for a cloud without them (`ingest --estimate-normals`).
    pub estimate_normals: Option<usize>,
    /// Shorter side of a render in pixels (the paper: 600).
    pub min_dim: u32,
    /// Splat radius in render pixels (the paper: 1).
    pub radius: f32,
    /// The paper's filters: 85% empty, 450 px.
    pub filters: Filters,
    /// Drop a photo whose sharpness (variance of the Laplacian, [`nrw_dataset::PhotoSignals`])
    /// is under this (`ingest --min-sharpness`; off by default).
    pub min_sharpness: Option<f64>,
    /// Images per shard (the unit of resumption and of work units).
    pub rows_per_shard: usize,
    /// Make an unreadable photo or label map an error instead of an `unreadable` verdict.
    pub strict: bool,
    /// Read a photo that is a symbolic link out of the images folder (refused by default: a
    /// model's names cannot make ingest read files the user did not put there).
    pub follow_outside_links: bool,
    /// Stop after this many groups, as an interruption would (resume tests).
    pub stop_after_groups: Option<usize>,
    /// Sleep this long after each group (so tests can kill a unit mid-way).
    pub pause_after_group: Option<std::time::Duration>,
}

impl IngestConfig {
    /// The paper's settings for a scene and a dataset folder.
    pub fn new(scene: impl Into<PathBuf>, out: impl Into<nrw_dataset::Location>) -> IngestConfig {
        IngestConfig {
            scene: scene.into(),
            out: out.into(),
            images: None,
            format: None,
            model: None,
            points: None,
            semantics: None,
            photo_info: None,
            segment: None,
            undistort: None,
            denoise: None,
            estimate_normals: None,
            min_sharpness: None,
            min_dim: 600,
            radius: 1.0,
            filters: Filters::default(),
            rows_per_shard: 64,
            strict: false,
            follow_outside_links: false,
            stop_after_groups: None,
            pause_after_group: None,
        }
    }
}

/// `ingest --segment-weights`: the model and mode that label each kept photo.
#[derive(Debug, Clone)]
pub struct InlineSegment {
    /// The SegFormer folder (config.json + model.safetensors).
    pub weights: PathBuf,
    pub mode: nrw_segment::Mode,
}

/// Everything a unit derives from the inputs before rendering (every unit derives the same).
pub(super) struct Prepared {
    pub(super) rec: Reconstruction,
    pub(super) photos_dir: PathBuf,
    pub(super) photos: BTreeMap<u32, (u32, u32)>,
    /// Photos whose header cannot be read, with the reason (their views are `unreadable`).
    pub(super) unreadable: BTreeMap<u32, String>,
    pub(super) cloud: RenderCloud,
    pub(super) source: String,
    pub(super) record: UnitRecord,
    /// The model of `--segment-weights`, loaded once, and its mode.
    pub(super) segmenter: Option<(nrw_segment::Segformer, nrw_segment::Mode)>,
    /// With `--undistort`: the photos' own (distorted) cameras; `rec` then holds the
    /// undistorted PINHOLE ones.
    pub(super) distorted: Option<BTreeMap<u32, nrw_colmap::Camera>>,
}
