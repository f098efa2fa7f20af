//! `nrw-etl triplets`: for each anchor photo, its k nearest and k furthest photos under the
//! style distance, from the descriptors `nrw-etl style` wrote.

use std::collections::BTreeMap;
use std::path::PathBuf;

use clap::Args;
use nrw_dataset::triplets::{write_triplets, TripletInfo, TripletRow, TRIPLETS_TABLE};
use nrw_dataset::Manifest;

use crate::error::{EtlError, Result};

/// Arguments of `triplets`.
#[derive(Debug, Args)]
pub struct TripletsArgs {
    /// Dataset folder with descriptors (run `nrw-etl style` first)
    pub dataset: PathBuf,
    /// Neighbours per anchor, nearest and furthest (the paper: 20)
    #[arg(long, default_value_t = 20)]
    pub k: usize,
    /// Draw anchors and neighbours from every split (default: the training split only, so
    /// validation photos never appear)
    #[arg(long)]
    pub all_splits: bool,
    /// Approximate: candidates from a PCA projection to this many dimensions, re-ranked
    /// exactly (for large N; recall against the exact path is measured and stored when N ≤ --check-up-to)
    #[arg(long)]
    pub pca: Option<usize>,
    /// Measure the approximate path's recall against the exact one up to this many photos
    #[arg(long, default_value_t = 20_000)]
    pub check_up_to: usize,
}

/// Run `triplets`.
pub fn run(args: &TripletsArgs) -> Result<()> {
    super::qa::timed(Some(args.dataset.as_path()), "triplets", || run_stage(args))
}

fn run_stage(args: &TripletsArgs) -> Result<()> {
    super::require_views(&args.dataset)?;
    let mut manifest = Manifest::read(&args.dataset)?;
    let Some((kind, rows)) = nrw_dataset::descriptors::read_all(&args.dataset)? else {
        return Err(EtlError::Usage(format!(
            "{}: no descriptors; run `nrw-etl style {}` first",
            args.dataset.display(),
            args.dataset.display()
        )));
    };
    let splits = nrw_dataset::split::read_splits(&args.dataset)?;
    let scope = if args.all_splits || splits.is_empty() {
        "all"
    } else {
        "train"
    };
    let allowed: Option<BTreeMap<u32, ()>> = (scope == "train").then(|| {
        splits
            .iter()
            .filter(|a| a.split == "train")
            .map(|a| (a.image_id, ()))
            .collect()
    });
    if let Some(a) = &allowed {
        let described: std::collections::BTreeSet<u32> = rows.iter().map(|r| r.image_id).collect();
        if let Some(missing) = a.keys().find(|id| !described.contains(id)) {
            return Err(EtlError::Usage(format!(
                "{}: training photo {missing} has no descriptor; run `nrw-etl style` again",
                args.dataset.display()
            )));
        }
    }
    let rows: Vec<_> = rows
        .into_iter()
        .filter(|r| allowed.as_ref().is_none_or(|a| a.contains_key(&r.image_id)))
        .collect();
    if args.k + 1 > rows.len() {
        return Err(EtlError::Usage(format!(
            "{}: --k {} needs at least {} photos in scope {scope}, found {}; use --k {} or fewer",
            args.dataset.display(),
            args.k,
            args.k + 1,
            rows.len(),
            rows.len().saturating_sub(1)
        )));
    }
    let desc: Vec<Vec<f32>> = rows.iter().map(|r| r.descriptor.clone()).collect();
    let name_err = |e: nrw_knn::KnnError| match e {
        nrw_knn::KnnError::NotFinite { row, index, value } => EtlError::Usage(format!(
            "{}: descriptor of photo {} (image {}) has value {value} at {index}: not finite",
            args.dataset.display(),
            rows[row].name,
            rows[row].image_id
        )),
        other => EtlError::Usage(format!("{}: {other}", args.dataset.display())),
    };
    let (found, method, recall) = match args.pca {
        None => (
            nrw_knn::exact(&desc, args.k).map_err(name_err)?,
            "exact".to_string(),
            None,
        ),
        Some(rank) => {
            let approx =
                nrw_knn::approx::approximate(&desc, args.k, rank, 3, 0).map_err(name_err)?;
            let recall = (desc.len() <= args.check_up_to)
                .then(|| {
                    nrw_knn::exact(&desc, args.k).map(|e| nrw_knn::approx::recall(&e, &approx))
                })
                .transpose()
                .map_err(name_err)?;
            if let Some((n, f)) = recall {
                eprintln!(
                    "pca-{rank}: recall@{} against the exact path: nearest {n:.3}, furthest {f:.3}",
                    args.k
                );
            }
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
        tier: kind.tier.clone(),
        method: method.clone(),
        scope: scope.into(),
        recall,
    };
    let entry = write_triplets(&args.dataset, &info, &table)?;
    manifest.tables.retain(|t| t.path != TRIPLETS_TABLE);
    manifest.tables.push(entry);
    manifest
        .parameters
        .insert("triplets_k".into(), args.k.into());
    manifest.write(&args.dataset)?;
    println!(
        "triplets {}: {} anchors × {} nearest / {} furthest ({}, scope {scope}, {method})",
        args.dataset.display(),
        table.len(),
        args.k,
        args.k,
        kind.tier
    );
    Ok(())
}

/// The style distance matrix of the given views in that order, from the dataset's `official`
/// descriptors (`dist_<name>.pckl` of the official export), or None when the dataset holds
/// descriptors of another tier or none. `crop` is the export's: a crop smaller than the
/// descriptors' would make the published code crop the exported photos differently.
pub fn official_distance_matrix(
    dataset: &std::path::Path,
    ids: &[u32],
    crop: Option<u32>,
) -> nrw_dataset::Result<Option<Vec<f64>>> {
    let Some((kind, rows)) = nrw_dataset::descriptors::read_all(dataset)? else {
        return Ok(None);
    };
    let Some(nrw_style::Tier::Official { crop: tier_crop }) = nrw_style::Tier::parse(&kind.tier)
    else {
        return Ok(None);
    };
    let field = |problem: String| nrw_dataset::DatasetError::Value {
        path: dataset.join(nrw_dataset::descriptors::DESCRIPTORS_DIR),
        record: format!("tier {}", kind.tier),
        field: "descriptor".into(),
        problem,
    };
    if let Some(c) = crop.filter(|&c| c < tier_crop) {
        return Err(field(format!(
            "the descriptors are of a {tier_crop}×{tier_crop} crop but the export crops to {c}×{c}; describe with --tier official-{c} or export with a larger --crop"
        )));
    }
    let by_id: std::collections::HashMap<u32, &[f32]> = rows
        .iter()
        .map(|r| (r.image_id, r.descriptor.as_slice()))
        .collect();
    let picked: Vec<&[f32]> = ids
        .iter()
        .map(|id| {
            by_id.get(id).copied().ok_or_else(|| {
                field(format!(
                    "image {id} has no descriptor; rerun `nrw-etl style` on the dataset"
                ))
            })
        })
        .collect::<nrw_dataset::Result<_>>()?;
    Ok(Some(nrw_knn::distance_matrix(&picked)))
}
