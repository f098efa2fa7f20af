//! Triplets: for each anchor photo, its k nearest and k furthest photos under the style
//! distance, from the descriptors style wrote; and the official export's distance matrix.

use nrw_dataset::split::TRAIN;
use std::collections::{BTreeMap, BTreeSet};

use nrw_dataset::descriptors::{Entry, Index};
use nrw_dataset::triplets::{write_triplets, TripletInfo, TripletRow};
use nrw_dataset::{Manifest, Store};

use crate::error::{PipelineError, Result, Setting};
use crate::settings::triplets::TripletsSettings;

/// A triplets run: the dataset, and the settings it runs with (declared once, in
/// [`crate::settings::triplets`]).
#[derive(Debug, Clone)]
pub struct TripletsConfig {
    pub dataset: nrw_dataset::Location,
    pub settings: TripletsSettings,
}

impl TripletsConfig {
    /// The paper's triplets of a dataset.
    pub fn new(dataset: impl Into<nrw_dataset::Location>) -> TripletsConfig {
        TripletsConfig {
            dataset: dataset.into(),
            settings: TripletsSettings::default(),
        }
    }
}

impl TripletsSettings {
    /// The triplets of `dataset` these settings ask for.
    pub fn config(&self, dataset: &nrw_dataset::Location) -> TripletsConfig {
        TripletsConfig {
            dataset: dataset.clone(),
            settings: self.clone(),
        }
    }
}

/// What triplets wrote.
#[derive(Debug, Clone, serde::Serialize)]
pub struct TripletsSummary {
    pub anchors: usize,
    pub k: usize,
    pub tier: String,
    pub scope: String,
    pub method: String,
    /// Recall (nearest, furthest) of the approximate path against the exact one.
    pub recall: Option<(f64, f64)>,
}

/// Refuse stages that need views when ingest kept none, saying so.
pub fn require_views(dataset: &Store) -> Result<nrw_dataset::reader::Dataset> {
    let ds = nrw_dataset::reader::Dataset::open(dataset)?;
    if ds.is_empty() {
        let registered = nrw_dataset::scene::read_verdicts(dataset)?.len();
        return Err(PipelineError::dataset(dataset.root(), format!(
            "no kept view: ingest dropped all {registered} registered photos (`nrw-etl inspect {}` shows why)",
            dataset.root()
        )));
    }
    Ok(ds)
}

/// The photos in scope: the training split unless `all_splits` (or no split yet).
fn in_scope(
    cfg: &TripletsConfig,
    store: &Store,
    ids: &BTreeSet<u32>,
) -> Result<(&'static str, Option<BTreeSet<u32>>)> {
    let splits = nrw_dataset::split::read_splits(store)?;
    if cfg.settings.all_splits || splits.is_empty() {
        return Ok(("all", None));
    }
    let train: BTreeSet<u32> = splits
        .iter()
        .filter(|a| a.split == TRAIN)
        .map(|a| a.image_id)
        .collect();
    if let Some(missing) = train.iter().find(|id| !ids.contains(id)) {
        return Err(PipelineError::dataset(
            &cfg.dataset,
            format!("training photo {missing} has no descriptor; run `nrw-etl style` again"),
        ));
    }
    Ok((TRAIN, Some(train)))
}

/// Compute and write the triplet table.
pub fn triplets(cfg: &TripletsConfig) -> Result<TripletsSummary> {
    let store = &Store::open(&cfg.dataset)?;
    crate::timing::timed(store, "triplets", || run(cfg, store))
}

/// A problem of the descriptors themselves, naming the photo (row `row` of `entries`).
fn descriptor_error(
    dataset: &nrw_dataset::Location,
    entries: &[Entry],
    e: nrw_knn::KnnError,
) -> PipelineError {
    let photo = |row: usize| {
        entries.get(row).map_or(format!("row {row}"), |r| {
            format!("photo {} (image {})", r.name, r.image_id)
        })
    };
    match e {
        nrw_knn::KnnError::NotFinite { row, index, value } => PipelineError::dataset(
            dataset,
            format!(
                "descriptor of {} has value {value} at {index}: not finite",
                photo(row)
            ),
        ),
        nrw_knn::KnnError::Dimension { row, len, dim } => PipelineError::dataset(
            dataset,
            format!(
                "descriptor of {} has {len} values, the others {dim}",
                photo(row)
            ),
        ),
        other => PipelineError::dataset(dataset, other.to_string()),
    }
}

/// The descriptors of `index` copied once into a scratch file (chunk-major, see
/// `nrw_knn::spill`), read from the dataset a few rows at a time.
pub(crate) fn spill(dataset: &Store, index: &Index) -> Result<nrw_knn::Spilled> {
    let n = index.entries.len();
    nrw_knn::Spilled::from_source(n, |sink| index.visit(dataset, sink)).map_err(|e| match e {
        nrw_knn::StreamError::Knn(e) => descriptor_error(&dataset.root(), &index.entries, e),
        nrw_knn::StreamError::Source(e) => e.into(),
        scratch => PipelineError::dataset(dataset.root(), scratch.to_string()),
    })
}

