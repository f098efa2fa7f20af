//! `nrw-etl qa`: the dataset QA report, to look at before training on a dataset.

use std::path::PathBuf;

use clap::Args;

use crate::error::{EtlError, Result};

/// Arguments of `qa`.
#[derive(Debug, Args)]
pub struct QaArgs {
    /// Dataset folder (written by `nrw-etl ingest`; split, style and triplets are shown when present)
    pub dataset: PathBuf,
    /// Folder for report.html and qa.json [default: DATASET/qa]
    #[arg(long)]
    pub out: Option<PathBuf>,
}

/// Run `qa`; returns the report's path.
pub fn run(args: &QaArgs) -> Result<PathBuf> {
    let out = args.out.clone().unwrap_or_else(|| args.dataset.join("qa"));
    let w = nrw_qa::build(&args.dataset, &out).map_err(|e| match e {
        nrw_qa::QaError::Dataset(d) => EtlError::Dataset(d),
        other => EtlError::Usage(other.to_string()),
    })?;
    let c = &w.figures.counts;
    eprintln!(
        "QA: {} registered → {} rendered → {} kept → {} train / {} val; {} warning(s)",
        c.registered,
        c.rendered,
        c.kept,
        c.train,
        c.val,
        w.figures.warnings.len()
    );
    println!("{}", w.report.display());
    Ok(w.report)
}

/// Run a stage and, when it succeeds on a dataset, record its duration in the dataset's
/// timings.json (shown by the report); failing to record is only worth a warning.
pub fn timed<T>(
    dataset: Option<&std::path::Path>,
    stage: &str,
    run: impl FnOnce() -> Result<T>,
) -> Result<T> {
    let started = std::time::Instant::now();
    let r = run();
    if let (Ok(_), Some(dir)) = (&r, dataset) {
        if let Err(e) = nrw_qa::record_timing(dir, stage, started.elapsed().as_secs_f64()) {
            eprintln!("warning: could not record {stage}'s time: {e}");
        }
    }
    r
}
