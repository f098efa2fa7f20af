//! What densify is asked to do, its defaults, and the check of a configuration.

use std::path::{Path, PathBuf};

use nrw_stereo::{FusionOptions, PatchMatchOptions};

use crate::error::{PipelineError, Result, Setting};

/// The longer side the undistorted views are capped at by default (about 0.5 MP at 4:3):
/// stereo's time grows with the pixels.
pub const DEFAULT_MAX_IMAGE_SIZE: u64 = 800;

/// Source views matched per reference view by default (COLMAP's `__auto__, 20` takes 20;
/// the cost of a view grows with the count, and Gipuma's best-3 rarely needs more than 8).
pub const DEFAULT_MAX_SOURCES: usize = 8;

/// Fusion's map cache by default, in MiB: about 100 views at 0.5 MP (19 bytes a pixel).
pub const DEFAULT_FUSION_CACHE_MB: usize = 1024;

/// What densify is asked to do.
#[derive(Debug, Clone)]
pub struct DensifyConfig {
    /// The scene folder (or its model folder).
    pub scene: PathBuf,
    /// The workspace: a folder, or an object-store URL; `SCENE/dense` when `None`.
    pub out: Option<nrw_dataset::Location>,
    /// Replace an existing workspace (a user's own COLMAP run is never touched otherwise).
    pub overwrite: bool,
    /// Longer side of the undistorted views (`None`: the photos' own size).
    pub max_image_size: Option<u64>,
    /// Source views per reference view.
    pub max_sources: usize,
    /// Run the geometric-consistency pass (COLMAP's `geom_consistency`).
    pub geometric: bool,
    /// Where the photos are, if not the scene's `images/`.
    pub images: Option<PathBuf>,
    /// Whether photo names may resolve through links out of the photo folder.
    pub follow_outside_links: bool,
    pub stereo: PatchMatchOptions,
    pub fusion: FusionOptions,
    /// The most bytes of maps fusion holds at once (COLMAP's `cache_size`); the cloud does not
    /// depend on it.
    pub fusion_cache_bytes: usize,
    /// Stop a pass after this many views, as an interruption would (for resume tests).
    pub stop_after_views: Option<usize>,
}

impl DensifyConfig {
    /// The defaults for a scene folder.
    pub fn new(scene: &Path) -> DensifyConfig {
        DensifyConfig {
            scene: scene.to_path_buf(),
            out: None,
            overwrite: false,
            max_image_size: Some(DEFAULT_MAX_IMAGE_SIZE),
            max_sources: DEFAULT_MAX_SOURCES,
            geometric: true,
            images: None,
            follow_outside_links: false,
            stereo: PatchMatchOptions::default(),
            fusion: FusionOptions::default(),
            fusion_cache_bytes: DEFAULT_FUSION_CACHE_MB << 20,
            stop_after_views: None,
        }
    }
}

/// The settings a workspace is built with: every unit and a resumed run must share them.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub(super) struct Settings {
    pub(super) tool_version: String,
    pub(super) max_image_size: Option<u64>,
    pub(super) max_sources: usize,
    pub(super) geometric: bool,
    pub(super) stereo: PatchMatchOptions,
    pub(super) fusion: FusionOptions,
}

impl Settings {
    pub(super) fn of(cfg: &DensifyConfig) -> Settings {
        Settings {
            tool_version: env!("CARGO_PKG_VERSION").to_string(),
            max_image_size: cfg.max_image_size,
            max_sources: cfg.max_sources,
            geometric: cfg.geometric,
            stereo: cfg.stereo.clone(),
            fusion: cfg.fusion.clone(),
        }
    }
}

pub(super) fn check(cfg: &DensifyConfig) -> Result<()> {
    if cfg.max_sources == 0 || cfg.max_sources > nrw_stereo::patchmatch::MAX_SOURCES {
        return Err(PipelineError::config(
            Setting::Key("densify.max_sources"),
            format!(
                "is {}; it must be 1 to {}",
                cfg.max_sources,
                nrw_stereo::patchmatch::MAX_SOURCES
            ),
        ));
    }
    if cfg.fusion.min_num_pixels == 0 {
        return Err(PipelineError::config(
            Setting::Key("densify.min_num_pixels"),
            "is 0; a fused point needs at least 1 pixel (the default is 2, COLMAP's 5)",
        ));
    }
    if cfg.max_image_size == Some(0) {
        return Err(PipelineError::config(
            Setting::Key("densify.max_image_size"),
            "is 0; leave it out for the photos' own size",
        ));
    }
    if cfg.stereo.iterations == 0 || cfg.stereo.window_radius == 0 || cfg.stereo.scales == 0 {
        return Err(PipelineError::config(
            Setting::Stereo,
            "iterations, window radius and scales must each be at least 1",
        ));
    }
    Ok(())
}
