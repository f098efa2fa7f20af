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

use crate::error::Setting;

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
    // Help that mentions a setting shows its flag, except while [`flag_of`] reads the
    // structs (it needs the flags' names, and the help would ask it again).
    let help = |v: T| match LOOKING_UP.get() {
        true => summary(v).to_string(),
        false => flags(summary(v)),
    };
    PossibleValuesParser::new(
        all.iter()
            .map(|v| PossibleValue::new(name(*v)).help(help(*v))),
    )
    .map(|n| n.parse::<T>().expect("clap passes only the listed names"))
}

thread_local! {
    /// Whether this thread is inside [`flag_of`].
    static LOOKING_UP: std::cell::Cell<bool> = const { std::cell::Cell::new(false) };
}

/// The flag that sets `key` (`stage.field`) as its stage's settings struct declares it
/// (`--no-geometric` for `densify.geometric`), or `None` for a key no struct has.
pub fn flag_of(key: &str) -> Option<String> {
    use clap::Args;
    let (stage, field) = key.split_once('.')?;
    let cmd = clap::Command::new("stage");
    let was = LOOKING_UP.replace(true);
    let cmd = match stage {
        "densify" => densify::DensifySettings::augment_args(cmd),
        "export" => export::ExportSettings::augment_args(cmd),
        "ingest" => ingest::IngestSettings::augment_args(cmd),
        "split" => split::SplitSettings::augment_args(cmd),
        "style" => style::StyleSettings::augment_args(cmd),
        "triplets" => triplets::TripletsSettings::augment_args(cmd),
        _ => clap::Command::new("none"),
    };
    LOOKING_UP.set(was);
    let arg = cmd.get_arguments().find(|a| a.get_id() == field)?;
    arg.get_long().map(|long| format!("--{long}"))
}

impl Setting {
    /// The command-line flag (or argument) of the setting: what the CLI names where a
    /// pipeline file names its key.
    pub fn flag(self) -> String {
        match self.named_flag() {
            Some(flag) => flag.to_string(),
            None => flag_of(self.key()).unwrap_or_else(|| self.to_string()),
        }
    }

    /// The flag of a setting with a variant of its own (`None` for a [`Setting::Key`], whose
    /// flag its settings struct declares).
    fn named_flag(self) -> Option<&'static str> {
        use Setting as S;
        Some(match self {
            S::SegmentWeights => "--segment-weights",
            S::Weights => "--weights",
            S::Unit => "--unit",
            S::UnitCount => "--unit-count",
            S::Photos => "SCENE",
            // Only a pipeline file has a [split] table.
            S::Split => "[split]",
            S::Images => "--images",
            S::Points => "--points",
            S::Overwrite => "--overwrite",
            S::Entries => "--entries",
            S::FollowOutsideLinks => "--follow-outside-links",
            S::DenseOut => "--out",
            S::Stereo => "--iterations/--window-radius/--scales",
            S::Key(_) => return None,
        })
    }
}

/// A library message as the CLI shows it: every setting it mentions (its key in backticks,
/// as [`Setting`] displays) shown as the flag that sets it.
pub fn flags(text: &str) -> String {
    if !text.contains('`') {
        return text.to_string();
    }
    let named = Setting::ALL.iter().fold(text.to_string(), |t, s| {
        t.replace(&s.to_string(), &s.flag())
    });
    declared_flags(&named)
}

/// `text` with each backticked key of a settings struct's field shown as its flag.
fn declared_flags(text: &str) -> String {
    let pieces: Vec<&str> = text.split('`').collect();
    let mut out = String::with_capacity(text.len());
    for (i, piece) in pieces.iter().enumerate() {
        // Odd pieces stand between backticks; the last is closed only if one follows.
        let quoted = i % 2 == 1;
        let closed = i + 1 < pieces.len();
        match (quoted, quoted && closed) {
            (false, _) => out.push_str(piece),
            (true, true) => match flag_of(piece) {
                Some(flag) => out.push_str(&flag),
                None => out.push_str(&format!("`{piece}`")),
            },
            // An opening backtick without a closing one is kept as it was.
            (true, false) => out.push_str(&format!("`{piece}")),
        }
    }
    out
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

    #[test]
    fn a_backticked_key_shows_as_its_flag_and_other_text_as_it_was() {
        assert_eq!(
            super::flags("`densify.geometric` off; see ingest.radius and `export.json`"),
            "--no-geometric off; see ingest.radius and `export.json`"
        );
        assert_eq!(
            super::flags("an open `ingest.radius"),
            "an open `ingest.radius"
        );
        assert_eq!(
            super::flags("`ingest.no_such` and `unit`"),
            "`ingest.no_such` and --unit"
        );
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
