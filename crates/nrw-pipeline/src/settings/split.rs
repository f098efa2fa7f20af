//! `split`'s settings: the flags of `nrw-etl split` and the `[split]` table of a pipeline
//! file, one declaration.

use std::path::PathBuf;

use serde::{Deserialize, Serialize};

/// How the kept photos are split into train and val; with neither `val` nor `val_fraction`,
/// the paper's 100 validation photos.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize, clap::Args)]
#[serde(deny_unknown_fields, default)]
pub struct SplitSettings {
    /// Number of validation photos [default: 100, the paper's]; 0 puts every photo in
    /// training
    #[arg(long, conflicts_with = "val_fraction")]
    pub val: Option<usize>,
    /// Validation photos as a fraction (0 to 1) of the kept photos, at least one
    #[arg(long)]
    pub val_fraction: Option<f64>,
    /// Seed of the assignment: same seed, same split on any machine
    #[arg(long, default_value_t = SplitSettings::default().seed)]
    pub seed: u64,
    /// Take the sets from a published Phototourism split file (NeRF-W's SCENE.tsv: filename,
    /// id, split, dataset) instead of drawing them: `train` rows train, `test` rows are the
    /// val split; rows without an id are ignored, as nerf_pl does; a name that is not in the
    /// scene's model is refused. Replaces any earlier split
    #[arg(long, conflicts_with_all = ["val", "val_fraction", "seed"])]
    pub from_tsv: Option<PathBuf>,
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::settings::tests::{declared_once, parse, table};

    #[test]
    fn every_flag_is_a_key_of_the_table_and_the_defaults_agree() {
        declared_once::<SplitSettings>();
        assert_eq!(
            parse::<SplitSettings>(&["--val", "3", "--seed", "7"]),
            table("val = 3\nseed = 7")
        );
        let both = SplitSettings {
            val: Some(3),
            val_fraction: Some(0.5),
            ..SplitSettings::default()
        };
        let e = both
            .config(&nrw_dataset::Location::parse("/nowhere"))
            .unwrap_err();
        assert!(e.to_string().contains("split.val_fraction"), "{e}");
    }
}
