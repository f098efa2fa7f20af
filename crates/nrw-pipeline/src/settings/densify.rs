//! `densify`'s settings: the flags of `nrw-etl densify` and the `[densify]` table of a
//! pipeline file, one declaration.

use nrw_stereo::{FusionOptions, PatchMatchOptions};
use serde::{Deserialize, Serialize};

/// The longer side the undistorted views are capped at by default (about 0.5 MP at 4:3):
/// stereo's time grows with the pixels.
pub const DEFAULT_MAX_IMAGE_SIZE: u64 = 800;

/// Source views matched per reference view by default (COLMAP's `__auto__, 20` takes 20;
/// the cost of a view grows with the count, and Gipuma's best-3 rarely needs more than 8).
pub const DEFAULT_MAX_SOURCES: usize = 8;

/// Fusion's map cache by default, in MiB: about 100 views at 0.5 MP (19 bytes a pixel).
pub const DEFAULT_FUSION_CACHE_MB: usize = 1024;

/// How densify matches and fuses; a setting left out of `[densify]` (or off the command line)
/// is densify's default.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, clap::Args)]
#[serde(deny_unknown_fields, default)]
pub struct DensifySettings {
    /// Longer side of the undistorted views, in pixels; 0 keeps the photos' size
    #[arg(long, default_value_t = DensifySettings::default().max_image_size)]
    pub max_image_size: u64,
    /// Source views each view is matched with (the most overlapping, at least 1° apart)
    #[arg(long, default_value_t = DensifySettings::default().max_sources)]
    pub max_sources: usize,
    /// Red-black PatchMatch sweeps per scale
    #[arg(long, default_value_t = DensifySettings::default().iterations)]
    pub iterations: usize,
    /// Half the matching window's side, in pixels (sampled every second pixel)
    #[arg(long, default_value_t = DensifySettings::default().window_radius)]
    pub window_radius: usize,
    /// Coarse-to-fine levels (1: full size only; each level halves the image)
    #[arg(long, default_value_t = DensifySettings::default().scales)]
    pub scales: usize,
    /// Skip the geometric-consistency pass (faster, noisier: photometric maps are fused)
    #[arg(long = "no-geometric", action = clap::ArgAction::SetFalse)]
    pub geometric: bool,
    /// The fewest pixels (of different views) fusion merges into a point: COLMAP's
    /// min_num_pixels (COLMAP: 5). The default 2 is OpenMVS's: a surface two photos see makes
    /// points; 5 gives a sparser, cleaner cloud of what many photos see
    #[arg(long, default_value_t = DensifySettings::default().min_num_pixels)]
    pub min_num_pixels: usize,
    /// The fewest source views whose depth must agree with a pixel's for it to keep its depth
    /// (COLMAP's filter_min_num_consistent, 2). 1 (OpenMVS's adjusted filter) keeps surfaces
    /// only two photos see, and more wrong depths with them: see docs/densify.md
    #[arg(long, default_value_t = DensifySettings::default().min_consistent)]
    pub min_consistent: usize,
    /// The most MiB of depth, normal and colour maps fusion holds at once (COLMAP's
    /// cache_size): views beyond it are read again when a walk needs them. The cloud is the
    /// same whatever the size; only the time is not
    #[arg(long, default_value_t = DensifySettings::default().fusion_cache_mb)]
    pub fusion_cache_mb: usize,
    /// Replace an existing workspace at the output (never replaced otherwise; in a pipeline
    /// file, an existing SCENE/dense is used as it is unless this is set)
    #[arg(long)]
    pub overwrite: bool,
}

impl Default for DensifySettings {
    /// Densify's defaults: 800 px views, 8 sources, nrw-stereo's matching and fusion.
    fn default() -> Self {
        let (stereo, fusion) = (PatchMatchOptions::default(), FusionOptions::default());
        DensifySettings {
            max_image_size: DEFAULT_MAX_IMAGE_SIZE,
            max_sources: DEFAULT_MAX_SOURCES,
            iterations: stereo.iterations,
            window_radius: stereo.window_radius,
            scales: stereo.scales,
            geometric: true,
            min_num_pixels: fusion.min_num_pixels,
            min_consistent: stereo.filter_min_consistent,
            fusion_cache_mb: DEFAULT_FUSION_CACHE_MB,
            overwrite: false,
        }
    }
}

impl DensifySettings {
    /// The longer side of the undistorted views (`None`: the photos' own size).
    pub fn max_image_size(&self) -> Option<u64> {
        (self.max_image_size > 0).then_some(self.max_image_size)
    }

    /// The PatchMatch options these settings ask for (the others nrw-stereo's defaults).
    pub fn stereo(&self) -> PatchMatchOptions {
        PatchMatchOptions {
            iterations: self.iterations,
            window_radius: self.window_radius,
            sigma_spatial: self.window_radius as f64,
            scales: self.scales,
            filter_min_consistent: self.min_consistent,
            ..PatchMatchOptions::default()
        }
    }

    /// The fusion options these settings ask for (the others COLMAP's defaults).
    pub fn fusion(&self) -> FusionOptions {
        FusionOptions {
            min_num_pixels: self.min_num_pixels,
            ..FusionOptions::default()
        }
    }

    /// The most bytes of maps fusion holds at once.
    pub fn fusion_cache_bytes(&self) -> usize {
        self.fusion_cache_mb.saturating_mul(1 << 20)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::settings::tests::{declared_once, parse, table};

    #[test]
    fn every_flag_is_a_key_of_the_table_and_the_defaults_agree() {
        declared_once::<DensifySettings>();
        assert_eq!(
            parse::<DensifySettings>(&["--no-geometric", "--window-radius", "3"]),
            table("geometric = false\nwindow_radius = 3")
        );
    }
}
