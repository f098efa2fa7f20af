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

    /// A command of one settings struct, as a stage's command flattens it.
    #[derive(clap::Parser)]
    struct Cli<T: clap::Args> {
        #[command(flatten)]
        settings: T,
    }

    /// The settings the flags `args` (after the command's name) give.
    pub(crate) fn parse<T: clap::Args>(args: &[&str]) -> T {
        let argv = std::iter::once("stage").chain(args.iter().copied());
        <Cli<T> as clap::Parser>::try_parse_from(argv)
            .unwrap_or_else(|e| panic!("{args:?}: {e}"))
            .settings
    }

    /// The settings a pipeline file's table gives.
    pub(crate) fn table<T: serde::de::DeserializeOwned>(text: &str) -> T {
        toml::from_str(text).unwrap_or_else(|e| panic!("{text:?}: {e}"))
    }

    /// A stage's settings are declared once: every flag is a table key and every key a flag,
    /// and no flag and an empty table both give the defaults.
    pub(crate) fn declared_once<T>()
    where
        T: clap::Args
            + serde::Serialize
            + serde::de::DeserializeOwned
            + Default
            + PartialEq
            + std::fmt::Debug,
    {
        let keys = match serde_json::to_value(T::default()).expect("settings serialise") {
            serde_json::Value::Object(m) => m.keys().cloned().collect::<BTreeSet<_>>(),
            v => panic!("settings serialise to an object, not {v}"),
        };
        let flags: BTreeSet<String> = T::augment_args(clap::Command::new("stage"))
            .get_arguments()
            .map(|a| a.get_id().to_string())
            .filter(|id| id != "help")
            .collect();
        assert_eq!(flags, keys, "flags (left) and table keys (right)");
        assert_eq!(parse::<T>(&[]), T::default(), "no flag gives the defaults");
        assert_eq!(
            table::<T>(""),
            T::default(),
            "an empty table gives the defaults"
        );
    }
}
