//! The CLI's error: a stage's typed error, or a problem with the command line itself.

/// Everything a command can fail with; each message names the file (and record) involved.
#[derive(Debug, thiserror::Error)]
pub enum EtlError {
    #[error(transparent)]
    Pipeline(nrw_pipeline::PipelineError),
    #[error(transparent)]
    Colmap(#[from] nrw_colmap::ColmapError),
    #[error(transparent)]
    Dataset(#[from] nrw_dataset::DatasetError),
    /// A flag's value the library refused, named by the flag.
    #[error("{flag} {problem}")]
    Flag { flag: String, problem: String },
    /// A problem with a pipeline file's keys (`run`), named as the file spells them: shown
    /// as it is, never with flags in place of keys.
    #[error("{0}")]
    Keys(nrw_pipeline::PipelineError),
}

/// A stage's error; a setting it names is shown as the flag that sets it.
impl From<nrw_pipeline::PipelineError> for EtlError {
    fn from(e: nrw_pipeline::PipelineError) -> Self {
        match e {
            nrw_pipeline::PipelineError::Config { setting, problem } => EtlError::Flag {
                flag: flag(setting),
                problem: flags(&problem),
            },
            e => EtlError::Pipeline(e),
        }
    }
}

/// The command-line flag (or argument) of a stage setting ([`nrw_pipeline::Setting::flag`]).
pub fn flag(s: nrw_pipeline::Setting) -> String {
    s.flag()
}

/// A library message as the CLI shows it ([`nrw_pipeline::settings::flags`]).
pub fn flags(text: &str) -> String {
    nrw_pipeline::settings::flags(text)
}

impl EtlError {
    /// Whether the message names pipeline keys, which the CLI must not turn into flags.
    pub fn names_keys(&self) -> bool {
        matches!(self, EtlError::Keys(_))
    }

    /// Whether the stage stopped on request (exit code 130: run again to resume).
    pub fn interrupted(&self) -> bool {
        matches!(
            self,
            EtlError::Pipeline(nrw_pipeline::PipelineError::Interrupted(_))
        )
    }
}

/// Result alias for the CLI.
/// An error as the command line prints it: `error: …`, then each cause not already in the
/// line before it (messages that include their cause would print it twice).
pub fn error_lines(e: &dyn std::error::Error) -> Vec<String> {
    let mut shown = e.to_string();
    let mut out = vec![format!("error: {shown}")];
    let mut src = e.source();
    while let Some(s) = src {
        let text = s.to_string();
        if !shown.contains(&text) {
            out.push(format!("  caused by: {text}"));
            shown = text;
        }
        src = s.source();
    }
    out
}

pub type Result<T, E = EtlError> = std::result::Result<T, E>;

#[cfg(test)]
mod tests {
    use super::*;
    use nrw_pipeline::Setting;

    #[test]
    fn every_mentioned_setting_shows_as_its_flag_and_other_text_stays() {
        for s in Setting::ALL {
            assert_eq!(
                flags(&format!("use {s} here")),
                format!("use {} here", flag(s))
            );
        }
        let m = format!(
            "{} 7 needs 8 photos; use {} 6 or a smaller {}",
            Setting::Key("triplets.k"),
            Setting::Key("triplets.k"),
            Setting::Key("export.crop")
        );
        assert_eq!(
            flags(&m),
            "--k 7 needs 8 photos; use --k 6 or a smaller --crop"
        );
        let other = "`dense/fused.ply` and `images/` stay; triplets.k without backticks stays";
        assert_eq!(flags(other), other);
    }

    /// The stages whose keys messages mention (`stage.field`).
    const STAGES: [&str; 8] = [
        "ingest", "style", "triplets", "split", "export", "segment", "corpus", "densify",
    ];

    /// Endings that make a backticked word a file name (`export.json`), not a key.
    const FILE_ENDINGS: [&str; 4] = ["json", "parquet", "toml", "txt"];

    /// Backticked `stage.field` words and `Setting::Key` names in the crates' sources that
    /// name no setting: a message of a crate below nrw-pipeline spells the key itself, and a
    /// renamed key must not leave it shown raw by the CLI.
    #[test]
    fn every_key_the_crates_mention_is_a_setting() {
        let known = |word: &str| {
            Setting::ALL.iter().any(|s| s.key() == word)
                || nrw_pipeline::settings::flag_of(word).is_some()
        };
        let crates = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
        let mut orphans = Vec::new();
        let mut seen = 0;
        for krate in ["nrw-colmap", "nrw-dataset", "nrw-export", "nrw-pipeline"] {
            for file in rs_files(&crates.join(krate).join("src")) {
                let text = std::fs::read_to_string(&file).unwrap();
                for named in text.split("Setting::Key(\"").skip(1) {
                    let word = named.split('"').next().unwrap_or_default();
                    seen += 1;
                    if !known(word) {
                        orphans.push(format!("{}: Setting::Key(\"{word}\")", file.display()));
                    }
                }
                for word in text.split('`').skip(1).step_by(2) {
                    let Some((stage, field)) = word.split_once('.') else {
                        continue;
                    };
                    let is_key = STAGES.contains(&stage)
                        && !FILE_ENDINGS.contains(&field)
                        && !field.is_empty()
                        && field.chars().all(|c| c.is_ascii_lowercase() || c == '_');
                    if is_key {
                        seen += 1;
                        if !known(word) {
                            orphans.push(format!("{}: `{word}`", file.display()));
                        }
                    }
                }
            }
        }
        assert!(
            seen >= 8,
            "the scan found only {seen} mentions: it reads nothing"
        );
        assert!(orphans.is_empty(), "keys that name no setting: {orphans:?}");
    }

    /// Every `.rs` file under `dir`.
    fn rs_files(dir: &std::path::Path) -> Vec<std::path::PathBuf> {
        let mut out = Vec::new();
        for e in std::fs::read_dir(dir).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                out.extend(rs_files(&p));
            } else if p.extension().is_some_and(|x| x == "rs") {
                out.push(p);
            }
        }
        out
    }
}
