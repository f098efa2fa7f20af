//! `run --set TABLE.KEY=VALUE`: a key of a pipeline file changed on the command line, typed
//! and checked as the file's own keys are, so a user changes `split.val` without copying the
//! file.

use std::path::Path;

use serde::Deserialize;

use super::pipeline::Pipeline;
use crate::error::{PipelineError, Result};

/// One `--set TABLE.KEY=VALUE`.
#[derive(Debug, Clone, PartialEq)]
pub struct Override {
    /// `TABLE.KEY=VALUE` as given, for messages.
    pub text: String,
    pub table: String,
    pub key: String,
    pub value: toml::Value,
}

impl std::str::FromStr for Override {
    type Err = String;

    /// `split.val=20`, `export.layout=gsplat`, `densify.preset="fast"`: the value as TOML reads
    /// it (a number, a boolean, a quoted string, an array), else the text as a string.
    fn from_str(text: &str) -> std::result::Result<Self, String> {
        let (path, value) = text
            .split_once('=')
            .ok_or_else(|| format!("`{text}` is not TABLE.KEY=VALUE (e.g. split.val=20)"))?;
        let (table, key) = path
            .trim()
            .split_once('.')
            .filter(|(t, k)| !t.is_empty() && !k.is_empty() && !k.contains('.'))
            .ok_or_else(|| format!("`{path}` is not TABLE.KEY (e.g. split.val)"))?;
        Ok(Override {
            text: text.to_string(),
            table: table.to_string(),
            key: key.to_string(),
            value: toml_value(value.trim()),
        })
    }
}

/// A value as TOML reads it, else the text as a string (`gsplat` needs no quotes).
fn toml_value(text: &str) -> toml::Value {
    toml::from_str::<toml::Table>(&format!("v = {text}"))
        .ok()
        .and_then(|mut t| t.remove("v"))
        .unwrap_or_else(|| toml::Value::String(text.to_string()))
}

impl Override {
    /// Refused unless a pipeline file holding only this key would parse: an unknown table or
    /// key, or a value of the wrong type, named as `TABLE.KEY`.
    fn check(&self) -> Result<()> {
        let mut table = toml::Table::new();
        table.insert(self.key.clone(), self.value.clone());
        let mut doc = toml::Table::new();
        doc.insert("name".into(), toml::Value::String("check".into()));
        doc.insert(self.table.clone(), toml::Value::Table(table));
        Pipeline::deserialize(toml::Value::Table(doc))
            .map(|_| ())
            .map_err(|e| self.refused(e.message().trim().to_string()))
    }

    fn refused(&self, problem: String) -> PipelineError {
        PipelineError::Override {
            set: self.text.clone(),
            problem,
        }
    }
}

impl Pipeline {
    /// Parse a pipeline file with `overrides` applied, each checked alone first (so an error
    /// names its key), then the whole as the file's own keys are.
    pub fn load_with(path: &Path, overrides: &[Override]) -> Result<Pipeline> {
        if overrides.is_empty() {
            return Pipeline::load(path);
        }
        let text = std::fs::read_to_string(path).map_err(|e| PipelineError::io(path, e))?;
        let file_error = |source| PipelineError::PipelineFile {
            path: path.into(),
            source,
        };
        let mut doc: toml::Table = toml::from_str(&text).map_err(file_error)?;
        for o in overrides {
            o.check()?;
            let table = doc
                .get_mut(&o.table)
                .and_then(|t| t.as_table_mut())
                .ok_or_else(|| {
                    o.refused(format!(
                        "{} has no [{}] table, so the stage does not run; add the table to the file to run it",
                        path.display(),
                        o.table
                    ))
                })?;
            table.insert(o.key.clone(), o.value.clone());
        }
        Pipeline::deserialize(toml::Value::Table(doc)).map_err(|e| PipelineError::Override {
            set: overrides
                .iter()
                .map(|o| o.text.as_str())
                .collect::<Vec<_>>()
                .join(" "),
            problem: e.message().trim().to_string(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nrw_export::Layout;

    fn paper() -> std::path::PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../pipelines/paper.toml")
    }

    fn set(texts: &[&str]) -> Result<Pipeline> {
        let o: Vec<Override> = texts.iter().map(|t| t.parse().unwrap()).collect();
        Pipeline::load_with(&paper(), &o)
    }

    #[test]
    fn a_set_key_replaces_the_files_value_typed_as_the_file_types_it() {
        let p = set(&[
            "split.val=20",
            "export.layout=gsplat",
            "ingest.max_empty = 0.9",
            "densify.preset=\"fast\"",
        ])
        .unwrap();
        assert_eq!(p.split.unwrap().val, Some(20));
        assert_eq!(p.export.unwrap().layout, Layout::Gsplat);
        assert_eq!(p.ingest.unwrap().max_empty, 0.9);
        assert_eq!(
            p.densify.unwrap().preset,
            crate::settings::densify::DensifyPreset::Fast
        );
        // The file's other keys stay.
        assert_eq!(set(&[]).unwrap().triplets.unwrap().k, 20);
    }

    #[test]
    fn a_bad_key_or_value_is_refused_naming_it() {
        let refused = |t: &str| set(&[t]).unwrap_err().to_string();
        for (t, says) in [
            ("split.vall=2", "unknown field `vall`"),
            ("split.val=abc", "invalid type: string \"abc\""),
            ("split.val=-1", "invalid value: integer `-1`"),
            ("nope.val=2", "unknown field `nope`"),
            ("export.layout=gsplatt", "gsplatt"),
        ] {
            let e = refused(t);
            assert!(
                e.starts_with(&format!("`{t}`: ")) && e.contains(says),
                "{t}: {e}"
            );
        }
        let p = std::env::temp_dir().join(format!("nrw-set-{}.toml", std::process::id()));
        std::fs::write(&p, "name = 'x'\n[ingest]\n").unwrap();
        let e = Pipeline::load_with(&p, &["split.val=2".parse().unwrap()])
            .unwrap_err()
            .to_string();
        std::fs::remove_file(&p).unwrap();
        assert!(e.contains("has no [split] table"), "{e}");
        for bad in ["val=2", "split=2", ".val=2", "split.=2", "a.b.c=1"] {
            assert!(bad.parse::<Override>().is_err(), "{bad}");
        }
    }
}
