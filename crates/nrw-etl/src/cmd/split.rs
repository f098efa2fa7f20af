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
    /// Take the sets from a published Phototourism split file (NeRF-W's SCENE.tsv: filename,
    /// id, split, dataset) instead of drawing them: `train` rows train, `test` rows are the
    /// val split; rows without an id are ignored, as nerf_pl does; a name that is not in the
    /// scene's model is refused. Replaces any earlier split
    #[arg(long, conflicts_with_all = ["val", "seed"])]
    pub from_tsv: Option<PathBuf>,
}

/// Run `split`.
pub fn run(args: &SplitArgs) -> Result<()> {
    let cfg = SplitConfig {
        val: args.val,
        seed: args.seed,
        from_tsv: args.from_tsv.clone(),
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
    if let Some(tsv) = &cfg.from_tsv {
        println!(
            "split {}: {} train, {} val, as {} lists them",
            cfg.dataset.display(),
            s.train,
            s.val,
            tsv.display()
        );
        if !s.listed_not_kept.is_empty() {
            eprintln!(
                "{} listed photo(s) were dropped by ingest and are in no split, e.g. {}",
                s.listed_not_kept.len(),
                s.listed_not_kept[0]
            );
        }
        if s.unlisted > 0 {
            eprintln!(
                "{} kept photo(s) are not listed and are in no split",
                s.unlisted
            );
        }
        return;
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
