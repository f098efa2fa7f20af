//! `nrw-etl qa`: the dataset QA report, to look at before training on a dataset.

use std::path::PathBuf;

use clap::Args;

use crate::error::Result;

/// Arguments of `qa`.
#[derive(Debug, Args)]
pub struct QaArgs {
    /// Dataset folder (written by `nrw-etl ingest`; split, style and triplets are shown when present)
    pub dataset: PathBuf,
    /// Folder for report.html and qa.json [default: DATASET/qa]
    #[arg(long)]
    pub out: Option<PathBuf>,
}

/// Run `qa`.
pub fn run(args: &QaArgs) -> Result<()> {
    let w = nrw_pipeline::qa::qa(&nrw_pipeline::qa::QaConfig {
        dataset: args.dataset.clone(),
        out: args.out.clone(),
    })?;
    print_summary(&w);
    Ok(())
}

/// The report's counts, and where it is.
pub fn print_summary(w: &nrw_qa::Written) {
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
}
