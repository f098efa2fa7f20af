//! `nrw-etl qa`: the dataset QA report, to look at before training on a dataset.

use clap::Args;

use crate::error::Result;

/// Arguments of `qa`.
#[derive(Debug, Args)]
pub struct QaArgs {
    /// Dataset folder (written by `nrw-etl ingest`; split, style and triplets are shown when present)
    pub dataset: nrw_dataset::Location,
    /// Folder for report.html and qa.json [default: DATASET/qa]
    #[arg(long)]
    pub out: Option<nrw_dataset::Location>,
}

/// Run `qa`.
pub fn run(args: &QaArgs) -> Result<()> {
    let w = nrw_pipeline::qa::qa(&nrw_pipeline::qa::QaConfig {
        dataset: args.dataset.clone(),
        out: args.out.clone(),
    })?;
    super::print_report(&nrw_pipeline::report::qa(&w));
    Ok(())
}
