//! `export`'s settings: the flags of `nrw-etl export` and the `[export]` table of a pipeline
//! file, one declaration.

use nrw_dataset::Location;
use nrw_export::official::DepthMapping;
use nrw_export::{ExportConfig, Layout};
use serde::{Deserialize, Serialize};

use crate::error::{PipelineError, Result, Setting};

/// What `export` is asked to write; a setting left out of `[export]` (or off the command
/// line) is the published pipeline's.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, clap::Args)]
#[serde(deny_unknown_fields, default)]
pub struct ExportSettings {
    /// Which layout to write
    #[arg(long, value_parser = super::names(&Layout::ALL, Layout::name, Layout::summary), default_value = "official")]
    pub layout: Layout,
    /// Dataset name the published code is run with (--dataset_name): NAME_train.tfrecord,
    /// dist_NAME.pckl [default: the dataset folder's name]
    #[arg(long)]
    pub name: Option<String>,
    /// Centre crop of every channel, official and tfrecord layouts [default: 512, the published
    /// pipeline's: its segmentation writes *_seg_rgb.png as the 512 centre crop, so its
    /// pretraining, which crops every channel but that one, reads only crops of the training
    /// resolution]. Use the resolution you train at (e.g. 256 for --train_resolution=256);
    /// views smaller than the crop are skipped and listed. `none` keeps the stored size, which
    /// dataset_utils.py converts but pretrain_appearance.py cannot read
    #[arg(long, value_parser = parse_crop)]
    pub crop: Option<Crop>,
    /// Export without semantics (no *_seg_rgb.png; empty `seg` in TFRecords): train with
    /// --use_semantic=False
    #[arg(long = "no-semantics", action = clap::ArgAction::SetFalse)]
    pub semantics: bool,
    /// How depth becomes the levels 1-255 the published loaders expect
    #[arg(long, value_parser = super::names(&DepthMapping::ALL, DepthMapping::name, DepthMapping::summary), default_value = "linear")]
    pub depth: DepthMapping,
    /// TFRecord files per split (`NAME-0000i-of-0000N_SPLIT.tfrecord`; `--shards` is its old
    /// name, still taken)
    #[arg(long, alias = "shards", default_value_t = 1)]
    pub tfrecord_files: usize,
    /// Metres a model unit, megadepth layout: IMC 2022's scaling_factors.csv, which its pose
    /// evaluation multiplies translations by (SfM does not know it: measure a known length)
    #[arg(long, value_parser = parse_scale)]
    pub metres_per_unit: Option<f64>,
    /// Export only photos under these licences, comma-separated (SPDX ids, Creative Commons
    /// names or URLs, Flickr ids; `unknown` for photos nobody gave one for), e.g.
    /// CC-BY-2.0,CC-BY-SA-2.0,CC0-1.0; the summary says how many views that leaves out.
    /// Licences come from `ingest --photo-info` [default: every view]
    #[arg(long, value_delimiter = ',', value_parser = parse_licence)]
    pub licences: Option<Vec<String>>,
}

impl Default for ExportSettings {
    fn default() -> Self {
        let c = ExportConfig::official(Location::parse(""), String::new());
        ExportSettings {
            layout: Layout::Official,
            name: None,
            crop: None,
            semantics: c.paper.semantics,
            depth: c.paper.depth,
            tfrecord_files: c.paper.tfrecord_files,
            metres_per_unit: c.imc.metres_per_unit,
            licences: None,
        }
    }
}

/// A crop: a side in pixels, or the word `none` (keep the stored size).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum Crop {
    Side(u32),
    Word(NoCrop),
}

/// The one word a crop takes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum NoCrop {
    None,
}

/// `--crop` values: a side in pixels, or `none`.
fn parse_crop(s: &str) -> std::result::Result<Crop, String> {
    match s {
        "none" => Ok(Crop::Word(NoCrop::None)),
        n => n
            .parse::<u32>()
            .map(Crop::Side)
            .map_err(|_| format!("{n:?} is neither a side in pixels (e.g. 512) nor `none`")),
    }
}

