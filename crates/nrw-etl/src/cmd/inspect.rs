//! `nrw-etl inspect`: what a COLMAP model holds and how well it agrees with itself, or what a
//! dataset holds (`nrw_pipeline::inspect`), printed.

use std::path::PathBuf;

use clap::Args;
use nrw_pipeline::inspect::{DatasetSummary, Inspected, ModelSummary};

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

/// Run `inspect`.
pub fn run(args: &InspectArgs) -> Result<()> {
    let found = nrw_pipeline::inspect::inspect(&args.scene, args.format.map(Into::into))?;
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
    match &found {
        Inspected::Model(m) => print_model(m),
        Inspected::Dataset(d) => print_dataset(d),
    }
    Ok(())
}

fn print_dataset(d: &DatasetSummary) {
    println!("dataset      {} (schema {})", d.dataset, d.schema_version);
    println!("registered   {}", d.registered);
    for (k, n) in &d.verdicts {
        println!("  {k:<10} {n}");
    }
    println!("views        {} in {} shards", d.views, d.shards);
    for (k, n) in &d.splits {
        println!("split {k:<6} {n}");
    }
}

fn print_model(m: &ModelSummary) {
    let fmt_px = |v: Option<f64>| v.map_or("n/a".to_string(), |v| format!("{v:.4} px"));
    println!(
        "model        {} ({}, {})",
        m.model_dir, m.encoding, m.layout
    );
    println!(
        "cameras      {} ({})",
        m.cameras,
        m.camera_models.join(", ")
    );
    println!("images       {}", m.images);
    println!("points       {}", m.points);
    println!(
        "observations {} (mean track length {:.2})",
        m.observations,
        m.mean_track_length()
    );
    println!(
        "reprojection mean {}, max {} over {} observations{}",
        fmt_px(m.mean_reprojection_error_px),
        fmt_px(m.max_reprojection_error_px),
        m.observations_projected,
        if m.not_visible_observations > 0 {
            format!(
                "; {} observations not visible (behind the camera)",
                m.not_visible_observations
            )
        } else {
            String::new()
        }
    );
    if m.layout == "colmap4" {
        println!("rigs/frames  {} / {}", m.rigs, m.frames);
    }
    for w in &m.warnings {
        println!("warning: {w}");
    }
}
