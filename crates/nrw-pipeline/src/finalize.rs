//! Finalize: merge the work units of ingest and style into the scene tables, descriptors and
//! manifest — the same bytes one process writes — refusing, by name, units that are missing or
//! ran with other parameters. Running it again changes nothing.

use std::collections::BTreeMap;
use std::path::Path;

use nrw_dataset::scene::VerdictKind;
use nrw_dataset::Store;

use nrw_dataset::units::{self, GroupRecord, UnitRecord};
use nrw_dataset::{FileEntry, ImageOutcome, Manifest, Tool, SCHEMA_VERSION, VERDICT_UNREADABLE};

use crate::error::{PipelineError, Result};

/// What finalize merged for ingest.
#[derive(Debug, Clone, serde::Serialize)]
pub struct IngestMerge {
    pub units: usize,
    pub registered: usize,
    pub kept: usize,
    pub too_small: usize,
    pub too_sparse: usize,
    /// Photos (or label maps) that could not be decoded whole: each is named in `warnings`.
    pub unreadable: usize,
    pub shards: usize,
    /// Empty ratio of the least empty render (what the filter would have to allow).
    pub least_empty: Option<f64>,
    pub warnings: Vec<String>,
}

/// What finalize merged for style.
#[derive(Debug, Clone, serde::Serialize)]
pub struct StyleMerge {
    pub units: usize,
    pub parts: usize,
    pub tier: String,
}

/// What `finalize` did; both `None` when there was nothing to merge.
#[derive(Debug, Clone, serde::Serialize)]
pub struct FinalizeSummary {
    pub dataset: String,
    pub ingest: Option<IngestMerge>,
    pub style: Option<StyleMerge>,
}

/// Merge whatever units wait in the dataset (ingest first, then style).
pub fn finalize(dataset: &Store) -> Result<FinalizeSummary> {
    let has = |stage| units::unit_records(dataset, stage).map(|r| !r.is_empty());
    for stage in [units::INGEST, units::STYLE] {
        if !dataset.list(&units::stage_dir(stage))?.is_empty() && !has(stage)? {
            return Err(units_error(dataset, format!(
                "{stage} units have started here but none has finished: run every unit (again; each resumes), then finalize"
            )));
        }
    }
    let ingest = if has(units::INGEST)? {
        Some(finalize_ingest(dataset)?)
    } else {
        None
    };
    let style = if has(units::STYLE)? {
        Some(finalize_style(dataset)?)
    } else {
        None
    };
    if ingest.is_none() && style.is_none() && !dataset.exists(Manifest::FILE)? {
        return Err(PipelineError::Units {
            dataset: dataset.root(),
            problem: "no unit has run here (no .units/ records and no manifest.json): run `nrw-etl ingest SCENE --out DATASET --shard I/N` first".into(),
        });
    }
    Ok(FinalizeSummary {
        dataset: dataset.root().display().to_string(),
        ingest,
        style,
    })
}

fn units_error(dataset: &Store, problem: String) -> PipelineError {
    PipelineError::Units {
        dataset: dataset.root(),
        problem,
    }
}

fn names(units: &[&UnitRecord]) -> String {
    let n: Vec<String> = units
        .iter()
        .map(|u| format!("{}/{}", u.index, u.count))
        .collect();
    format!(
        "unit{} {}",
        if n.len() > 1 { "s" } else { "" },
        n.join(", ")
    )
}

/// The first way `b` differs from `a`: a parameter (named with both values) or an input file.
fn difference(a: &UnitRecord, b: &UnitRecord) -> String {
    let keys: std::collections::BTreeSet<&String> =
        a.parameters.keys().chain(b.parameters.keys()).collect();
    for k in keys {
        let (va, vb) = (a.parameters.get(k), b.parameters.get(k));
        if va != vb {
            let show =
                |v: Option<&serde_json::Value>| v.map_or("(unset)".to_string(), |v| v.to_string());
            return format!("{k} = {} vs {k} = {}", show(vb), show(va));
        }
    }
    for ia in &a.inputs {
        match b.inputs.iter().find(|ib| ib.path == ia.path) {
            Some(ib) if ib.sha256 == ia.sha256 => {}
            Some(_) => return format!("input {} had other contents", ia.path),
            None => return format!("input {} was not read", ia.path),
        }
    }
    "other inputs".into()
}

