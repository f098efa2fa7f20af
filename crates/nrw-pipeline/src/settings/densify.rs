//! `densify`'s settings: the flags of `nrw-etl densify` and the `[densify]` table of a
//! pipeline file, one declaration.

use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::densify::DensifyConfig;

/// How densify matches and fuses; a setting left out of `[densify]` (or off the command line)
/// is densify's default ([`DensifyConfig::new`]).
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
    fn default() -> Self {
        let c = DensifyConfig::new(Path::new(""));
        DensifySettings {
            max_image_size: c.max_image_size.unwrap_or(0),
            max_sources: c.max_sources,
            iterations: c.stereo.iterations,
            window_radius: c.stereo.window_radius,
            scales: c.stereo.scales,
            geometric: c.geometric,
            min_num_pixels: c.fusion.min_num_pixels,
            min_consistent: c.stereo.filter_min_consistent,
            fusion_cache_mb: c.fusion_cache_bytes >> 20,
            overwrite: c.overwrite,
        }
    }
}

impl DensifySettings {
    /// Densify's configuration for `scene` with these settings (the output and the photo
    /// folder are the caller's).
    pub fn config(&self, scene: &Path) -> DensifyConfig {
        let mut c = DensifyConfig::new(scene);
        c.max_image_size = (self.max_image_size > 0).then_some(self.max_image_size);
        c.max_sources = self.max_sources;
        c.stereo.iterations = self.iterations;
        c.stereo.window_radius = self.window_radius;
        c.stereo.sigma_spatial = self.window_radius as f64;
        c.stereo.scales = self.scales;
        c.geometric = self.geometric;
        c.fusion.min_num_pixels = self.min_num_pixels;
        c.stereo.filter_min_consistent = self.min_consistent;
        c.fusion_cache_bytes = self.fusion_cache_mb.saturating_mul(1 << 20);
        c.overwrite = self.overwrite;
        c
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