fn run(cfg: &TripletsConfig, store: &Store) -> Result<TripletsSummary> {
    require_views(store)?;
    let mut manifest = Manifest::read(store)?;
    let Some(mut index) = Index::read(store)? else {
        return Err(PipelineError::dataset(
            &cfg.dataset,
            format!("no descriptors; run `nrw-etl style {}` first", cfg.dataset),
        ));
    };
    let described: BTreeSet<u32> = index.entries.iter().map(|r| r.image_id).collect();
    let (scope, allowed) = in_scope(cfg, store, &described)?;
    index.retain(|r| allowed.as_ref().is_none_or(|a| a.contains(&r.image_id)));
    let rows = &index.entries;
    if cfg.settings.k + 1 > rows.len() {
        return Err(PipelineError::config(Setting::Key("triplets.k"), format!(
            "{} needs at least {} photos in scope {scope}, found {}; use {} {} or fewer (dataset {})",
            cfg.settings.k,
            cfg.settings.k + 1,
            rows.len(),
            Setting::Key("triplets.k"),
            rows.len().saturating_sub(1),
            cfg.dataset
        )));
    }
    let desc = spill(store, &index)?;
    let name_err = |e| descriptor_error(&cfg.dataset, rows, e);
    let (found, method, recall) = match cfg.settings.pca {
        None => (
            nrw_knn::exact_spilled(&desc, cfg.settings.k).map_err(name_err)?,
            "exact".to_string(),
            None,
        ),
        Some(rank) => {
            let approx = nrw_knn::approx::approximate_spilled(&desc, cfg.settings.k, rank, 3, 0)
                .map_err(name_err)?;
            let recall = (desc.len() <= cfg.settings.check_up_to)
                .then(|| {
                    nrw_knn::exact_spilled(&desc, cfg.settings.k)
                        .map(|e| nrw_knn::approx::recall(&e, &approx))
                })
                .transpose()
                .map_err(name_err)?;
            (approx, format!("pca-{rank}"), recall)
        }
    };
    let table: Vec<TripletRow> = rows
        .iter()
        .zip(&found)
        .map(|(r, n)| TripletRow {
            anchor_id: r.image_id,
            anchor_name: r.name.clone(),
            nearest_ids: n.nearest.iter().map(|p| rows[p.0].image_id).collect(),
            nearest_d2: n.nearest.iter().map(|p| p.1).collect(),
            furthest_ids: n.furthest.iter().map(|p| rows[p.0].image_id).collect(),
            furthest_d2: n.furthest.iter().map(|p| p.1).collect(),
        })
        .collect();
    let info = TripletInfo {
        tier: index.kind.tier.clone(),
        method: method.clone(),
        scope: scope.into(),
        recall,
    };
    manifest.replace_table(write_triplets(store, &info, &table)?);
    manifest
        .parameters
        .insert("triplets_k".into(), cfg.settings.k.into());
    manifest.write(store)?;
    Ok(TripletsSummary {
        anchors: table.len(),
        k: cfg.settings.k,
        tier: index.kind.tier,
        scope: scope.into(),
        method,
        recall,
    })
}

/// Bytes of pair state while a block of distance-matrix rows is summed (80 bytes a value).
const DIST_BLOCK_BYTES: usize = 256 << 20;

/// The style distance matrix of the given views in that order, from the dataset's `official`
/// descriptors (`dist_<name>.pckl` of the official export), as blocks of rows; None when the
/// dataset holds descriptors of another tier or none (known from the index, before any value
/// is read). `crop` is the export's: a crop smaller than the descriptors' would make the
/// published code crop the exported photos differently.
pub fn official_distance_matrix(
    dataset: &Store,
    ids: &[u32],
    crop: Option<u32>,
) -> nrw_dataset::Result<Option<nrw_export::DistRows>> {
    let Some(mut index) = Index::read(dataset)? else {
        return Ok(None);
    };
    let Some(nrw_style::Tier::Official { crop: tier_crop }) =
        nrw_style::Tier::parse(&index.kind.tier)
    else {
        return Ok(None);
    };
    let tier = index.kind.tier.clone();
    let field = |problem: String| nrw_dataset::DatasetError::Value {
        path: dataset.name(nrw_dataset::descriptors::DESCRIPTORS_DIR),
        record: format!("tier {tier}"),
        field: "descriptor".into(),
        problem,
    };
    if let Some(c) = crop.filter(|&c| c < tier_crop) {
        return Err(field(format!(
            "the descriptors are of a {tier_crop}×{tier_crop} crop but the export crops to {c}×{c}; describe with {} official-{c} or export with a larger {}",
            Setting::Key("style.tier"),
            Setting::Key("export.crop")
        )));
    }
    let want: BTreeMap<u32, usize> = ids.iter().enumerate().map(|(p, id)| (*id, p)).collect();
    index.retain(|e| want.contains_key(&e.image_id));
    if let Some(id) = ids.iter().find(|id| {
        index
            .entries
            .binary_search_by_key(*id, |e| e.image_id)
            .is_err()
    }) {
        return Err(field(format!(
            "image {id} has no descriptor; rerun `nrw-etl style` on the dataset"
        )));
    }
    let order: Vec<usize> = index.entries.iter().map(|e| want[&e.image_id]).collect();
    let spilled = nrw_knn::Spilled::from_source(ids.len(), |sink| {
        index.visit(dataset, &mut |p, v| sink(order[p], v))
    })
    .map_err(|e| match e {
        nrw_knn::StreamError::Source(e) => e,
        other => field(other.to_string()),
    })?;
    let block = (DIST_BLOCK_BYTES / (80 * ids.len().max(1))).max(1);
    Ok(Some((
        block,
        Box::new(move |rows| Ok(spilled.distance_rows(rows))),
    )))
}