/// Check a stage's unit records agree and are complete; returns one of them.
fn check_units(dataset: &Store, stage: &str) -> Result<UnitRecord> {
    let records = units::unit_records(dataset, stage)?;
    let first = records
        .first()
        .cloned()
        .ok_or_else(|| units_error(dataset, format!("no {stage} unit has run here")))?;
    let counts: std::collections::BTreeSet<usize> = records.iter().map(|r| r.count).collect();
    if counts.len() > 1 {
        let by = |n: usize| names(&records.iter().filter(|r| r.count == n).collect::<Vec<_>>());
        let shown: Vec<String> = counts.iter().map(|n| by(*n)).collect();
        return Err(units_error(dataset, format!(
            "{stage} units were run with different unit counts ({}); run every unit with the same --shard I/N count",
            shown.join("; ")
        )));
    }
    // The largest group of agreeing units is taken as the intended run.
    let mut by_fp: BTreeMap<&str, Vec<&UnitRecord>> = BTreeMap::new();
    for r in &records {
        by_fp.entry(r.fingerprint.as_str()).or_default().push(r);
    }
    if by_fp.len() > 1 {
        let mut groups: Vec<Vec<&UnitRecord>> = by_fp.into_values().collect();
        groups.sort_by_key(|g| std::cmp::Reverse(g.len()));
        let (main, odd) = (&groups[0], &groups[1]);
        return Err(units_error(
            dataset,
            format!(
            "{stage} {} ran with other parameters than {}: {}; run {} again with the same settings",
            names(odd),
            names(main),
            difference(main[0], odd[0]),
            if odd.len() > 1 { "them" } else { "it" },
        ),
        ));
    }
    let missing: Vec<String> = (0..first.count)
        .filter(|i| !records.iter().any(|r| r.index == *i))
        .map(|i| format!("{i}/{}", first.count))
        .collect();
    if !missing.is_empty() {
        return Err(units_error(dataset, format!(
            "{stage} unit{} {} {} not run (or not finished): run {} with --shard, then finalize again",
            if missing.len() > 1 { "s" } else { "" },
            missing.join(", "),
            if missing.len() > 1 { "have" } else { "has" },
            if missing.len() > 1 { "them" } else { "it" },
        )));
    }
    Ok(first)
}

fn count(outcomes: &BTreeMap<u32, ImageOutcome>, verdict: &str) -> usize {
    outcomes.values().filter(|o| o.verdict == verdict).count()
}

/// Merge ingest's units: scene tables and manifest from the group records, stale shards
/// (of runs with other parameters) removed.
pub fn finalize_ingest(dataset: &Store) -> Result<IngestMerge> {
    let unit = check_units(dataset, units::INGEST)?;
    let mut outcomes = BTreeMap::new();
    let mut photos = BTreeMap::new();
    let mut shards: Vec<FileEntry> = Vec::new();
    for g in 0..unit.groups {
        let rel = units::group_record_path(units::INGEST, g);
        let r: Option<GroupRecord> = units::read_record(dataset, &rel)?;
        let r = r
            .filter(|r| r.fingerprint == unit.fingerprint)
            .ok_or_else(|| {
                units_error(
                    dataset,
                    format!(
                "ingest group {g} (unit {}/{}) has no record of this run: run that unit again",
                g % unit.count,
                unit.count
            ),
                )
            })?;
        shards.extend(r.shard);
        for i in r.images {
            photos.insert(i.image_id, i.photo_size);
            outcomes.insert(i.image_id, i.outcome);
        }
    }
    let scene = unit
        .scene
        .clone()
        .ok_or_else(|| units_error(dataset, "ingest unit record names no scene".into()))?;
    let (mut rec, changed) = crate::ingest::reread_model(&scene, &unit.inputs)?;
    if let Some(f) = changed {
        return Err(units_error(
            dataset,
            format!(
                "{} changed since the ingest units read it: run the units again",
                f.display()
            ),
        ));
    }
    // `ingest --undistort` stored the undistorted PINHOLE cameras: the scene tables list those.
    if let Some(v) = unit.parameters.get("undistort") {
        let options = crate::ingest::undistort_from_parameters(v).ok_or_else(|| {
            units_error(
                dataset,
                format!("ingest unit record: unreadable `undistort` parameters {v}"),
            )
        })?;
        crate::ingest::undistort_model(&mut rec, &options, Path::new(&scene.model_dir))?;
    }
    // Shards of an earlier run with other parameters must not linger next to these.
    for stale in nrw_dataset::views::stale_shards(dataset, &shards)? {
        dataset.delete(&stale)?;
    }
    let mut tables = nrw_dataset::write_scene_tables(dataset, &rec, &photos, &outcomes)?;
    tables.extend(shards.iter().cloned());
    // A split from an earlier run stays (split assigns only new photos when run again).
    if dataset.exists(nrw_dataset::split::SPLITS_TABLE)? {
        tables.push(FileEntry::of(dataset, nrw_dataset::split::SPLITS_TABLE)?);
    }
    let mut warnings = unit.warnings.clone();
    for (id, o) in outcomes
        .iter()
        .filter(|(_, o)| o.verdict == VERDICT_UNREADABLE)
    {
        warnings.push(format!(
            "{}: unreadable, left out: {}",
            rec.images.get(id).map_or("?", |i| i.name.as_str()),
            o.detail.as_deref().unwrap_or("")
        ));
    }
    // Triplets depend on which views survive: a new ingest makes them stale.
    let stale = nrw_dataset::triplets::TRIPLETS_TABLE;
    if dataset.exists(stale)? {
        dataset.delete(stale)?;
        warnings.push(format!(
            "{}: removed (stale after a new ingest); run `nrw-etl triplets` again",
            dataset.name(stale).display()
        ));
    }
    let manifest = Manifest {
        schema_version: SCHEMA_VERSION,
        tool: Tool {
            name: "nrw-etl".into(),
            version: env!("CARGO_PKG_VERSION").into(),
        },
        scene,
        inputs: unit.inputs.clone(),
        parameters: unit.parameters.clone(),
        tables,
        warnings: warnings.clone(),
    };
    manifest.write(dataset)?;
    close_stage(dataset, units::INGEST)?;
    Ok(IngestMerge {
        units: unit.count,
        registered: outcomes.len(),
        kept: count(&outcomes, nrw_dataset::scene::VERDICT_KEPT),
        too_small: count(&outcomes, VerdictKind::TooSmall.name()),
        too_sparse: count(&outcomes, VerdictKind::TooSparse.name()),
        unreadable: count(&outcomes, VERDICT_UNREADABLE),
        shards: shards.len(),
        least_empty: outcomes
            .values()
            .filter_map(|o| o.empty_ratio)
            .reduce(f64::min),
        warnings,
    })
}

