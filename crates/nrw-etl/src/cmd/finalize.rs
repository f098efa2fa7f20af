//! `nrw-etl finalize`: merge the work units that ran into a dataset.

use clap::Args;

use crate::error::Result;

/// Arguments of `finalize`.
#[derive(Debug, Args)]
#[command(
    after_help = "Exit codes: 0 merged (or nothing left to merge: finalize is idempotent);
1 a unit is missing, ran with other parameters, or its files are damaged (the message names
the unit, the parameter and the file; nothing is changed)."
)]
pub struct FinalizeArgs {
    /// Dataset folder the units wrote into (`ingest --unit I/N`, `style --unit I/N`)
    pub dataset: nrw_dataset::Location,
    /// Print a JSON summary on stdout
    #[arg(long)]
    pub json: bool,
}

/// Run `finalize`.
pub fn run(args: &FinalizeArgs) -> Result<()> {
    let s = nrw_pipeline::finalize::finalize(&nrw_dataset::Store::open(&args.dataset)?)?;
    super::print_report(&nrw_pipeline::report::finalize(&s));
    if args.json {
        println!(
            "{}",
            serde_json::to_string_pretty(&s).expect("summary serialises")
        );
    }
    Ok(())
}