/// `--licences` values: one accepted spelling each, kept as its SPDX id.
fn parse_licence(s: &str) -> std::result::Result<String, String> {
    nrw_dataset::photo_info::normalise_licence(s).ok_or_else(|| {
        format!(
            "{s:?} is not a licence nrw-etl knows; give {}",
            nrw_dataset::photo_info::LICENCE_SPELLINGS
        )
    })
}

/// `--metres-per-unit` values: a finite length above zero.
fn parse_scale(s: &str) -> std::result::Result<f64, String> {
    match s.parse::<f64>() {
        Ok(x) if x.is_finite() && x > 0.0 => Ok(x),
        _ => Err(format!(
            "{s:?} is not a length in metres above zero (e.g. 0.0254)"
        )),
    }
}

impl ExportSettings {
    /// The export of `dataset` into `out` these settings ask for: the one place a default
    /// (the layout's crop, the dataset's name) is resolved, for the CLI and pipeline files.
    pub fn config(&self, dataset: &Location, out: &Location) -> Result<ExportConfig> {
        if let Some(m) = self.metres_per_unit {
            if !(m.is_finite() && m > 0.0) {
                return Err(PipelineError::config(
                    Setting::Key("export.metres_per_unit"),
                    format!("is {m}: a length in metres above zero (e.g. 0.0254)"),
                ));
            }
        }
        if self.tfrecord_files == 0 {
            return Err(PipelineError::config(
                Setting::Key("export.tfrecord_files"),
                "is 0: a split needs at least one TFRecord file",
            ));
        }
        Ok(ExportConfig {
            name: self
                .name
                .clone()
                .unwrap_or_else(|| crate::export::default_name(dataset)),
            paper: nrw_export::published::PaperOptions {
                // The files layout keeps views whole; the paper's layouts take the published
                // crop.
                crop: match self.crop {
                    Some(Crop::Side(n)) => Some(n),
                    Some(Crop::Word(NoCrop::None)) => None,
                    None => self.layout.about().default_crop,
                },
                semantics: self.semantics,
                depth: self.depth,
                tfrecord_files: self.tfrecord_files,
            },
            imc: nrw_export::imc::ImcOptions {
                metres_per_unit: self.metres_per_unit,
            },
            licences: self
                .licences
                .as_ref()
                .map(|l| {
                    l.iter()
                        .map(|s| {
                            parse_licence(s).map_err(|e| {
                                PipelineError::config(Setting::Key("export.licences"), e)
                            })
                        })
                        .collect::<Result<Vec<_>>>()
                })
                .transpose()?,
            ..crate::export::official(dataset, out)
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::settings::tests::{declared_once, parse, table};

    #[test]
    fn every_flag_is_a_key_of_the_table_and_the_defaults_agree() {
        declared_once::<ExportSettings>();
    }

    #[test]
    fn the_command_line_and_the_table_say_the_same_thing_the_same_way() {
        let cli: ExportSettings = parse(&[
            "--layout",
            "megadepth",
            "--name",
            "trevi",
            "--crop",
            "none",
            "--no-semantics",
            "--depth",
            "inverse",
            "--shards",
            "4",
            "--metres-per-unit",
            "0.37",
        ]);
        let file: ExportSettings = table(
            "layout = \"megadepth\"\nname = \"trevi\"\ncrop = \"none\"\nsemantics = false\ndepth = \"inverse\"\ntfrecord_files = 4\nmetres_per_unit = 0.37\n",
        );
        assert_eq!(cli, file);
        let e = toml::from_str::<ExportSettings>("tfrecord_file = 2").unwrap_err();
        assert!(
            e.to_string().contains("unknown field `tfrecord_file`"),
            "{e}"
        );
        let bad = ExportSettings {
            metres_per_unit: Some(-1.0),
            ..ExportSettings::default()
        };
        let e = bad
            .config(&Location::parse("/tmp/ds"), &Location::parse("/tmp/out"))
            .unwrap_err();
        assert!(e.to_string().contains("export.metres_per_unit"), "{e}");
    }
}
