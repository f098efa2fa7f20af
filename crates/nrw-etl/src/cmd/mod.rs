//! One module per subcommand: each turns its arguments into a stage's config, calls the
//! stage in nrw-pipeline, and prints what it did.

pub mod corpus;
pub mod demo;
pub mod densify;
pub mod export;
pub mod finalize;
pub mod ingest;
pub mod inspect;
pub mod qa;
pub mod run;
pub mod segment;
pub mod split;
pub mod style;
pub mod synth;
pub mod triplets;
pub mod verify;

use std::sync::Mutex;

use clap::Args;
use nrw_pipeline::{Progress, Unit};

/// Print a stage's report: each line on its stream (results on stdout, the rest on stderr).
pub fn print_report(report: &nrw_pipeline::report::Report) {
    for line in &report.0 {
        match line {
            nrw_pipeline::report::Line::Out(s) => println!("{}", crate::error::flags(s)),
            nrw_pipeline::report::Line::Err(s) => eprintln!("{}", crate::error::flags(s)),
        }
    }
}

/// A clap parser over a library enum's names ([`nrw_pipeline::settings::names`]).
pub use nrw_pipeline::settings::names;

/// `--unit`/`--unit-count`: run one work unit of a stage instead of the whole stage.
#[derive(Debug, Clone, Default, Args)]
pub struct UnitArgs {
    /// Do only work unit I of N (0-based), e.g. 2/8, then `nrw-etl finalize DATASET` once
    /// every unit has run. `auto` reads Slurm array (SLURM_ARRAY_TASK_ID/COUNT) or Kubernetes
    /// Indexed Job (JOB_COMPLETION_INDEX, with --unit-count) variables. `--shard` is its old
    /// name, still taken
    #[arg(long = "unit", alias = "shard", value_name = "I/N|auto")]
    pub unit: Option<String>,
    /// Unit count for --unit auto when the scheduler does not export it (Kubernetes;
    /// `--shard-count` is its old name)
    #[arg(long, alias = "shard-count", value_name = "N")]
    pub unit_count: Option<usize>,
}

impl UnitArgs {
    /// The unit asked for, or `None` for the whole stage.
    pub fn unit(&self) -> crate::error::Result<Option<Unit>> {
        let Some(text) = &self.unit else {
            return Ok(None);
        };
        Ok(Some(Unit::parse(text, self.unit_count, &|k| {
            std::env::var(k).ok()
        })?))
    }
}

/// A stage's progress as a terminal bar with its ETA (hidden with `--quiet`), and its
/// warnings on stderr.
pub struct Bars {
    quiet: bool,
    bar: Mutex<Option<indicatif::ProgressBar>>,
}

impl Bars {
    /// Bars that draw unless `quiet`.
    pub fn new(quiet: bool) -> Bars {
        Bars {
            quiet,
            bar: Mutex::new(None),
        }
    }

    fn with(&self, f: impl FnOnce(&indicatif::ProgressBar)) {
        if let Some(b) = self.bar.lock().expect("bar lock").as_ref() {
            f(b)
        }
    }
}

impl Progress for Bars {
    fn start(&self, what: &str, len: u64, unit: &str) {
        if self.quiet {
            return;
        }
        let b = indicatif::ProgressBar::new(len).with_style(
            indicatif::ProgressStyle::with_template(&format!(
                "{{msg:>10}} [{{bar:30}}] {{pos}}/{{len}} {unit} {{elapsed}} (eta {{eta}})"
            ))
            .expect("valid template")
            .progress_chars("=> "),
        );
        b.set_message(what.to_string());
        *self.bar.lock().expect("bar lock") = Some(b);
    }

    fn inc(&self, n: u64) {
        self.with(|b| b.inc(n));
    }

    fn finish(&self) {
        if let Some(b) = self.bar.lock().expect("bar lock").take() {
            b.finish_and_clear();
        }
    }

    fn warn(&self, message: &str) {
        if !self.quiet {
            eprintln!("warning: {}", crate::error::flags(message));
        }
    }
}
