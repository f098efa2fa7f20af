//! `style`'s settings: the flags of `nrw-etl style` and the `[style]` table of a pipeline
//! file, one declaration. The weights are a file named on the command line (`style
//! --weights`, `run --vgg-weights`), never a table key: the tool never downloads them.

use nrw_style::{Preprocess, Tier};
use serde::{Deserialize, Serialize};

/// Photos per descriptor part by default (the unit of resumption and of work units).
pub const PART_PHOTOS: usize = 64;

/// How photos are described; a setting left out is the paper's reference tier.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, clap::Args)]
#[serde(deny_unknown_fields, default)]
pub struct StyleSettings {
    /// Descriptor tier: vgg16-<128|256|512|full>[-l<layers 1-5>], the same with vgg19,
    /// official[-N] (the published code's distance: N×N centre crop, default 512, no resize,
    /// v·2/255 − 1 into tensorflow-vgg's Caffe VGG16, per-layer mean squared Gram difference;
    /// needs that vgg16.npy; for the official export's dist_<name>.pckl), or color-stats (no
    /// weights needed)
    #[arg(long, default_value_t = StyleSettings::default().tier, value_parser = tier_name)]
    pub tier: String,
    /// Network input scaling: torchvision's ImageNet mean/std, or the official code's
    /// v/127.5 − 1 (recorded with the descriptors; the official tiers always use the published
    /// code's own)
    #[arg(long, value_enum, default_value = "imagenet")]
    pub preprocess: Scaling,
    /// Photos per descriptor part (the unit of resumption and of --unit work units)
    #[arg(long, default_value_t = PART_PHOTOS)]
    pub photos_per_part: usize,
}

/// `--tier` values: a tier's name, checked as the table's is in [`StyleSettings::config`].
fn tier_name(s: &str) -> std::result::Result<String, String> {
    s.parse::<Tier>().map(|_| s.to_string())
}

/// `preprocess` values.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "kebab-case")]
pub enum Scaling {
    /// RGB in [0,1], minus ImageNet mean, divided by std (what the weights were trained with)
    Imagenet,
    /// v/127.5 − 1, as the paper's official code scaled its inputs
    MinusOneToOne,
}

impl From<Scaling> for Preprocess {
    fn from(p: Scaling) -> Self {
        match p {
            Scaling::Imagenet => Preprocess::Imagenet,
            Scaling::MinusOneToOne => Preprocess::MinusOneToOne,
        }
    }
}

impl Default for StyleSettings {
    fn default() -> Self {
        StyleSettings {
            tier: Tier::reference().name(),
            preprocess: Scaling::Imagenet,
            photos_per_part: PART_PHOTOS,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::settings::tests::{declared_once, parse, table};

    #[test]
    fn every_flag_is_a_key_of_the_table_and_the_defaults_agree() {
        declared_once::<StyleSettings>();
        assert_eq!(
            parse::<StyleSettings>(&["--tier", "color-stats", "--preprocess", "minus-one-to-one"]),
            table("tier = \"color-stats\"\npreprocess = \"minus-one-to-one\"")
        );
        let bad = StyleSettings {
            tier: "vgg17".into(),
            ..StyleSettings::default()
        };
        let e = bad
            .config(&nrw_dataset::Location::parse("/ds"), None)
            .unwrap_err();
        assert!(e.to_string().contains("style.tier"), "{e}");
    }
}