/// Record the units' summed time as the stage's, and remove their records (merged).
fn close_stage(dataset: &Store, stage: &str) -> Result<()> {
    let seconds: f64 = units::unit_records(dataset, stage)?
        .iter()
        .map(|r| r.seconds)
        .sum();
    crate::qa::record_timing(dataset, stage, seconds);
    Ok(units::clear_stage(dataset, stage)?)
}

/// Merge style's units: every part present and of the units' kind, parts past the end
/// (of an earlier, larger run) removed, all parts listed in the manifest.
pub fn finalize_style(dataset: &Store) -> Result<StyleMerge> {
    let unit = check_units(dataset, units::STYLE)?;
    let kind = crate::style::kind_of(&unit);
    for k in 0..unit.groups {
        let rel = nrw_dataset::descriptors::part_path(k);
        // Only the kind columns: the descriptors themselves are megabytes per photo.
        let ok = dataset.exists(&rel)?
            && nrw_dataset::descriptors::read_kinds(dataset, &rel)?
                .iter()
                .all(|k| *k == kind);
        if !ok {
            return Err(units_error(
                dataset,
                format!(
                    "{rel} (style unit {}/{}) is missing or of another kind: run that unit again",
                    k % unit.count,
                    unit.count
                ),
            ));
        }
    }
    let mut manifest = Manifest::read(dataset)?;
    crate::style::list_parts(dataset, &mut manifest, unit.groups)?;
    manifest.write(dataset)?;
    close_stage(dataset, units::STYLE)?;
    Ok(StyleMerge {
        units: unit.count,
        parts: unit.groups,
        tier: kind.tier,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_renderers_verdicts_are_words_of_the_images_table() {
        use nrw_render::verdict::Verdict;
        for (v, kind) in [
            (Verdict::Kept { empty_ratio: 0.1 }, VerdictKind::Kept),
            (
                Verdict::TooSmall { shorter_side_px: 9 },
                VerdictKind::TooSmall,
            ),
            (
                Verdict::TooSparse { empty_ratio: 0.9 },
                VerdictKind::TooSparse,
            ),
        ] {
            assert_eq!(VerdictKind::of(v.name()), Some(kind));
        }
        for k in VerdictKind::ALL {
            assert_eq!(VerdictKind::of(k.name()), Some(k));
        }
    }
}
