//! `nrw-etl finalize`: merge the work units that ran into a dataset.

use std::path::PathBuf;

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
    /// Dataset folder the units wrote into (`ingest --shard I/N`, `style --shard I/N`)
    pub dataset: PathBuf,
    /// Print a JSON summary on stdout
    #[arg(long)]
    pub json: bool,
}

/// Run `finalize`.
pub fn run(args: &FinalizeArgs) -> Result<()> {
    let s = nrw_pipeline::finalize::finalize(&nrw_dataset::Store::open_path(&args.dataset)?)?;
    if let Some(i) = &s.ingest {
        for w in &i.warnings {
            eprintln!("warning: {w}");
        }
        eprintln!(
            "finalized ingest of {} from {} units: {} registered, {} kept, {} too sparse, {} too small, {} unreadable; {} shards",
            s.dataset, i.units, i.registered, i.kept, i.too_sparse, i.too_small, i.unreadable, i.shards
        );
    }
    if let Some(st) = &s.style {
        eprintln!(
            "finalized style of {} from {} units: {} parts of {}",
            s.dataset, st.units, st.parts, st.tier
        );
    }
    if s.ingest.is_none() && s.style.is_none() {
        eprintln!(
            "{}: nothing to finalize (no unit records; the dataset is final)",
            s.dataset
        );
    }
    if args.json {
        println!(
            "{}",
            serde_json::to_string_pretty(&s).expect("summary serialises")
        );
    }
    Ok(())
}
