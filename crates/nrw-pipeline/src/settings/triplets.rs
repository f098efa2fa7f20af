//! `triplets`' settings: the flags of `nrw-etl triplets` and the `[triplets]` table of a
//! pipeline file, one declaration.

use serde::{Deserialize, Serialize};

/// How the style triplets are mined; a setting left out is the paper's (k = 20, exact, the
/// training split).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, clap::Args)]
#[serde(deny_unknown_fields, default)]
pub struct TripletsSettings {
    /// Neighbours per anchor, nearest and furthest (the paper: 20)
    #[arg(long, default_value_t = TripletsSettings::default().k)]
    pub k: usize,
    /// Draw anchors and neighbours from every split (default: the training split only, so
    /// validation photos never appear)
    #[arg(long)]
    pub all_splits: bool,
    /// Approximate: candidates from a PCA projection to this many dimensions, re-ranked
    /// exactly (for large N; recall against the exact path is measured and stored when N ≤
    /// --check-up-to)
    #[arg(long)]
    pub pca: Option<usize>,
    /// Measure the approximate path's recall against the exact one up to this many photos
    #[arg(long, default_value_t = TripletsSettings::default().check_up_to)]
    pub check_up_to: usize,
}

impl Default for TripletsSettings {
    /// The paper's: k = 20, exact, the training split.
    fn default() -> Self {
        TripletsSettings {
            k: 20,
            all_splits: false,
            pca: None,
            check_up_to: 20_000,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::settings::tests::{declared_once, parse, table};

    #[test]
    fn every_flag_is_a_key_of_the_table_and_the_defaults_agree() {
        declared_once::<TripletsSettings>();
        assert_eq!(
            parse::<TripletsSettings>(&["--k", "5", "--pca", "16"]),
            table("k = 5\npca = 16")
        );
    }
}
