//! `ingest`'s settings: the flags of `nrw-etl ingest` and the `[ingest]` table of a pipeline
//! file, one declaration. Where the scene, photos, cloud and SegFormer are is given on the
//! command line (places, not settings); in a pipeline file `semantics` is relative to the
//! scene folder.

use std::path::PathBuf;

use nrw_render::Filters;
use nrw_segment::ModeKind;
use serde::{Deserialize, Serialize};

/// How views are rendered and filtered; a setting left out is the paper's.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, clap::Args)]
#[serde(deny_unknown_fields, default)]
pub struct IngestSettings {
    /// Render so the shorter side has this many pixels (the paper: 600)
    #[arg(long, default_value_t = IngestSettings::default().min_dim)]
    pub min_dim: u32,
    /// Splat radius in render pixels: a point covers the pixels whose centres lie within it
    /// (0: its own pixel)
    #[arg(long, default_value_t = IngestSettings::default().radius)]
    pub radius: f32,
    /// Drop views whose render has more than this fraction of empty pixels (the paper: 0.85)
    #[arg(long, default_value_t = IngestSettings::default().max_empty)]
    pub max_empty: f64,
    /// Drop photos whose shorter side is under this many pixels (the paper: 450)
    #[arg(long, default_value_t = IngestSettings::default().min_photo_side)]
    pub min_photo_side: u32,
    /// Drop photos less sharp than this: the variance of the Laplacian of the full-size
    /// photo's grey levels, as instant-ngp's colmap2nerf records it (higher is sharper; it
    /// grows with resolution). Every kept photo's value is in scene/images.parquet's
    /// `sharpness` and QA's sharpness plot [default: keep every photo]
    #[arg(long, value_name = "VAR")]
    pub min_sharpness: Option<f64>,
    /// Images per shard (one shard per group of this many images, in id order; the unit of
    /// resumption and of --unit work units)
    #[arg(long, default_value_t = IngestSettings::default().rows_per_shard)]
    pub rows_per_shard: usize,
    /// Stop with an error (exit 1, naming the file) at the first photo or label map that
    /// cannot be decoded whole, instead of dropping its view as `unreadable` and going on
    #[arg(long)]
    pub strict: bool,
    /// Folder of per-photo ADE20K label maps (8-bit PNG of class ids, the photo's size, named
    /// like the photo with .png); stored colour-coded with a transient mask, and with
    /// --undistort resampled with the photo (nearest class, never a blend)
    #[arg(long)]
    pub semantics: Option<PathBuf>,
    /// With --segment-weights: how a photo is fed to the network
    #[arg(long, value_parser = super::names(&ModeKind::ALL, ModeKind::name, ModeKind::summary), default_value = "resize")]
    pub segment_mode: ModeKind,
    /// With --segment-weights: network input size in pixels
    #[arg(long, default_value_t = IngestSettings::default().segment_size)]
    pub segment_size: u32,
    /// Store every view undistorted, as COLMAP's image_undistorter does: the PINHOLE camera
    /// it computes (no blank pixels, scale clipped to 0.2–2) and the photo resampled to it
    /// through the exact camera model, so photo and render align pixel for pixel with a
    /// pinhole camera (what NeRF-W, nerfstudio and Gaussian-splatting loaders expect)
    #[arg(long)]
    pub undistort: bool,
    /// With --undistort: 0 keeps only pixels that see the photo (COLMAP's default), 1 keeps
    /// every photo pixel (black corners), values between interpolate
    #[arg(long, default_value_t = 0.0, requires = "undistort")]
    pub blank_pixels: f64,
    /// With --undistort: longest side of the undistorted camera, as COLMAP's
    /// --max_image_size [default: no limit]
    #[arg(long, requires = "undistort")]
    pub undistort_max_size: Option<u64>,
    /// Remove floating points before rendering (off by default: the paper renders the raw
    /// cloud): "K,SIGMA" drops a point when its mean distance to its K nearest neighbours
    /// exceeds the cloud's mean by SIGMA standard deviations (Open3D's
    /// remove_statistical_outlier; e.g. 16,2). The count removed goes into the manifest
    #[arg(long, value_name = "K,SIGMA")]
    pub denoise: Option<Denoise>,
    /// Estimate normals for a cloud without them (the sparse points, most PLYs from other
    /// tools) by PCA of each point's K nearest neighbours, oriented toward the cameras that
    /// see it; gives the deep buffer its normal channel (e.g. 16)
    #[arg(long, value_name = "K")]
    pub estimate_normals: Option<usize>,
}

impl Default for IngestSettings {
    /// The paper's settings: 600 px renders of 1 px splats, its filters (nrw-render's
    /// [`Filters`]), 64 images a shard.
    fn default() -> Self {
        let paper = Filters::default();
        IngestSettings {
            min_dim: 600,
            radius: 1.0,
            max_empty: paper.max_empty_ratio,
            min_photo_side: paper.min_photo_side,
            min_sharpness: None,
            rows_per_shard: 64,
            strict: false,
            semantics: None,
            segment_mode: ModeKind::Resize,
            segment_size: 512,
            undistort: false,
            blank_pixels: 0.0,
            undistort_max_size: None,
            denoise: None,
            estimate_normals: None,
        }
    }
}

/// Statistical outlier removal, `K,SIGMA` on the command line and in a pipeline file:
/// k ≥ 2 neighbours (the point itself counts), σ > 0.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "String", into = "String")]
pub struct Denoise {
    pub k: usize,
    pub sigma: f64,
}

