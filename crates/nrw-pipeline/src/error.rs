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
    /// A pipeline key changed on the command line (`TABLE.KEY=VALUE`) that the table refuses.
    #[error("`{set}`: {problem}")]
    Override { set: String, problem: String },
    /// What a pipeline run found wrong before its first stage, every problem at once.
    #[error("the pipeline cannot run as set (nothing was started):\n  - {}", problems.join("\n  - "))]
    Preflight { problems: Vec<String> },
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
/// key (`stage.field`, as pipeline files spell it) in backticks, wherever in a message it
/// stands; the CLI shows its flag instead, so no library message spells a flag. A field of a
/// stage's settings struct is a [`Setting::Key`], its flag read from the struct; the variants
/// name what no settings struct holds (places, work units, tables), and [`Setting::ALL`] is
/// their closed set.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Setting {
    SegmentWeights,
    Weights,
    Unit,
    /// How many units a `Unit::parse("auto")` run has, where the scheduler does not say.
    UnitCount,
    /// The photos a segment run reads: a scene's model, or a folder of images.
    Photos,
    /// A pipeline file's `[split]` table.
    Split,
    /// The photo folder, where it is not the model's `images/`.
    Images,
    /// A point cloud given instead of the scene's `dense/fused.ply`.
    Points,
    /// Whether a stage may replace what an earlier run of other settings wrote.
    Overwrite,
    /// The corpus index's list of scenes and their outcomes.
    Entries,
    /// Whether photo names may resolve through links out of the photo folder.
    FollowOutsideLinks,
    /// Where densify writes its dense workspace.
    DenseOut,
    /// The PatchMatch kernel's settings (iterations, window, scales).
    Stereo,
    /// A field of a stage's settings struct ([`crate::settings`]), named by its key
    /// (`stage.field`): its flag is the one the struct declares, so a setting needs no
    /// variant of its own.
    Key(&'static str),
}

impl Setting {
    /// Every named variant: the set the CLI maps from keys to flags besides the settings
    /// structs' fields.
    pub const ALL: [Setting; 13] = [
        Setting::SegmentWeights,
        Setting::Weights,
        Setting::Unit,
        Setting::UnitCount,
        Setting::Photos,
        Setting::Split,
        Setting::Images,
        Setting::Points,
        Setting::Overwrite,
        Setting::Entries,
        Setting::FollowOutsideLinks,
        Setting::DenseOut,
        Setting::Stereo,
    ];

    /// The setting's key: `stage.field` as a pipeline file or a library caller names it.
    pub fn key(self) -> &'static str {
        match self {
            Setting::SegmentWeights => "ingest.segment_weights",
            Setting::Weights => "style.weights",
            Setting::Unit => "unit",
            Setting::UnitCount => "unit_count",
            Setting::Photos => "segment.scene",
            Setting::Split => "split",
            Setting::Images => "ingest.images",
            Setting::Points => "ingest.points",
            Setting::Overwrite => "overwrite",
            Setting::Entries => "corpus.entries",
            Setting::FollowOutsideLinks => "follow_outside_links",
            Setting::DenseOut => "densify.out",
            Setting::Stereo => "densify.stereo",
            Setting::Key(key) => key,
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
            .filter(|l| !l.starts_with("Key("))
            .collect();
        let listed: Vec<String> = Setting::ALL.iter().map(|s| format!("{s:?}")).collect();
        assert_eq!(declared, listed);
    }
}
