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

/// Named settings that trade accuracy for time: how much matching work densify spends a
/// pixel. Each is a row of docs/densify.md's table (seconds a view, peak memory, F1).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum DensifyPreset {
    /// Previews: fewer sweeps and sources.
    Fast,
    /// The default: the settings docs/densify.md's accuracy figures are measured with.
    #[default]
    Default,
    /// More sweeps and sources, for a final dataset when time does not matter.
    Thorough,
}

/// The matching settings a preset stands for; an explicit flag or key overrides each.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PresetValues {
    pub max_sources: usize,
    pub iterations: usize,
    pub refine_iterations: usize,
    pub geom_iterations: usize,
    pub window_radius: usize,
    pub scales: usize,
}

impl DensifyPreset {
    /// Every preset, in the order help lists them.
    pub const ALL: [DensifyPreset; 3] = [
        DensifyPreset::Fast,
        DensifyPreset::Default,
        DensifyPreset::Thorough,
    ];

    /// The preset's name on the command line, in pipeline files and in `densify.json`.
    pub fn name(self) -> &'static str {
        match self {
            DensifyPreset::Fast => "fast",
            DensifyPreset::Default => "default",
            DensifyPreset::Thorough => "thorough",
        }
    }

    /// What the preset does, in one line (the CLI's help for each value).
    pub fn summary(self) -> &'static str {
        match self {
            DensifyPreset::Fast => FAST_SUMMARY,
            DensifyPreset::Default => DEFAULT_SUMMARY,
            DensifyPreset::Thorough => THOROUGH_SUMMARY,
        }
    }

    /// The matching settings the preset stands for.
    pub fn values(self) -> PresetValues {
        let stereo = PatchMatchOptions::default();
        let default = PresetValues {
            max_sources: DEFAULT_MAX_SOURCES,
            iterations: stereo.iterations,
            refine_iterations: stereo.refine_iterations,
            geom_iterations: stereo.geom_iterations,
            window_radius: stereo.window_radius,
            scales: stereo.scales,
        };
        match self {
            DensifyPreset::Fast => PresetValues {
                iterations: 3,
                refine_iterations: 2,
                geom_iterations: 1,
                ..default
            },
            DensifyPreset::Default => default,
            // The full size only: a coarse level's start does not pay for its sweeps once
            // the full size gets seven of its own.
            DensifyPreset::Thorough => PresetValues {
                max_sources: 12,
                iterations: 7,
                geom_iterations: 3,
                scales: 1,
                ..default
            },
        }
    }
}

const FAST_SUMMARY: &str =
    "Previews: 8 sources, 3 sweeps at half size, 2 at full size, 1 geometric (about 2/3 of the default's time)";
const DEFAULT_SUMMARY: &str = "8 sources, 5 sweeps at half size, 3 at full size, 2 geometric";
const THOROUGH_SUMMARY: &str =
    "12 sources, 7 sweeps at full size only, 3 geometric (about 1.4 times the default's time)";

impl std::str::FromStr for DensifyPreset {
    type Err = String;

    /// A preset by its name; the error lists the names.
    fn from_str(s: &str) -> std::result::Result<DensifyPreset, String> {
        DensifyPreset::ALL
            .into_iter()
            .find(|p| p.name() == s)
            .ok_or_else(|| format!("{s:?} is not a densify preset: fast, default, thorough"))
    }
}

/// How densify matches and fuses; a setting left out of `[densify]` (or off the command line)
/// is densify's default, and a matching setting left out is its preset's.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, clap::Args)]
#[serde(deny_unknown_fields, default)]
pub struct DensifySettings {
    /// Longer side of the undistorted views, in pixels; 0 keeps the photos' own size
    #[arg(long, default_value_t = DensifySettings::default().max_image_size)]
    pub max_image_size: u64,
    /// How much matching work a pixel gets: each preset is a row of docs/densify.md's table of
    /// seconds a view and F1; the flags below override its values one by one
    #[arg(long, value_parser = super::names(&DensifyPreset::ALL, DensifyPreset::name, DensifyPreset::summary), default_value = "default")]
    pub preset: DensifyPreset,
    /// Source views each view is matched with (the most overlapping, at least 1° apart)
    /// [default: the preset's; 8]
    #[arg(long)]
    pub max_sources: Option<usize>,
    /// Red-black PatchMatch sweeps at the coarsest scale, from random planes [default: the
    /// preset's; 5]
    #[arg(long)]
    pub iterations: Option<usize>,
    /// Sweeps at each finer scale, from the coarser scale's planes [default: the preset's; 3]
    #[arg(long)]
    pub refine_iterations: Option<usize>,
    /// Sweeps of the geometric-consistency pass [default: the preset's; 2]
    #[arg(long)]
    pub geom_iterations: Option<usize>,
    /// Half the matching window's side, in pixels (sampled every second pixel) [default: the
    /// preset's; 5]
    #[arg(long)]
    pub window_radius: Option<usize>,
    /// Coarse-to-fine levels (1: full size only; each level halves the image) [default: the
    /// preset's; 2]
    #[arg(long)]
    pub scales: Option<usize>,
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
    /// The most MiB of depth, normal and colour maps fusion holds at once (19 bytes a pixel of
    /// a view, read in bands of 16 rows): a band dropped is read again when a walk needs it
    /// (finalize prints the reads and the size that reads each band once). The cloud is the
    /// same whatever the size; only the time is not
    #[arg(long, default_value_t = DensifySettings::default().fusion_cache_mb)]
    pub fusion_cache_mb: usize,
    /// Replace an existing workspace at the output (never replaced otherwise; in a pipeline
    /// file, an existing SCENE/dense is used as it is unless this is set)
    #[arg(long)]
    pub overwrite: bool,
}

