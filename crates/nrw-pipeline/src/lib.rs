//! The stages of nrw-etl as functions over plain configuration structs: ingest, finalize,
//! segment, split, style, triplets, export and qa, plus the pipeline runner that chains them. Each
//! config's `Default` (or `new`) is the paper's settings; each stage returns a typed summary
//! or a typed error and reports progress through [`Progress`], so the library never prints.
//!
//! Ingest and style also run as independent work units (`Unit`, `--unit I/N`): each unit
//! does the groups it owns and writes only its own files; [`finalize::finalize`] merges the
//! units into the same bytes a single process writes.

pub mod corpus;
pub mod densify;
pub mod error;
pub mod export;
pub mod finalize;
pub mod ingest;
pub mod inspect;
pub mod model;
pub mod mvs_prior;
pub mod progress;
pub mod qa;
pub mod report;
pub mod runner;
pub mod segment;
pub mod settings;
pub mod split;
pub mod stage;
pub mod style;
pub mod synth;
pub mod timing;
pub mod triplets;
pub mod units;
pub mod verify;

pub use error::{PipelineError, Result, Setting};
pub use progress::{Progress, Silent};
pub use units::Unit;

/// SHA-256 of bytes as lower-case hex (fingerprints of inputs and parameters), as the
/// dataset's manifest writes digests.
pub use nrw_dataset::manifest::sha256_hex;
