//! `nrw-etl synth`: generate a synthetic scene from a spec file (or the embedded demo spec).

use std::path::{Path, PathBuf};
use std::time::Instant;

use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use nrw_synth::{SceneSpec, SynthReport};

use crate::error::{EtlError, Result};

/// Arguments of `synth`.
#[derive(Debug, Args)]
pub struct SynthArgs {
    /// Scene spec (TOML; see scenes/*.toml) [default: the embedded demo scene]
    pub spec: Option<PathBuf>,
    /// Folder to write the scene into (images/, sparse/0/, dense/, ground_truth/)
    #[arg(long)]
    pub out: PathBuf,
    /// Override the spec's seed
    #[arg(long)]
    pub seed: Option<u64>,
}

/// Load a spec file, or the embedded demo.
pub fn load_spec(path: Option<&Path>, seed: Option<u64>) -> Result<SceneSpec> {
    let mut spec = match path {
        None => SceneSpec::demo(),
        Some(p) => {
            let text = std::fs::read_to_string(p).map_err(|e| {
                EtlError::Usage(format!("{}: cannot read scene spec: {e}", p.display()))
            })?;
            SceneSpec::from_toml(&text, &p.display().to_string())?
        }
    };
    if let Some(s) = seed {
        spec.seed = s;
    }
    Ok(spec)
}

/// Generate with a progress bar over photos; returns the report.
pub fn generate(spec: &SceneSpec, out: &Path) -> Result<SynthReport> {
    let bar = ProgressBar::new(spec.cameras.count as u64).with_style(
        ProgressStyle::with_template("{msg:>10} [{bar:30}] {pos}/{len} photos {elapsed}")
            .expect("valid template")
            .progress_chars("=> "),
    );
    bar.set_message("rendering");
    let t = Instant::now();
    let report = nrw_synth::generate(spec, out, &|| bar.inc(1))?;
    bar.finish_and_clear();
    eprintln!(
        "synthesised {:?}: {} photos ({} small, {} looking away), {} sparse points, {} observations, {} dense points in {:.1} s",
        spec.name,
        report.photos,
        report.small_photos,
        report.away_photos,
        report.sparse_points,
        report.observations,
        report.dense_points,
        t.elapsed().as_secs_f64()
    );
    Ok(report)
}

/// Run `synth`.
pub fn run(args: &SynthArgs) -> Result<()> {
    let spec = load_spec(args.spec.as_deref(), args.seed)?;
    generate(&spec, &args.out)?;
    println!("{}", args.out.display());
    Ok(())
}
