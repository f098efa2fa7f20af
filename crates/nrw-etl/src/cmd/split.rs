//! `nrw-etl split`: a reproducible, incremental train/validation assignment of the kept photos.

use std::path::PathBuf;

use clap::Args;
use nrw_dataset::split::{assign, read_splits, write_splits, SPLITS_TABLE};
use nrw_dataset::Manifest;

use crate::error::{EtlError, Result};

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
    super::qa::timed(Some(args.dataset.as_path()), "split", || run_stage(args))
}

fn run_stage(args: &SplitArgs) -> Result<()> {
    let mut manifest = Manifest::read(&args.dataset)?;
    let kept: Vec<(u32, String)> = nrw_dataset::scene::read_verdicts(&args.dataset)?
        .into_iter()
        .filter(|(_, _, v)| v == nrw_dataset::scene::VERDICT_KEPT)
        .map(|(id, name, _)| (id, name))
        .collect();
    let previous = read_splits(&args.dataset)?;
    let (rows, change) = assign(&kept, &previous, args.val, args.seed)
        .map_err(|e| EtlError::Usage(format!("{}: {e}", args.dataset.display())))?;
    let entry = write_splits(&args.dataset, &rows)?;
    manifest.tables.retain(|t| t.path != SPLITS_TABLE);
    manifest.tables.push(entry);
    manifest
        .parameters
        .insert("split_val".into(), args.val.into());
    manifest.write(&args.dataset)?;
    for g in &change.gone {
        eprintln!(
            "warning: {g} was assigned earlier but is no longer kept; removed from the split"
        );
    }
    let val = rows.iter().filter(|a| a.split == "val").count();
    println!(
        "split {}: {} train, {val} val ({} kept as before, {} newly assigned with seed {})",
        args.dataset.display(),
        rows.len() - val,
        change.kept_train + change.kept_val,
        change.new_train + change.new_val,
        args.seed
    );
    Ok(())
}
