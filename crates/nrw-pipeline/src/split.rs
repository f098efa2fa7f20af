//! Split: a reproducible, incremental train/validation assignment of the kept photos.

use crate::settings::split::SplitSettings;
use nrw_dataset::split::VAL;

use nrw_dataset::split::{assign_grouped, read_splits, write_splits};
use nrw_dataset::{Manifest, Store};

use crate::error::{PipelineError, Result, Setting};

/// A split: the dataset, its settings (declared once, in [`crate::settings::split`]) and
/// the count of validation photos they come to.
#[derive(Debug, Clone)]
pub struct SplitConfig {
    pub dataset: nrw_dataset::Location,
    /// Validation photos (`settings`' count, or its fraction of the kept photos); 0 puts
    /// every photo in training.
    pub val: usize,
    pub settings: SplitSettings,
}

impl SplitConfig {
    /// The paper's split of a dataset: 100 validation photos, seed 0.
    pub fn new(dataset: impl Into<nrw_dataset::Location>) -> SplitConfig {
        SplitConfig {
            dataset: dataset.into(),
            val: PAPER_VAL,
            settings: SplitSettings::default(),
        }
    }
}

/// The paper's validation photos.
pub const PAPER_VAL: usize = 100;

impl SplitSettings {
    /// Refused before any work: a fraction outside [0, 1), or both a count and a fraction.
    pub fn check(&self) -> Result<()> {
        if let Some(f) = self.val_fraction.filter(|f| !(0.0..1.0).contains(f)) {
            return Err(PipelineError::config(
                Setting::Key("split.val_fraction"),
                format!("is {f}: a fraction of the kept photos, at least 0 and below 1"),
            ));
        }
        if self.val.is_some() && self.val_fraction.is_some() {
            return Err(PipelineError::config(
                Setting::Key("split.val"),
                format!(
                    "and {} were both given: give exactly one, a count or a fraction",
                    Setting::Key("split.val_fraction")
                ),
            ));
        }
        Ok(())
    }

    /// The validation photos asked for as a count (`val`, or the paper's 100 when neither
    /// `val` nor `val_fraction` is given); `None` for a fraction or a split file.
    pub fn val_count(&self) -> Option<usize> {
        match (self.val, self.val_fraction, &self.from_tsv) {
            (_, _, Some(_)) | (None, Some(_), _) => None,
            (Some(v), _, _) => Some(v),
            (None, None, None) => Some(PAPER_VAL),
        }
    }

    /// The split of `dataset` these settings ask for: a fraction becomes a count of the
    /// dataset's kept photos here, for the CLI and pipeline files alike.
    pub fn config(&self, dataset: &nrw_dataset::Location) -> Result<SplitConfig> {
        self.check()?;
        let val = match (self.val, self.val_fraction) {
            (Some(v), _) => v,
            (None, Some(f)) => {
                let store = nrw_dataset::Store::open(dataset)?;
                let kept = nrw_dataset::reader::Dataset::open(store)?.len();
                ((kept as f64 * f) as usize).max(1)
            }
            (None, None) => PAPER_VAL,
        };
        Ok(SplitConfig {
            dataset: dataset.clone(),
            val,
            settings: self.clone(),
        })
    }
}

/// What split assigned.
#[derive(Debug, Clone, serde::Serialize)]
pub struct SplitSummary {
    pub train: usize,
    pub val: usize,
    /// Photos that kept their earlier assignment.
    pub kept: usize,
    pub new: usize,
    /// Photos assigned earlier that are no longer kept (removed from the split).
    pub gone: Vec<String>,
    /// Photos a split file lists that ingest did not keep (not assigned).
    pub listed_not_kept: Vec<String>,
    /// Kept photos a split file does not list (in no split, as in nerf_pl).
    pub unlisted: usize,
    /// Near-duplicate groups (scene/duplicates.parquet) the split holds.
    pub duplicate_groups: usize,
    /// Groups with members on both sides (a published split, or one assigned before ingest
    /// looked for copies): each group's members' names.
    pub straddling: Vec<Vec<String>>,
}

/// Each kept photo's near-duplicate group, by name, and how many groups there are.
fn duplicate_groups(store: &Store) -> Result<(std::collections::BTreeMap<String, u32>, usize)> {
    let members = nrw_dataset::duplicates::read_duplicates(store)?;
    let groups = nrw_dataset::duplicates::group_of(&members);
    let n = groups
        .values()
        .collect::<std::collections::BTreeSet<_>>()
        .len();
    Ok((groups, n))
}

