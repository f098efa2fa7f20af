//! `nrw-etl split`: arguments → `nrw_pipeline::split`, and the assignment, printed.

use std::path::PathBuf;

use clap::Args;
use nrw_pipeline::split::SplitConfig;

use crate::error::Result;

/// Arguments of `split`.
#[derive(Debug, Args)]
pub struct SplitArgs {
    /// Dataset folder written by `ingest`
    pub dataset: nrw_dataset::Location,
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
    super::print_report(&nrw_pipeline::report::split(
        &cfg,
        &nrw_pipeline::split::split(&cfg)?,
    ));
    Ok(())
}
