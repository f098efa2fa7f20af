//! `nrw-etl split`: arguments → `nrw_pipeline::split`, and the assignment, printed.

use clap::Args;

use crate::error::Result;

/// Arguments of `split`.
#[derive(Debug, Args)]
pub struct SplitArgs {
    /// Dataset folder written by `ingest`
    pub dataset: nrw_dataset::Location,
    #[command(flatten)]
    pub settings: nrw_pipeline::settings::split::SplitSettings,
}

/// Run `split`.
pub fn run(args: &SplitArgs) -> Result<()> {
    let cfg = args.settings.config(&args.dataset)?;
    super::print_report(&nrw_pipeline::report::split(
        &cfg,
        &nrw_pipeline::split::split(&cfg)?,
    ));
    Ok(())
}