fn straddling(
    rows: &[nrw_dataset::split::Assignment],
    groups: &std::collections::BTreeMap<String, u32>,
) -> Vec<Vec<String>> {
    nrw_dataset::split::straddling(rows, groups)
        .into_iter()
        .map(|(_, names)| names)
        .collect()
}

/// Largest split file read: a Phototourism tsv is a few hundred kB.
const MAX_TSV_BYTES: u64 = 1 << 30;

/// Assign exactly the train/test sets of a published split file.
fn split_from_tsv(tsv: &std::path::Path, store: &Store) -> Result<SplitSummary> {
    let io = |e| PipelineError::from(nrw_dataset::DatasetError::io(tsv, e));
    let len = std::fs::metadata(tsv).map_err(io)?.len();
    if len > MAX_TSV_BYTES {
        return Err(PipelineError::dataset(
            tsv,
            format!("{len} bytes is more than a split file's {MAX_TSV_BYTES}"),
        ));
    }
    let bytes = std::fs::read(tsv).map_err(io)?;
    let text = std::str::from_utf8(&bytes)
        .map_err(|e| PipelineError::dataset(tsv, format!("not UTF-8 text: {e}")))?;
    let rows = nrw_dataset::split::parse_phototourism_tsv(tsv, text)?;
    let verdicts = nrw_dataset::scene::read_verdicts(store)?;
    let kept = verdicts
        .iter()
        .filter(|(_, _, v)| v == nrw_dataset::scene::VERDICT_KEPT)
        .map(|(id, _, _)| *id)
        .collect();
    let model: Vec<(u32, String)> = verdicts.into_iter().map(|(i, n, _)| (i, n)).collect();
    let a = nrw_dataset::split::assign_from_tsv(tsv, &rows, &model, &kept)?;
    let (groups, duplicate_groups) = duplicate_groups(store)?;
    let mut manifest = Manifest::read(store)?;
    manifest.replace_table(write_splits(store, &a.rows)?);
    manifest.parameters.insert(
        "split_from_tsv".into(),
        serde_json::json!({
            "file": tsv.file_name().map(|n| n.to_string_lossy().into_owned()),
            "sha256": crate::sha256_hex(&bytes),
        }),
    );
    manifest.parameters.remove("split_val");
    manifest.write(store)?;
    let val = a.rows.iter().filter(|r| r.split == VAL).count();
    Ok(SplitSummary {
        train: a.rows.len() - val,
        val,
        kept: 0,
        new: a.rows.len(),
        gone: Vec::new(),
        straddling: straddling(&a.rows, &groups),
        listed_not_kept: a.not_kept,
        unlisted: a.unlisted,
        duplicate_groups,
    })
}

/// Assign the kept photos and list the table in the manifest.
pub fn split(cfg: &SplitConfig) -> Result<SplitSummary> {
    let store = &Store::open(&cfg.dataset)?;
    crate::timing::timed(store, "split", || {
        if let Some(tsv) = &cfg.settings.from_tsv {
            return split_from_tsv(tsv, store);
        }
        let mut manifest = Manifest::read(store)?;
        let kept: Vec<(u32, String)> = nrw_dataset::scene::read_verdicts(store)?
            .into_iter()
            .filter(|(_, _, v)| v == nrw_dataset::scene::VERDICT_KEPT)
            .map(|(id, name, _)| (id, name))
            .collect();
        let previous = read_splits(store)?;
        let (groups, duplicate_groups) = duplicate_groups(store)?;
        let (rows, change) = assign_grouped(&kept, &previous, cfg.val, cfg.settings.seed, &groups)
            .map_err(|e| PipelineError::dataset(&cfg.dataset, e.to_string()))?;
        manifest.replace_table(write_splits(store, &rows)?);
        manifest
            .parameters
            .insert("split_val".into(), cfg.val.into());
        manifest.write(store)?;
        let val = rows.iter().filter(|a| a.split == VAL).count();
        Ok(SplitSummary {
            train: rows.len() - val,
            val,
            kept: change.kept_train + change.kept_val,
            new: change.new_train + change.new_val,
            gone: change.gone,
            listed_not_kept: Vec::new(),
            unlisted: 0,
            duplicate_groups,
            straddling: straddling(&rows, &groups),
        })
    })
}
