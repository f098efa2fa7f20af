//! `nrw-etl inspect`: what a COLMAP model holds and how well it agrees with itself, or what a
//! dataset holds (`nrw_pipeline::inspect`), printed.

use clap::Args;
use nrw_pipeline::inspect::Inspected;

use crate::error::Result;
use nrw_colmap::Format;

/// Arguments of `inspect`.
#[derive(Debug, Args)]
pub struct InspectArgs {
    /// Scene folder holding sparse/0/ (or sparse/), a model folder itself, or a dataset folder
    pub scene: nrw_dataset::Location,
    /// Print one JSON object instead of a readable summary
    #[arg(long)]
    pub json: bool,
    /// Read this encoding even if the other exists [default: bin when present, else txt]
    #[arg(long, value_parser = super::names(&Format::ALL, Format::name, Format::summary))]
    pub format: Option<Format>,
    /// Summarise the sub-model sparse/N [default: the one with the most registered images;
    /// a scene with several lists them all]
    #[arg(long, value_name = "N")]
    pub model: Option<u32>,
}

/// Run `inspect`.
pub fn run(args: &InspectArgs) -> Result<()> {
    let found = nrw_pipeline::inspect::inspect(&args.scene, args.format, args.model)?;
    if args.json {
        // Through a JSON value, so keys print sorted as they always have.
        let v = match &found {
            Inspected::Model(m) => serde_json::to_value(m),
            Inspected::Dataset(d) => serde_json::to_value(d),
        }
        .expect("JSON of plain values");
        println!(
            "{}",
            serde_json::to_string_pretty(&v).expect("JSON of plain values")
        );
        return Ok(());
    }
    super::print_report(&nrw_pipeline::report::inspected(&found));
    Ok(())
}
