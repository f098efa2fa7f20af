//! Each stage's settings declared once: one struct per stage from which the command line's
//! flags (clap), the pipeline file's table (serde, defaults the paper's) and the names errors
//! use all come. A field's name is its table key; its flag is that name in kebab case (or
//! `--no-NAME` for a setting on by default); its doc comment is the flag's help.
//!
//! A command's flags outside its settings struct name places and run control (where, which
//! model file, which work unit, whether to replace, how much to print), never how a stage
//! computes.
//!
//! Declared here: densify, ingest, split, style, triplets, export (every stage a pipeline
//! file has a table for). `segment`, which no pipeline file runs (ingest's
//! `segment_mode`/`segment_size` do), keeps its flags in nrw-etl's `cmd/segment.rs`.

pub mod densify;
pub mod export;
pub mod ingest;
pub mod split;
pub mod style;
pub mod triplets;

use clap::builder::{PossibleValue, PossibleValuesParser, TypedValueParser};

/// A clap parser over a library enum's names (`ALL`, `name`, `summary`), each value with its
/// help line: the CLI, pipeline files and the library share one enum.
pub fn names<T>(
    all: &'static [T],
    name: fn(T) -> &'static str,
    summary: fn(T) -> &'static str,
) -> impl TypedValueParser<Value = T>
where
    T: Copy + Send + Sync + std::str::FromStr + 'static,
    T::Err: std::fmt::Debug,
{
    PossibleValuesParser::new(
        all.iter()
            .map(|v| PossibleValue::new(name(*v)).help(crate::error::flags(summary(*v)))),
    )
    .map(|n| n.parse::<T>().expect("clap passes only the listed names"))
}

#[cfg(test)]
pub(crate) mod tests {
    use std::collections::BTreeSet;

    /// The table keys of a settings struct: the fields of its default as serialised.
    pub(crate) fn keys<T: serde::Serialize + Default>() -> BTreeSet<String> {
        match serde_json::to_value(T::default()).expect("settings serialise") {
            serde_json::Value::Object(m) => m.keys().cloned().collect(),
            v => panic!("settings serialise to an object, not {v}"),
        }
    }

    /// The argument ids (field names) of a settings struct's flags.
    pub(crate) fn flags<T: clap::Args>() -> BTreeSet<String> {
        T::augment_args(clap::Command::new("stage"))
            .get_arguments()
            .map(|a| a.get_id().to_string())
            .filter(|id| id != "help")
            .collect()
    }
}
