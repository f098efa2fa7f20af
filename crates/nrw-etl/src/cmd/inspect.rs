//! `nrw-etl inspect`: what a COLMAP model holds and how well it agrees with itself.

use std::path::PathBuf;

use clap::Args;
use serde_json::json;

use nrw_pipeline::ingest::{describe, load_model};

use super::Encoding;
use crate::error::Result;

/// Arguments of `inspect`.
#[derive(Debug, Args)]
pub struct InspectArgs {
    /// Scene folder holding sparse/0/ (or sparse/), a model folder itself, or a dataset folder
    pub scene: PathBuf,
    /// Print one JSON object instead of a readable summary
    #[arg(long)]
    pub json: bool,
    /// Read this encoding even if the other exists [default: bin when present, else txt]
    #[arg(long, value_enum)]
    pub format: Option<Encoding>,
}

/// A dataset's summary: verdict counts and split sizes.
fn inspect_dataset(args: &InspectArgs) -> Result<()> {
    let ds = nrw_dataset::reader::Dataset::open(nrw_dataset::Store::open_path(&args.scene)?)?;
    let verdicts = nrw_dataset::scene::read_verdicts(&ds.store)?;
    let mut counts = std::collections::BTreeMap::new();
    for (_, _, v) in &verdicts {
        *counts.entry(v.clone()).or_insert(0usize) += 1;
    }
    let splits: std::collections::BTreeMap<String, usize> = ds.splits().into_iter().collect();
    if args.json {
        let v = json!({
            "dataset": args.scene.display().to_string(),
            "schema_version": ds.manifest.schema_version,
            "registered": verdicts.len(),
            "verdicts": counts,
            "views": ds.len(),
            "splits": splits,
            "parameters": ds.manifest.parameters,
        });
        println!(
            "{}",
            serde_json::to_string_pretty(&v).expect("JSON of plain values")
        );
        return Ok(());
    }
    println!(
        "dataset      {} (schema {})",
        args.scene.display(),
        ds.manifest.schema_version
    );
    println!("registered   {}", verdicts.len());
    for (k, n) in &counts {
        println!("  {k:<10} {n}");
    }
    println!("views        {} in {} shards", ds.len(), ds.shard_count());
    for (k, n) in &splits {
        println!("split {k:<6} {n}");
    }
    Ok(())
}

/// Run `inspect`.
pub fn run(args: &InspectArgs) -> Result<()> {
    if nrw_dataset::store::is_url(&args.scene.to_string_lossy())
        || args.scene.join(nrw_dataset::Manifest::FILE).is_file()
    {
        return inspect_dataset(args);
    }
    let (dir, rec) = load_model(&args.scene, args.format.map(Into::into))?;
    let stats = nrw_colmap::reprojection_stats(&rec);
    let (enc, layout) = describe(&rec);
    let warnings: Vec<String> = rec.warnings.iter().map(|w| w.to_string()).collect();
    if args.json {
        let v = json!({
            "model_dir": dir.display().to_string(),
            "encoding": enc,
            "layout": layout,
            "cameras": rec.cameras.len(),
            "images": rec.images.len(),
            "points": rec.points.len(),
            "observations": rec.num_observations(),
            "camera_models": rec.camera_model_names(),
            "mean_reprojection_error_px": stats.mean_px,
            "max_reprojection_error_px": stats.max_px,
            "not_visible_observations": stats.not_visible,
            "rigs": rec.rigs.len(),
            "frames": rec.frames.len(),
            "warnings": warnings,
        });
        println!(
            "{}",
            serde_json::to_string_pretty(&v).expect("JSON of plain values")
        );
        return Ok(());
    }
    let fmt_px = |v: Option<f64>| v.map_or("n/a".to_string(), |v| format!("{v:.4} px"));
    println!("model        {} ({enc}, {layout})", dir.display());
    println!(
        "cameras      {} ({})",
        rec.cameras.len(),
        rec.camera_model_names().join(", ")
    );
    println!("images       {}", rec.images.len());
    println!("points       {}", rec.points.len());
    let mean_track = if rec.points.is_empty() {
        0.0
    } else {
        rec.num_observations() as f64 / rec.points.len() as f64
    };
    println!(
        "observations {} (mean track length {mean_track:.2})",
        rec.num_observations()
    );
    println!(
        "reprojection mean {}, max {} over {} observations{}",
        fmt_px(stats.mean_px),
        fmt_px(stats.max_px),
        stats.observations,
        if stats.not_visible > 0 {
            format!(
                "; {} observations not visible (behind the camera)",
                stats.not_visible
            )
        } else {
            String::new()
        }
    );
    if rec.is_colmap4() {
        println!("rigs/frames  {} / {}", rec.rigs.len(), rec.frames.len());
    }
    for w in &warnings {
        println!("warning: {w}");
    }
    Ok(())
}
