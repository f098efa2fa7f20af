//! A pipeline file: the stages it turns on and their settings, as the runner reads them.

use std::path::Path;

use serde::Deserialize;

use crate::error::{PipelineError, Result};

/// A pipeline file: each table present is a stage to run, with its parameters.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Pipeline {
    pub name: String,
    pub densify: Option<DensifyTable>,
    pub ingest: Option<IngestTable>,
    pub split: Option<SplitTable>,
    pub style: Option<StyleTable>,
    pub triplets: Option<TripletsTable>,
    pub export: Option<ExportTable>,
    pub qa: Option<QaTable>,
}

/// `[densify]`: multi-view stereo into SCENE/dense before ingest, when the scene has no dense
/// cloud yet (an existing SCENE/dense is used as it is unless `overwrite`), as `densify`'s
/// flags say it ([`crate::settings::densify::DensifySettings`]).
pub type DensifyTable = crate::settings::densify::DensifySettings;

/// `[ingest]`: as `ingest`'s flags say it ([`crate::settings::ingest::IngestSettings`];
/// `semantics` relative to the scene folder).
pub type IngestTable = crate::settings::ingest::IngestSettings;

/// `[split]`: as `split`'s flags say it ([`crate::settings::split::SplitSettings`]).
pub type SplitTable = crate::settings::split::SplitSettings;

/// `[style]`: as `style`'s flags say it ([`crate::settings::style::StyleSettings`]; the
/// weights come from the command line).
pub type StyleTable = crate::settings::style::StyleSettings;

/// `[triplets]`: as `triplets`' flags say it ([`crate::settings::triplets::TripletsSettings`];
/// k is lowered, with a warning, to what the training split holds).
pub type TripletsTable = crate::settings::triplets::TripletsSettings;

/// `[export]`: the export into DIR/export, as `export`'s flags say it
/// ([`crate::settings::export::ExportSettings`]; the published code's own layout, `official`,
/// when left out).
pub type ExportTable = crate::settings::export::ExportSettings;

/// `[qa]`: the report into DIR/qa.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct QaTable {}

impl Pipeline {
    /// Parse a pipeline file, naming the file in errors.
    pub fn load(path: &Path) -> Result<Pipeline> {
        let text = std::fs::read_to_string(path).map_err(|e| PipelineError::io(path, e))?;
        toml::from_str(&text).map_err(|source| PipelineError::PipelineFile {
            path: path.into(),
            source,
        })
    }

    /// The demo's pipeline: the paper's settings, the synthetic scene's ground-truth labels
    /// standing in for a segmentation model, a fifth of the few photos held out, and the
    /// colour-statistics tier unless VGG16 weights are given.
    pub fn demo(weights: bool) -> Pipeline {
        Pipeline {
            name: "demo".into(),
            densify: None,
            ingest: Some(IngestTable {
                semantics: Some(nrw_synth::truth::SEMANTICS.into()),
                ..IngestTable::default()
            }),
            split: Some(SplitTable {
                val_fraction: Some(0.2),
                ..SplitTable::default()
            }),
            style: Some(if weights {
                StyleTable::default()
            } else {
                StyleTable {
                    tier: nrw_style::Tier::ColorStats.name(),
                    ..StyleTable::default()
                }
            }),
            triplets: Some(TripletsTable::default()),
            export: Some(ExportTable::default()),
            qa: Some(QaTable {}),
        }
    }
}