impl Default for DensifySettings {
    /// Densify's defaults: 800 px views, the default preset, nrw-stereo's fusion.
    fn default() -> Self {
        let (stereo, fusion) = (PatchMatchOptions::default(), FusionOptions::default());
        DensifySettings {
            max_image_size: DEFAULT_MAX_IMAGE_SIZE,
            preset: DensifyPreset::Default,
            max_sources: None,
            iterations: None,
            refine_iterations: None,
            geom_iterations: None,
            window_radius: None,
            scales: None,
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

    /// The matching settings in effect: the preset's, each overridden where set.
    pub fn matching(&self) -> PresetValues {
        let p = self.preset.values();
        PresetValues {
            max_sources: self.max_sources.unwrap_or(p.max_sources),
            iterations: self.iterations.unwrap_or(p.iterations),
            refine_iterations: self.refine_iterations.unwrap_or(p.refine_iterations),
            geom_iterations: self.geom_iterations.unwrap_or(p.geom_iterations),
            window_radius: self.window_radius.unwrap_or(p.window_radius),
            scales: self.scales.unwrap_or(p.scales),
        }
    }

    /// The PatchMatch options these settings ask for (the others nrw-stereo's defaults).
    pub fn stereo(&self) -> PatchMatchOptions {
        let m = self.matching();
        PatchMatchOptions {
            iterations: m.iterations,
            refine_iterations: m.refine_iterations,
            geom_iterations: m.geom_iterations,
            window_radius: m.window_radius,
            sigma_spatial: m.window_radius as f64,
            scales: m.scales,
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

    #[test]
    fn a_preset_gives_its_values_and_each_flag_overrides_one() {
        let fast = parse::<DensifySettings>(&["--preset", "fast"]);
        assert_eq!(fast.matching(), DensifyPreset::Fast.values());
        assert_eq!(fast.stereo().iterations, 3);
        assert_eq!(fast.stereo().geom_iterations, 1);
        assert_eq!(
            parse::<DensifySettings>(&["--preset", "thorough"])
                .stereo()
                .scales,
            1
        );
        let mixed = parse::<DensifySettings>(&["--preset", "fast", "--iterations", "4"]);
        assert_eq!(
            mixed.matching(),
            PresetValues {
                iterations: 4,
                ..DensifyPreset::Fast.values()
            }
        );
        assert_eq!(
            table::<DensifySettings>("preset = \"thorough\"\nmax_sources = 6").matching(),
            PresetValues {
                max_sources: 6,
                ..DensifyPreset::Thorough.values()
            }
        );
        // The default preset is the kernel's defaults and densify's 8 sources.
        let d = DensifySettings::default();
        assert_eq!(d.stereo(), PatchMatchOptions::default());
        assert_eq!(d.matching().max_sources, DEFAULT_MAX_SOURCES);
        // Each preset's help line states its values (written by hand: `names` takes a
        // `&'static str`), so it must say what `values` gives.
        for p in DensifyPreset::ALL {
            let (v, help) = (p.values(), p.summary());
            for part in [
                format!("{} sources", v.max_sources),
                format!("{} geometric", v.geom_iterations),
            ] {
                assert!(
                    help.contains(&part),
                    "{}: {help:?} lacks {part:?}",
                    p.name()
                );
            }
        }
        let e = "quick".parse::<DensifyPreset>().unwrap_err();
        assert!(e.contains("fast, default, thorough"), "{e}");
    }
}
