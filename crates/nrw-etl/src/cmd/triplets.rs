//! `nrw-etl triplets`: arguments → `nrw_pipeline::triplets`, and the table's summary, printed.

use clap::Args;

use crate::error::Result;

/// Arguments of `triplets`.
#[derive(Debug, Args)]
pub struct TripletsArgs {
    /// Dataset folder with descriptors (run `nrw-etl style` first)
    pub dataset: nrw_dataset::Location,
    #[command(flatten)]
    pub settings: nrw_pipeline::settings::triplets::TripletsSettings,
}

/// Run `triplets`.
pub fn run(args: &TripletsArgs) -> Result<()> {
    let cfg = args.settings.config(&args.dataset);
    super::print_report(&nrw_pipeline::report::triplets(
        &args.dataset,
        &nrw_pipeline::triplets::triplets(&cfg)?,
    ));
    Ok(())
}