impl std::str::FromStr for Denoise {
    type Err = String;

    fn from_str(s: &str) -> std::result::Result<Denoise, String> {
        let (k, sigma) = s
            .split_once(',')
            .ok_or_else(|| format!("`{s}`: give K,SIGMA, e.g. 16,2"))?;
        let k: usize = k
            .trim()
            .parse()
            .map_err(|_| format!("`{k}` is not a whole number of neighbours"))?;
        let sigma: f64 = sigma
            .trim()
            .parse()
            .map_err(|_| format!("`{sigma}` is not a number of standard deviations"))?;
        if k < 2 || !(sigma.is_finite() && sigma > 0.0) {
            return Err(format!(
                "K = {k}, SIGMA = {sigma}: K must be at least 2 (the point itself is one) and SIGMA positive"
            ));
        }
        Ok(Denoise { k, sigma })
    }
}

impl TryFrom<String> for Denoise {
    type Error = String;

    fn try_from(s: String) -> std::result::Result<Denoise, String> {
        s.parse()
    }
}

impl From<Denoise> for String {
    fn from(d: Denoise) -> String {
        format!("{},{}", d.k, d.sigma)
    }
}

impl IngestSettings {
    /// The paper's filters with these thresholds.
    pub fn filters(&self) -> Filters {
        Filters {
            max_empty_ratio: self.max_empty,
            min_photo_side: self.min_photo_side,
        }
    }

    /// COLMAP's undistorter options, with `--undistort`.
    pub fn undistort_options(&self) -> Option<nrw_colmap::UndistortOptions> {
        self.undistort.then_some(nrw_colmap::UndistortOptions {
            blank_pixels: self.blank_pixels,
            max_image_size: self.undistort_max_size,
            ..Default::default()
        })
    }

    /// The settings the run's record does not hold in a field of its own
    /// ([`nrw_dataset::provenance::IngestParameters`]) and that differ from the paper's, each
    /// under its own key: a setting added here is recorded (and tells units apart) without
    /// another file changing, and a run that leaves it at its default keeps its bytes.
    pub fn unrecorded(&self) -> nrw_dataset::provenance::Parameters {
        use nrw_dataset::provenance::to_parameters;
        without_recorded(to_parameters(self), &to_parameters(&Self::default()))
    }
}

/// `settings` without the keys [`RECORDED_ELSEWHERE`] names and those at their `defaults`.
fn without_recorded(
    mut settings: nrw_dataset::provenance::Parameters,
    defaults: &nrw_dataset::provenance::Parameters,
) -> nrw_dataset::provenance::Parameters {
    settings.retain(|key, value| {
        !RECORDED_ELSEWHERE.contains(&key.as_str()) && defaults.get(key) != Some(value)
    });
    settings
}

/// Settings the record holds otherwise: in a field of
/// [`nrw_dataset::provenance::IngestParameters`] (some with what the run found), or not at
/// all because they never change a byte of the dataset (`strict` only turns a drop into an
/// error).
const RECORDED_ELSEWHERE: &[&str] = &[
    "min_dim",
    "radius",
    "max_empty",
    "min_photo_side",
    "min_sharpness",
    "rows_per_shard",
    "strict",
    "semantics",
    "segment_mode",
    "segment_size",
    "undistort",
    "blank_pixels",
    "undistort_max_size",
    "denoise",
    "estimate_normals",
];

#[cfg(test)]
mod tests {
    use super::*;
    use crate::settings::tests::{declared_once, parse, table};

    #[test]
    fn every_flag_is_a_key_of_the_table_and_the_defaults_agree() {
        declared_once::<IngestSettings>();
        let cli: IngestSettings = parse(&[
            "--min-dim",
            "96",
            "--denoise",
            "16,2",
            "--segment-mode",
            "slide",
            "--undistort",
            "--undistort-max-size",
            "640",
            "--min-sharpness",
            "40.5",
        ]);
        assert_eq!(
            cli,
            table("min_dim = 96\ndenoise = \"16,2\"\nsegment_mode = \"slide\"\nundistort = true\nundistort_max_size = 640\nmin_sharpness = 40.5")
        );
        let e = toml::from_str::<IngestSettings>("denoise = \"1,2\"").unwrap_err();
        assert!(e.to_string().contains("K must be at least 2"), "{e}");
    }

    #[test]
    fn a_setting_without_a_field_of_the_record_is_recorded_under_its_own_key() {
        let settings = IngestSettings {
            strict: true,
            min_dim: 96,
            ..Default::default()
        };
        let mut all = nrw_dataset::provenance::to_parameters(&settings);
        // Every name the list gives is a setting (a renamed one would be recorded twice).
        for key in RECORDED_ELSEWHERE {
            assert!(all.contains_key(*key), "{key} is not a setting");
        }
        // A setting the list does not name (one added later) goes in with its value, unless
        // it is at its default.
        let mut defaults = nrw_dataset::provenance::to_parameters(&IngestSettings::default());
        all.insert("new_setting".into(), 7.into());
        defaults.insert("new_setting".into(), 0.into());
        let kept = without_recorded(all.clone(), &defaults);
        assert_eq!(kept.keys().collect::<Vec<_>>(), ["new_setting"]);
        assert_eq!(kept["new_setting"], 7);
        defaults.insert("new_setting".into(), 7.into());
        assert!(without_recorded(all, &defaults).is_empty());
    }
}
