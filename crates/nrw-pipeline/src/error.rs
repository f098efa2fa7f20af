//! The stages' error: a lower crate's typed error, or a named problem with a configuration
//! value, an input file or the work units of a dataset.

use std::path::PathBuf;

/// Everything a stage can fail with; each message names the file, setting or unit involved.
#[derive(Debug, thiserror::Error)]
pub enum PipelineError {
    #[error(transparent)]
    Colmap(#[from] nrw_colmap::ColmapError),
    #[error(transparent)]
    Dataset(#[from] nrw_dataset::DatasetError),
    /// An export that could not be written (the export crate names the file or folder).
    #[error(transparent)]
    Export(#[from] nrw_export::ExportError),
    #[error(transparent)]
    Synth(#[from] nrw_synth::SynthError),
    #[error(transparent)]
    Qa(#[from] nrw_qa::QaError),
    /// A segmentation model or photo the segment stage could not use.
    #[error(transparent)]
    Segment(#[from] nrw_segment::SegmentError),
    /// Weights or an image the style stage could not use.
    #[error(transparent)]
    StyleInput(#[from] nrw_style::StyleError),
    /// A setting outside what the stage accepts, named by its key (the binary shows its flag).
    #[error("{setting} {problem}")]
    Config { setting: Setting, problem: String },
    /// A camera COLMAP's undistorter cannot undistort (named by the model folder).
    #[error("{}: {source}", path.display())]
    Undistort {
        path: PathBuf,
        #[source]
        source: nrw_colmap::UndistortError,
    },
    /// A file or folder that could not be read or written.
    #[error("{}: {source}", path.display())]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// A pipeline file that is not the TOML the runner reads.
    #[error("{}: {source}", path.display())]
    PipelineFile {
        path: PathBuf,
        #[source]
        source: toml::de::Error,
    },
    /// An input file or folder that cannot serve (missing, inconsistent with the model, …).
    #[error("{path}: {problem}")]
    Input {
        path: nrw_dataset::Location,
        problem: String,
    },
    /// A stage needs an earlier stage's output, or a non-empty dataset.
    #[error("{dataset}: {problem}")]
    NotReady {
        dataset: nrw_dataset::Location,
        problem: String,
    },
    /// Work units that cannot be merged (missing, or run with other parameters).
    #[error("{dataset}: {problem}")]
    Units {
        dataset: nrw_dataset::Location,
        problem: String,
    },
    /// Style descriptors could not be computed for a photo.
    #[error("photo {name} (image {image_id}): {source}")]
    Style {
        name: String,
        image_id: u32,
        #[source]
        source: nrw_style::StyleError,
    },
    /// The style backend failed on a batch of photos (named by its first and last photo).
    #[error("descriptor part {part}, photos {first} … {last}: {source}")]
    StyleBatch {
        part: usize,
        first: String,
        last: String,
        #[source]
        source: nrw_style::StyleError,
    },
    /// The weights file cannot serve the requested tier.
    #[error("{}: {problem}", path.display())]
    Weights { path: PathBuf, problem: String },
    /// Stopped on request before the end; running the same stage again resumes.
    #[error("interrupted: {0}")]
    Interrupted(String),
}

/// A setting of a stage's configuration that a message can name. The library names it by its
/// key (the stage's config field, as pipeline files spell it) in backticks, wherever in a
/// message it stands; the CLI shows its flag instead ([`Setting::ALL`] is the closed set it
/// looks for), so no library message spells a flag.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Setting {
    RowsPerShard,
    Radius,
    MaxEmpty,
    /// `--min-sharpness`: the blur filter.
    MinSharpness,
    EstimateNormals,
    Undistort,
    SegmentWeights,
    SegmentMode,
    /// The SegFormer's input size in pixels.
    SegmentSize,
    PhotosPerPart,
    Tier,
    Weights,
    K,
    Unit,
    /// How many units a `Unit::parse("auto")` run has, where the scheduler does not say.
    UnitCount,
    /// The photos a segment run reads: a scene's model, or a folder of images.
    Photos,
    /// A pipeline file's `[split]` table.
    Split,
    /// The photo folder, where it is not the model's `images/`.
    Images,
    /// A folder of label maps given instead of a segmentation model.
    Semantics,
    /// A point cloud given instead of the scene's `dense/fused.ply`.
    Points,
    /// Whether a stage may replace what an earlier run of other settings wrote.
    Overwrite,
    /// How many photos the split holds out for validation.
    Val,
    /// The share of the kept photos the split holds out for validation.
    ValFraction,
    /// The square an export crops views to.
    Crop,
    /// How many TFRecord files an export writes per split.
    TfrecordFiles,
    /// Metres a model unit (IMC 2022's scaling factor).
    MetresPerUnit,
    Licences,
    /// Whether an export writes the views' semantic labels.
    ExportSemantics,
    /// The corpus index's list of scenes and their outcomes.
    Entries,
    /// Whether photo names may resolve through links out of the photo folder.
    FollowOutsideLinks,
    /// Where densify writes its dense workspace.
    DenseOut,
    /// Source views stereo matches each view with.
    MaxSources,
    /// The longer side densify's undistorted views are capped at.
    MaxImageSize,
    /// The PatchMatch kernel's settings (iterations, window, scales).
    Stereo,
    /// The fewest pixels fusion merges into a point.
    MinNumPixels,
}

impl Setting {
    /// Every setting: the set the CLI maps from keys to flags.
    pub const ALL: [Setting; 35] = [
        Setting::RowsPerShard,
        Setting::Radius,
        Setting::MaxEmpty,
        Setting::MinSharpness,
        Setting::EstimateNormals,
        Setting::Undistort,
        Setting::SegmentWeights,
        Setting::SegmentMode,
        Setting::SegmentSize,
        Setting::PhotosPerPart,
        Setting::Tier,
        Setting::Weights,
        Setting::K,
        Setting::Unit,
        Setting::UnitCount,
        Setting::Photos,
        Setting::Split,
        Setting::Images,
        Setting::Semantics,
        Setting::Points,
        Setting::Overwrite,
        Setting::Val,
        Setting::ValFraction,
        Setting::Crop,
        Setting::TfrecordFiles,
        Setting::MetresPerUnit,
        Setting::Licences,
        Setting::ExportSemantics,
        Setting::Entries,
        Setting::FollowOutsideLinks,
        Setting::DenseOut,
        Setting::MaxSources,
        Setting::MaxImageSize,
        Setting::Stereo,
        Setting::MinNumPixels,
    ];

    /// The setting's key: `stage.field` as a pipeline file or a library caller names it.
    pub fn key(self) -> &'static str {
        match self {
            Setting::RowsPerShard => "ingest.rows_per_shard",
            Setting::Radius => "ingest.radius",
            Setting::MaxEmpty => "ingest.max_empty",
            Setting::MinSharpness => "ingest.min_sharpness",
            Setting::EstimateNormals => "ingest.estimate_normals",
            Setting::Undistort => "ingest.undistort",
            Setting::SegmentWeights => "ingest.segment_weights",
            Setting::SegmentMode => "ingest.segment_mode",
            Setting::SegmentSize => "ingest.segment_size",
            Setting::PhotosPerPart => "style.photos_per_part",
            Setting::Tier => "style.tier",
            Setting::Weights => "style.weights",
            Setting::K => "triplets.k",
            Setting::Unit => "unit",
            Setting::UnitCount => "unit_count",
            Setting::Photos => "segment.scene",
            Setting::Split => "split",
            Setting::Images => "ingest.images",
            Setting::Semantics => "ingest.semantics",
            Setting::Points => "ingest.points",
            Setting::Overwrite => "overwrite",
            Setting::Val => "split.val",
            Setting::ValFraction => "split.val_fraction",
            Setting::Crop => "export.crop",
            Setting::TfrecordFiles => "export.tfrecord_files",
            Setting::MetresPerUnit => "export.metres_per_unit",
            Setting::Licences => "export.licences",
            Setting::ExportSemantics => "export.semantics",
            Setting::Entries => "corpus.entries",
            Setting::FollowOutsideLinks => "follow_outside_links",
            Setting::DenseOut => "densify.out",
            Setting::MaxSources => "densify.max_sources",
            Setting::MaxImageSize => "densify.max_image_size",
            Setting::Stereo => "densify.stereo",
            Setting::MinNumPixels => "densify.min_num_pixels",
        }
    }
}

/// The key in backticks, as messages mention a setting (the CLI swaps in the flag).
impl std::fmt::Display for Setting {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "`{}`", self.key())
    }
}

/// Result alias for the stages.
pub type Result<T, E = PipelineError> = std::result::Result<T, E>;

impl PipelineError {
    /// A configuration value out of range.
    pub fn config(setting: Setting, problem: impl Into<String>) -> Self {
        PipelineError::Config {
            setting,
            problem: problem.into(),
        }
    }

    /// An I/O error with its file.
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        PipelineError::Io {
            path: path.into(),
            source,
        }
    }

    /// A problem with an input file or folder.
    pub fn input(path: impl Into<nrw_dataset::Location>, problem: impl Into<String>) -> Self {
        PipelineError::Input {
            path: path.into(),
            problem: problem.into(),
        }
    }

    /// A dataset that lacks what the stage needs.
    pub fn dataset(dataset: impl Into<nrw_dataset::Location>, problem: impl Into<String>) -> Self {
        PipelineError::NotReady {
            dataset: dataset.into(),
            problem: problem.into(),
        }
    }
}

impl Setting {
    /// The command-line flag (or argument) of the setting: what the CLI names where a
    /// pipeline file names its key.
    pub fn flag(self) -> &'static str {
        use Setting as S;
        match self {
            S::RowsPerShard => "--rows-per-shard",
            S::Radius => "--radius",
            S::MaxEmpty => "--max-empty",
            S::MinSharpness => "--min-sharpness",
            S::EstimateNormals => "--estimate-normals",
            S::Undistort => "--undistort",
            S::SegmentWeights => "--segment-weights",
            S::SegmentMode => "--segment-mode",
            S::SegmentSize => "--segment-size",
            S::PhotosPerPart => "--photos-per-part",
            S::Tier => "--tier",
            S::Weights => "--weights",
            S::K => "--k",
            S::Unit => "--unit",
            S::UnitCount => "--unit-count",
            S::Photos => "SCENE",
            // Only a pipeline file has a [split] table.
            S::Split => "[split]",
            S::Images => "--images",
            S::Semantics => "--semantics",
            S::Points => "--points",
            S::Overwrite => "--overwrite",
            S::Val => "--val",
            S::ValFraction => "--val-fraction",
            S::Crop => "--crop",
            S::TfrecordFiles => "--tfrecord-files",
            S::MetresPerUnit => "--metres-per-unit",
            S::Licences => "--licences",
            // The flag turns the setting off.
            S::ExportSemantics => "--no-semantics",
            S::Entries => "--entries",
            S::FollowOutsideLinks => "--follow-outside-links",
            S::DenseOut => "--out",
            S::MaxSources => "--max-sources",
            S::MaxImageSize => "--max-image-size",
            S::Stereo => "--iterations/--window-radius/--scales",
            S::MinNumPixels => "--min-num-pixels",
        }
    }
}

/// A library message as the CLI shows it: every setting it mentions (its key in backticks,
/// as [`Setting`] displays) shown as the flag that sets it.
pub fn flags(text: &str) -> String {
    if !text.contains('`') {
        return text.to_string();
    }
    Setting::ALL
        .iter()
        .fold(text.to_string(), |t, s| t.replace(&s.to_string(), s.flag()))
}

#[cfg(test)]
mod tests {
    use super::Setting;

    /// `Setting::ALL` is written by hand: a variant left out of it would never show as its
    /// flag, so the declared variants (read from this file) must be exactly the list.
    #[test]
    fn every_declared_setting_is_in_the_list_the_cli_maps() {
        let body = include_str!("error.rs")
            .split("pub enum Setting {")
            .nth(1)
            .and_then(|rest| rest.split("\n}").next())
            .expect("the Setting enum in error.rs");
        let declared: Vec<&str> = body
            .lines()
            .map(str::trim)
            .filter(|l| !l.is_empty() && !l.starts_with("//"))
            .map(|l| l.trim_end_matches(','))
            .collect();
        let listed: Vec<String> = Setting::ALL.iter().map(|s| format!("{s:?}")).collect();
        assert_eq!(declared, listed);
    }
}
