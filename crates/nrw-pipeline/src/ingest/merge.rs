//! Ingest's merge: the units' group records into the scene tables and the manifest (what
//! `finalize` runs for ingest, and a whole ingest runs at its end).

use nrw_dataset::provenance::{from_parameters, IngestParameters};
use std::collections::BTreeMap;
use std::path::Path;

use nrw_dataset::photo_info::PhotoRecord;
use nrw_dataset::scene::ImageVerdict;
use nrw_dataset::units::{self, GroupRecord, UnitRecord};
use nrw_dataset::{
    FileEntry, ImageOutcome, Manifest, Store, Tool, SCHEMA_VERSION, VERDICT_UNREADABLE,
};

use crate::error::Result;
use crate::units::{check_units, close_stage, units_error};

/// What finalize merged for ingest.
#[derive(Debug, Clone, serde::Serialize)]
pub struct IngestMerge {
    pub units: usize,
    pub registered: usize,
    pub kept: usize,
    pub too_small: usize,
    pub too_sparse: usize,
    /// Photos less sharp than `--min-sharpness`.
    pub too_blurry: usize,
    /// Photos (or label maps) that could not be decoded whole: each is named in `warnings`.
    pub unreadable: usize,
    /// Groups of kept photos that are one picture, and the photos in them.
    pub duplicate_groups: usize,
    pub duplicate_photos: usize,
    pub shards: usize,
    /// Empty ratio of the least empty render (what the filter would have to allow).
    pub least_empty: Option<f64>,
    pub warnings: Vec<String>,
}

fn count(outcomes: &BTreeMap<u32, ImageOutcome>, verdict: &str) -> usize {
    outcomes.values().filter(|o| o.verdict == verdict).count()
}

/// Each registered image's provenance: its row of the photo-info file ingest read (checked
/// unchanged since), and its photo's EXIF.
fn photo_records(
    rec: &nrw_colmap::Reconstruction,
    scene: &nrw_dataset::SceneSource,
    recorded: &IngestParameters,
    inputs: &[FileEntry],
    dataset: &Store,
) -> Result<Vec<PhotoRecord>> {
    let mut info = BTreeMap::new();
    if let Some(file) = &recorded.photo_info {
        let path = Path::new(file);
        if !crate::model::unchanged(path, inputs)? {
            return Err(units_error(
                dataset,
                format!("{file} changed since the ingest units read it: run the units again"),
            ));
        }
        info = nrw_dataset::photo_info::read_photo_info(path)?;
    }
    let photos = scene.images_dir.as_deref().map(Path::new);
    Ok(rec
        .images
        .values()
        .map(|img| PhotoRecord {
            image_id: img.id,
            name: img.name.clone(),
            info: info.remove(&img.name).map(|(_, i)| i).unwrap_or_default(),
            // The one checked join of a model's name into a path (no links out of the folder).
            exif: photos
                .and_then(|d| nrw_colmap::names::photo_path(d, &img.name, false).ok())
                .map(|p| nrw_dataset::photo_info::read_exif(&p))
                .unwrap_or_default(),
        })
        .collect())
}

/// The groups of kept photos that are one picture ([`super::duplicates`], default options);
/// without a photo folder only the hashes can say.
fn near_duplicates(
    rec: &nrw_colmap::Reconstruction,
    outcomes: &BTreeMap<u32, ImageOutcome>,
    scene: &nrw_dataset::SceneSource,
) -> Result<Vec<nrw_dataset::duplicates::Member>> {
    use super::duplicates as d;
    let photos = d::photos(rec, outcomes);
    let mut options = d::DuplicateOptions::default();
    if scene.images_dir.is_none() {
        options.centre_fraction = -1.0;
    }
    let dir = Path::new(scene.images_dir.as_deref().unwrap_or(""));
    let scores = d::duplicate_pairs(&photos, dir, &options)?;
    Ok(d::groups(&photos, &scores, &options))
}

