//! `nrw-etl triplets`: arguments → `nrw_pipeline::triplets`, and the table's summary, printed.

use clap::Args;
use nrw_pipeline::triplets::TripletsConfig;

use crate::error::Result;

/// Arguments of `triplets`.
#[derive(Debug, Args)]
pub struct TripletsArgs {
    /// Dataset folder with descriptors (run `nrw-etl style` first)
    pub dataset: nrw_dataset::Location,
    /// Neighbours per anchor, nearest and furthest (the paper: 20)
    #[arg(long, default_value_t = 20)]
    pub k: usize,
    /// Draw anchors and neighbours from every split (default: the training split only, so
    /// validation photos never appear)
    #[arg(long)]
    pub all_splits: bool,
    /// Approximate: candidates from a PCA projection to this many dimensions, re-ranked
    /// exactly (for large N; recall against the exact path is measured and stored when N ≤ --check-up-to)
    #[arg(long)]
    pub pca: Option<usize>,
    /// Measure the approximate path's recall against the exact one up to this many photos
    #[arg(long, default_value_t = 20_000)]
    pub check_up_to: usize,
}

/// Run `triplets`.
pub fn run(args: &TripletsArgs) -> Result<()> {
    let cfg = TripletsConfig {
        k: args.k,
        all_splits: args.all_splits,
        pca: args.pca,
        check_up_to: args.check_up_to,
        ..TripletsConfig::new(&args.dataset)
    };
    super::print_report(&nrw_pipeline::report::triplets(
        &args.dataset,
        &nrw_pipeline::triplets::triplets(&cfg)?,
    ));
    Ok(())
}
