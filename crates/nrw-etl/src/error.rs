//! The CLI's error: a stage's typed error, or a problem with the command line itself.

/// Everything a command can fail with; each message names the file (and record) involved.
#[derive(Debug, thiserror::Error)]
pub enum EtlError {
    #[error(transparent)]
    Pipeline(nrw_pipeline::PipelineError),
    #[error(transparent)]
    Colmap(#[from] nrw_colmap::ColmapError),
    #[error(transparent)]
    Dataset(#[from] nrw_dataset::DatasetError),
    /// A flag's value the library refused, named by the flag.
    #[error("{flag} {problem}")]
    Flag { flag: &'static str, problem: String },
}

/// A stage's error; a setting it names is shown as the flag that sets it.
impl From<nrw_pipeline::PipelineError> for EtlError {
    fn from(e: nrw_pipeline::PipelineError) -> Self {
        match e {
            nrw_pipeline::PipelineError::Config { setting, problem } => EtlError::Flag {
                flag: flag(setting),
                problem,
            },
            e => EtlError::Pipeline(e),
        }
    }
}

/// The command-line flag (or argument) of a stage setting.
pub fn flag(s: nrw_pipeline::Setting) -> &'static str {
    use nrw_pipeline::Setting as S;
    match s {
        S::RowsPerShard => "--rows-per-shard",
        S::Radius => "--radius",
        S::MaxEmpty => "--max-empty",
        S::EstimateNormals => "--estimate-normals",
        S::Undistort => "--undistort",
        S::SegmentWeights => "--segment-weights",
        S::SegmentMode => "--segment-mode",
        S::PhotosPerPart => "--photos-per-part",
        S::Tier => "--tier",
        S::Weights => "--weights",
        S::K => "--k",
        S::Unit => "--unit",
        S::UnitCount => "--unit-count",
        S::Photos => "SCENE",
        // Only a pipeline file has a [split] table.
        S::Split => "[split]",
    }
}

impl EtlError {
    /// Whether the stage stopped on request (exit code 130: run again to resume).
    pub fn interrupted(&self) -> bool {
        matches!(
            self,
            EtlError::Pipeline(nrw_pipeline::PipelineError::Interrupted(_))
        )
    }
}

/// Result alias for the CLI.
pub type Result<T, E = EtlError> = std::result::Result<T, E>;
