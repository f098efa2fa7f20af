//! The CLI's error: a stage's typed error, or a problem with the command line itself.

/// Everything a command can fail with; each message names the file (and record) involved.
#[derive(Debug, thiserror::Error)]
pub enum EtlError {
    #[error(transparent)]
    Pipeline(#[from] nrw_pipeline::PipelineError),
    #[error(transparent)]
    Colmap(#[from] nrw_colmap::ColmapError),
    #[error(transparent)]
    Dataset(#[from] nrw_dataset::DatasetError),
    /// A flag's value the library refused, named by the flag.
    #[error("{flag} {problem}")]
    Flag { flag: &'static str, problem: String },
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