/// Merge ingest's units: scene tables and manifest from the group records, stale shards
/// (of runs with other parameters) removed.
pub fn finalize_ingest(dataset: &Store) -> Result<IngestMerge> {
    let unit = check_units(dataset, units::INGEST)?;
    let groups = read_groups(dataset, &unit)?;
    let scene = unit
        .scene
        .clone()
        .ok_or_else(|| units_error(dataset, "ingest unit record names no scene".into()))?;
    let mut rec = unchanged_model(dataset, &scene, &unit)?;
    // Near-duplicates are found on the photos as they are on disk, with their own cameras
    // (before any undistortion).
    let members = near_duplicates(&rec, &groups.outcomes, &scene)?;
    // `ingest --undistort` stored the undistorted PINHOLE cameras: the scene tables list those.
    let recorded: IngestParameters = from_parameters(
        &dataset.name(&format!(
            "{}/ (ingest unit record)",
            nrw_dataset::units::stage_dir(nrw_dataset::units::INGEST)
        )),
        &unit.parameters,
    )?;
    if let Some(u) = &recorded.undistort {
        let options = crate::model::undistort_options(u);
        crate::model::undistort_model(&mut rec, &options, Path::new(&scene.model_dir))?;
    }
    // Shards of an earlier run with other parameters must not linger next to these.
    for stale in nrw_dataset::views::stale_shards(dataset, &groups.shards)? {
        dataset.delete(&stale)?;
    }
    let mut tables =
        nrw_dataset::write_scene_tables(dataset, &rec, &groups.photos, &groups.outcomes)?;
    let records = photo_records(&rec, &scene, &recorded, &unit.inputs, dataset)?;
    tables.extend(nrw_dataset::photo_info::write_photos_table(
        dataset, &records,
    )?);
    tables.push(nrw_dataset::duplicates::write_duplicates(
        dataset, &members,
    )?);
    tables.extend(groups.shards.iter().cloned());
    // A split from an earlier run stays (split assigns only new photos when run again).
    if dataset.exists(nrw_dataset::split::SPLITS_TABLE)? {
        tables.push(FileEntry::of(dataset, nrw_dataset::split::SPLITS_TABLE)?);
    }
    let warnings = merge_warnings(dataset, &unit, &rec, &groups.outcomes)?;
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
    Ok(summary(unit.count, &groups, &members, warnings))
}

/// What the units' group records say together: each registered image's photo size and
/// outcome, and the shards written.
struct Groups {
    photos: BTreeMap<u32, Option<(u32, u32)>>,
    outcomes: BTreeMap<u32, ImageOutcome>,
    shards: Vec<FileEntry>,
}

/// Every group record of this run (a group without one is an error naming its unit).
fn read_groups(dataset: &Store, unit: &UnitRecord) -> Result<Groups> {
    let mut groups = Groups {
        photos: BTreeMap::new(),
        outcomes: BTreeMap::new(),
        shards: Vec::new(),
    };
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
        groups.shards.extend(r.shard);
        for i in r.images {
            groups.photos.insert(i.image_id, i.photo_size);
            groups.outcomes.insert(i.image_id, i.outcome);
        }
    }
    Ok(groups)
}

/// The scene's model, read again; an error if a model file changed since the units read it.
fn unchanged_model(
    dataset: &Store,
    scene: &nrw_dataset::SceneSource,
    unit: &UnitRecord,
) -> Result<nrw_colmap::Reconstruction> {
    let (rec, changed) = crate::model::reread_model(scene, &unit.inputs)?;
    match changed {
        Some(f) => Err(units_error(
            dataset,
            format!(
                "{} changed since the ingest units read it: run the units again",
                f.display()
            ),
        )),
        None => Ok(rec),
    }
}

/// The units' warnings, one for each unreadable photo, and one for the triplets a new ingest
/// makes stale (which it removes).
fn merge_warnings(
    dataset: &Store,
    unit: &UnitRecord,
    rec: &nrw_colmap::Reconstruction,
    outcomes: &BTreeMap<u32, ImageOutcome>,
) -> Result<Vec<String>> {
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
            dataset.name(stale)
        ));
    }
    Ok(warnings)
}

/// The merge's counts, for the summary line.
fn summary(
    units: usize,
    groups: &Groups,
    members: &[nrw_dataset::duplicates::Member],
    warnings: Vec<String>,
) -> IngestMerge {
    let outcomes = &groups.outcomes;
    IngestMerge {
        units,
        registered: outcomes.len(),
        kept: count(outcomes, nrw_dataset::scene::VERDICT_KEPT),
        too_small: count(outcomes, ImageVerdict::TooSmall.name()),
        too_sparse: count(outcomes, ImageVerdict::TooSparse.name()),
        too_blurry: count(outcomes, ImageVerdict::TooBlurry.name()),
        unreadable: count(outcomes, VERDICT_UNREADABLE),
        duplicate_groups: members
            .iter()
            .map(|m| m.group)
            .collect::<std::collections::BTreeSet<_>>()
            .len(),
        duplicate_photos: members.len(),
        shards: groups.shards.len(),
        least_empty: outcomes
            .values()
            .filter_map(|o| o.empty_ratio)
            .reduce(f64::min),
        warnings,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_renderers_verdicts_are_words_of_the_images_table() {
        use nrw_render::verdict::FilterVerdict;
        for (v, kind) in [
            (FilterVerdict::Kept { empty_ratio: 0.1 }, ImageVerdict::Kept),
            (
                FilterVerdict::TooSmall { shorter_side_px: 9 },
                ImageVerdict::TooSmall,
            ),
            (
                FilterVerdict::TooSparse { empty_ratio: 0.9 },
                ImageVerdict::TooSparse,
            ),
        ] {
            assert_eq!(ImageVerdict::of(v.name()), Some(kind));
        }
        for k in ImageVerdict::ALL {
            assert_eq!(ImageVerdict::of(k.name()), Some(k));
        }
    }
}
