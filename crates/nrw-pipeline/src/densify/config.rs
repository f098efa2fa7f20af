//! What densify is asked to do, its defaults, and the check of a configuration.

use std::path::{Path, PathBuf};

use nrw_stereo::{FusionOptions, PatchMatchOptions};

use crate::settings::densify::DensifySettings;

use crate::error::{PipelineError, Result, Setting};

pub use crate::settings::densify::{
    DEFAULT_FUSION_CACHE_MB, DEFAULT_MAX_IMAGE_SIZE, DEFAULT_MAX_SOURCES,
};

/// A densify run: the scene, where the workspace goes, and the settings it runs with
/// (declared once, in [`crate::settings::densify`]).
#[derive(Debug, Clone)]
pub struct DensifyConfig {
    /// The scene folder (or its model folder).
    pub scene: PathBuf,
    /// The workspace: a folder, or an object-store URL; `SCENE/dense` when `None`.
    pub out: Option<nrw_dataset::Location>,
    /// Where the photos are, if not the scene's `images/`.
    pub images: Option<PathBuf>,
    /// Whether photo names may resolve through links out of the photo folder.
    pub follow_outside_links: bool,
    /// Stop a pass after this many views, as an interruption would (for resume tests).
    pub stop_after_views: Option<usize>,
    pub settings: DensifySettings,
}

impl DensifyConfig {
    /// The defaults for a scene folder.
    pub fn new(scene: &Path) -> DensifyConfig {
        DensifyConfig {
            scene: scene.to_path_buf(),
            out: None,
            images: None,
            follow_outside_links: false,
            stop_after_views: None,
            settings: DensifySettings::default(),
        }
    }
}

impl DensifySettings {
    /// Densify's configuration for `scene` with these settings (the output and the photo
    /// folder are the caller's).
    pub fn config(&self, scene: &Path) -> DensifyConfig {
        DensifyConfig {
            settings: self.clone(),
            ..DensifyConfig::new(scene)
        }
    }
}

/// The settings a workspace is built with: every unit and a resumed run must share them.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub(super) struct Settings {
    pub(super) tool_version: String,
    pub(super) max_image_size: Option<u64>,
    pub(super) preset: crate::settings::densify::DensifyPreset,
    pub(super) max_sources: usize,
    pub(super) geometric: bool,
    pub(super) stereo: PatchMatchOptions,
    pub(super) fusion: FusionOptions,
}

impl Settings {
    pub(super) fn of(cfg: &DensifyConfig) -> Settings {
        Settings {
            tool_version: env!("CARGO_PKG_VERSION").to_string(),
            max_image_size: cfg.settings.max_image_size(),
            preset: cfg.settings.preset,
            max_sources: cfg.settings.matching().max_sources,
            geometric: cfg.settings.geometric,
            stereo: cfg.settings.stereo(),
            fusion: cfg.settings.fusion(),
        }
    }
}

/// Densify's settings refused before any work: each names its key.
pub(crate) fn check(cfg: &DensifyConfig) -> Result<()> {
    let m = cfg.settings.matching();
    if m.max_sources == 0 || m.max_sources > nrw_stereo::patchmatch::MAX_SOURCES {
        return Err(PipelineError::config(
            Setting::Key("densify.max_sources"),
            format!(
                "is {}; it must be 1 to {}",
                m.max_sources,
                nrw_stereo::patchmatch::MAX_SOURCES
            ),
        ));
    }
    if cfg.settings.min_num_pixels == 0 {
        return Err(PipelineError::config(
            Setting::Key("densify.min_num_pixels"),
            "is 0; a fused point needs at least 1 pixel (the default is 2, COLMAP's 5)",
        ));
    }
    if cfg.settings.max_image_size() == Some(0) {
        return Err(PipelineError::config(
            Setting::Key("densify.max_image_size"),
            "is 0; leave it out for the photos' own size",
        ));
    }
    if m.iterations == 0 || m.window_radius == 0 || m.scales == 0 {
        return Err(PipelineError::config(
            Setting::Stereo,
            "iterations, window radius and scales must each be at least 1",
        ));
    }
    Ok(())
}
