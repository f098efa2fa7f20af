//! One module per subcommand.

pub mod demo;
pub mod export;
pub mod ingest;
pub mod inspect;
pub mod qa;
pub mod run;
pub mod split;
pub mod style;
pub mod synth;
pub mod triplets;

use std::path::{Path, PathBuf};

use clap::ValueEnum;

/// `--format` values: which encoding of the model to read.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum Encoding {
    /// cameras.bin, images.bin, points3D.bin (preferred when both exist)
    Bin,
    /// cameras.txt, images.txt, points3D.txt
    Txt,
}

impl From<Encoding> for nrw_colmap::Format {
    fn from(e: Encoding) -> Self {
        match e {
            Encoding::Bin => nrw_colmap::Format::Binary,
            Encoding::Txt => nrw_colmap::Format::Text,
        }
    }
}

/// Find and read the model of a scene folder (or a model folder itself).
pub fn load_model(
    scene: &Path,
    format: Option<Encoding>,
) -> crate::error::Result<(PathBuf, nrw_colmap::Reconstruction)> {
    let dir = nrw_colmap::find_model_dir(scene)?;
    let rec = nrw_colmap::read_model(&dir, format.map(Into::into))?;
    Ok((dir, rec))
}

/// Refuse stages that need views when ingest kept none, saying so (rather than pointing at a
/// missing earlier stage).
pub fn require_views(dataset: &Path) -> crate::error::Result<nrw_dataset::reader::Dataset> {
    let ds = nrw_dataset::reader::Dataset::open(dataset)?;
    if ds.is_empty() {
        let registered = nrw_dataset::scene::read_verdicts(dataset)?.len();
        return Err(crate::error::EtlError::Usage(format!(
            "{}: no kept view: ingest dropped all {registered} registered photos (`nrw-etl inspect {}` shows why)",
            dataset.display(),
            dataset.display()
        )));
    }
    Ok(ds)
}

/// `bin`/`txt` and `colmap3`/`colmap4`, as reports and manifests spell them.
pub fn describe(rec: &nrw_colmap::Reconstruction) -> (&'static str, &'static str) {
    let enc = rec.format.map_or("?", |f| f.ext());
    let layout = if rec.is_colmap4() {
        "colmap4"
    } else {
        "colmap3"
    };
    (enc, layout)
}

/// A stage's progress bar over `len` items called `unit` (views, photos), with its ETA;
/// hidden with `--quiet`.
pub fn progress_bar(len: usize, unit: &str, quiet: bool) -> indicatif::ProgressBar {
    if quiet {
        return indicatif::ProgressBar::hidden();
    }
    indicatif::ProgressBar::new(len as u64).with_style(
        indicatif::ProgressStyle::with_template(&format!(
            "{{msg:>10}} [{{bar:30}}] {{pos}}/{{len}} {unit} {{elapsed}} (eta {{eta}})"
        ))
        .expect("valid template")
        .progress_chars("=> "),
    )
}
