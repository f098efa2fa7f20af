//! `nrw-etl split`: arguments → `nrw_pipeline::split`, and the assignment, printed.

use std::path::PathBuf;

use clap::Args;
use nrw_pipeline::split::{SplitConfig, SplitSummary};

use crate::error::Result;

/// Arguments of `split`.
#[derive(Debug, Args)]
pub struct SplitArgs {
    /// Dataset folder written by `ingest`
    pub dataset: PathBuf,
    /// Number of validation photos (the paper: 100); 0 puts every photo in training
    #[arg(long, default_value_t = 100)]
    pub val: usize,
    /// Seed of the assignment: same seed, same split on any machine
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
}

/// Run `split`.
pub fn run(args: &SplitArgs) -> Result<()> {
    let cfg = SplitConfig {
        val: args.val,
        seed: args.seed,
        ..SplitConfig::new(&args.dataset)
    };
    print_summary(&cfg, &nrw_pipeline::split::split(&cfg)?);
    Ok(())
}

/// What split assigned, and photos that left the split.
pub fn print_summary(cfg: &SplitConfig, s: &SplitSummary) {
    for g in &s.gone {
        eprintln!(
            "warning: {g} was assigned earlier but is no longer kept; removed from the split"
        );
    }
    println!(
        "split {}: {} train, {} val ({} kept as before, {} newly assigned with seed {})",
        cfg.dataset.display(),
        s.train,
        s.val,
        s.kept,
        s.new,
        cfg.seed
    );
}
