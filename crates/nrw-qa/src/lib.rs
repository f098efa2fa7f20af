//! Dataset QA: before training for days on a dataset, see it. `build` reads a dataset's tables
//! (polars lazy scans) and views, and writes a self-contained `report.html` (charts as inline
//! SVG, thumbnails as data URIs: no network, no side files) and `qa.json` with the same figures.

pub mod error;
pub mod html;
pub mod plots;
pub mod tables;
pub mod thumbs;

use nrw_dataset::split::{TRAIN, VAL};
use std::collections::BTreeMap;

use serde::Serialize;

pub use error::{QaError, Result};
use tables::ImageRow;

/// The report's numbers, also written as qa.json.
#[derive(Debug, Clone, Serialize)]
pub struct Figures {
    pub dataset: String,
    pub scene_dir: String,
    pub tool: String,
    pub counts: Counts,
    /// Dropped photos by reason (`too_small`, `too_sparse`, …).
    pub drops: BTreeMap<String, usize>,
    /// Stage parameters as the manifest records them.
    pub parameters: serde_json::Map<String, serde_json::Value>,
    /// Seconds per stage (from timings.json; stages run before it existed are missing).
    pub timings: BTreeMap<String, f64>,
    pub distributions: BTreeMap<String, Summary>,
    pub triplets: Option<TripletFigures>,
    pub warnings: Vec<Warning>,
    /// Registered photos by licence, when the dataset records provenance
    /// (`ingest --photo-info`, or photos with EXIF); empty otherwise (every licence unknown).
    #[serde(skip_serializing_if = "BTreeMap::is_empty")]
    pub licences: BTreeMap<String, usize>,
    /// Groups of kept photos that are one picture (scene/duplicates.parquet), by name.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub near_duplicates: Vec<Vec<String>>,
}

/// A kept photo this much less sharp than the dataset's median is worth a look.
const BLUR_FACTOR: f64 = 10.0;

/// Warnings from the photos' own pixels: kept photos far less sharp than the rest, and
/// near-duplicate groups that the split puts on both sides.
fn signal_warnings(
    images: &[ImageRow],
    members: &[nrw_dataset::duplicates::Member],
    warnings: &mut Vec<Warning>,
) {
    let kept: Vec<(&str, f64)> = images
        .iter()
        .filter(|r| r.verdict == nrw_dataset::scene::VERDICT_KEPT)
        .filter_map(|r| Some((r.name.as_str(), r.signals?.sharpness)))
        .collect();
    if let Some(median) =
        Summary::of(&kept.iter().map(|k| k.1).collect::<Vec<_>>()).map(|s| s.median)
    {
        let blurry: Vec<String> = kept
            .iter()
            .filter(|(_, s)| *s * BLUR_FACTOR < median)
            .map(|(n, _)| n.to_string())
            .collect();
        if !blurry.is_empty() {
            warnings.push(Warning {
                kind: "low_sharpness".into(),
                message: format!(
                    "{} kept photos are less than a tenth as sharp as the median ({median:.1}, variance of the Laplacian): blurred or out of focus? `ingest --min-sharpness` drops them",
                    blurry.len()
                ),
                photos: blurry,
            });
        }
    }
    // The split as assignments (the photos split has placed), and the groups that straddle it.
    let rows: Vec<nrw_dataset::split::Assignment> = images
        .iter()
        .filter_map(|r| {
            Some(nrw_dataset::split::Assignment {
                image_id: r.image_id,
                name: r.name.clone(),
                split: r.split.clone()?,
                seed: 0,
            })
        })
        .collect();
    let groups = nrw_dataset::duplicates::group_of(members);
    let both: Vec<String> = nrw_dataset::split::straddling(&rows, &groups)
        .into_iter()
        .flat_map(|(_, names)| names)
        .collect();
    if !both.is_empty() {
        warnings.push(Warning {
            kind: "near_duplicates_split".into(),
            message: format!(
                "{} photos are in near-duplicate groups with members in both train and val: validation sees copies of training photos",
                both.len()
            ),
            photos: both,
        });
    }
}

/// Photos at every stage.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct Counts {
    pub registered: usize,
    /// Photos large enough to render (not dropped as too small).
    pub rendered: usize,
    pub kept: usize,
    pub dropped: usize,
    /// Rows in the view shards (equals `kept` in a consistent dataset).
    pub shard_rows: u64,
    pub train: usize,
    pub val: usize,
    pub descriptors: usize,
}

/// Five-number summary of a distribution.
#[derive(Debug, Clone, Serialize)]
pub struct Summary {
    pub n: usize,
    pub min: f64,
    pub p25: f64,
    pub median: f64,
    pub p75: f64,
    pub max: f64,
}

impl Summary {
    fn of(values: &[f64]) -> Option<Summary> {
        let mut v: Vec<f64> = values.iter().copied().filter(|x| x.is_finite()).collect();
        if v.is_empty() {
            return None;
        }
        v.sort_by(|a, b| a.total_cmp(b));
        let q = |f: f64| v[((v.len() - 1) as f64 * f).round() as usize];
        Some(Summary {
            n: v.len(),
            min: v[0],
            p25: q(0.25),
            median: q(0.5),
            p75: q(0.75),
            max: v[v.len() - 1],
        })
    }
}

/// The triplet table's settings.
#[derive(Debug, Clone, Serialize)]
pub struct TripletFigures {
    pub anchors: usize,
    pub k: usize,
    pub tier: String,
    pub method: String,
    pub scope: String,
    pub recall_nearest: Option<f64>,
}

/// Something worth a human's attention, with the photos it concerns.
#[derive(Debug, Clone, Serialize)]
pub struct Warning {
    pub kind: String,
    pub message: String,
    pub photos: Vec<String>,
}

/// Where the report went.
#[derive(Debug, Clone)]
pub struct Written {
    pub report: nrw_dataset::Location,
    pub json: nrw_dataset::Location,
    pub figures: Figures,
}

/// The report's file name in its folder.
pub const REPORT_FILE: &str = "report.html";
/// The figures' file name in the report's folder.
pub const QA_JSON: &str = "qa.json";

/// Name of the per-stage timing log inside a dataset (owned by nrw-dataset).
pub use nrw_dataset::timings::TIMINGS_FILE;

/// Record how long a stage took in `DATASET/timings.json`.
pub fn record_timing(dir: &nrw_dataset::Store, stage: &str, seconds: f64) -> Result<()> {
    Ok(nrw_dataset::timings::record(dir, stage, seconds)?)
}

/// Compute the figures and write `report.html` and `qa.json` into `out` (a folder or an
/// object-store prefix, through its `Store`).
pub fn build(dir: &nrw_dataset::Store, out: &nrw_dataset::Store) -> Result<Written> {
    let manifest = nrw_dataset::Manifest::read(dir)?;
    let images = tables::images(dir)?;
    let triplets = tables::triplets(dir, 3)?;
    let descriptors = nrw_dataset::descriptors::Index::read(dir)?;
    let timings = nrw_dataset::timings::read(dir);
    let kept: Vec<&ImageRow> = images
        .iter()
        .filter(|r| r.verdict == nrw_dataset::scene::VERDICT_KEPT)
        .collect();
    let counts = counts(&images, kept.len(), &manifest, descriptors.as_ref());
    // Ingest always records its filters; their defaults live in nrw-render alone, so a
    // missing one is an error, not a guess.
    let ingest: nrw_dataset::provenance::IngestParameters =
        nrw_dataset::provenance::from_parameters(
            &dir.name(nrw_dataset::Manifest::FILE),
            &manifest.parameters,
        )?;
    let max_empty = ingest.max_empty;
    let mut warnings = warnings(&images, &counts, max_empty);
    let attributions = nrw_dataset::photo_info::read_attributions(dir)?;
    let licences = provenance_warnings(&images, &attributions, &mut warnings);
    let members = nrw_dataset::duplicates::read_duplicates(dir)?;
    let near_duplicates = nrw_dataset::duplicates::names_by_group(&members);
    signal_warnings(&images, &members, &mut warnings);
    let figures = Figures {
        licences,
        dataset: dir.root().to_string(),
        scene_dir: manifest.scene.scene_dir.clone(),
        tool: format!("{} {}", manifest.tool.name, manifest.tool.version),
        counts,
        drops: drops(&images),
        parameters: manifest.parameters.clone(),
        timings,
        distributions: distributions(&images, &kept),
        triplets: triplets.as_ref().map(|t| t.settings.clone()),
        warnings,
        near_duplicates,
    };
    let page = html::render(&html::Inputs {
        dir,
        manifest: &manifest,
        figures: &figures,
        images: &images,
        triplets: triplets.as_ref(),
        descriptors: descriptors.as_ref(),
        max_empty,
        min_side: ingest.min_photo_side as f64,
        min_sharpness: ingest.min_sharpness,
        duplicates: &members,
    })?;
    out.write(REPORT_FILE, page.into_bytes())?;
    let mut text = serde_json::to_string_pretty(&figures).expect("figures serialise");
    text.push('\n');
    out.write(QA_JSON, text.into_bytes())?;
    Ok(Written {
        report: out.name(REPORT_FILE),
        json: out.name(QA_JSON),
        figures,
    })
}

/// How many views each stage saw, kept and split, with the shards' rows and descriptors.
fn counts(
    images: &[ImageRow],
    kept: usize,
    manifest: &nrw_dataset::Manifest,
    descriptors: Option<&nrw_dataset::descriptors::Index>,
) -> Counts {
    let split = |side: &str| {
        images
            .iter()
            .filter(|r| r.split.as_deref() == Some(side))
            .count()
    };
    Counts {
        registered: images.len(),
        rendered: images
            .iter()
            .filter(|r| r.verdict != nrw_dataset::scene::ImageVerdict::TooSmall.name())
            .count(),
        kept,
        dropped: images.len() - kept,
        shard_rows: tables::shard_rows(manifest),
        train: split(TRAIN),
        val: split(VAL),
        descriptors: descriptors.map_or(0, |d| d.entries.len()),
    }
}

/// The dropped views, counted by verdict.
fn drops(images: &[ImageRow]) -> BTreeMap<String, usize> {
    let mut drops = BTreeMap::new();
    for r in images
        .iter()
        .filter(|r| r.verdict != nrw_dataset::scene::VERDICT_KEPT)
    {
        *drops.entry(r.verdict.clone()).or_insert(0) += 1;
    }
    drops
}

/// The summaries of each per-view figure QA plots (over the kept views, or every
/// registered one where drops are what the figure explains).
fn distributions(images: &[ImageRow], kept: &[&ImageRow]) -> BTreeMap<String, Summary> {
    let short = |r: &ImageRow| match (r.photo_width, r.photo_height) {
        (Some(w), Some(h)) => Some(w.min(h) as f64),
        _ => None,
    };
    let signal = |f: fn(&nrw_dataset::PhotoSignals) -> f64| -> Vec<f64> {
        kept.iter()
            .filter_map(|r| r.signals.as_ref().map(f))
            .collect()
    };
    let series: [(&str, Vec<f64>); 7] = [
        ("sharpness", signal(|s| s.sharpness)),
        ("luma_mean", signal(|s| s.luma_mean)),
        (
            "empty_ratio",
            images.iter().filter_map(|r| r.empty_ratio).collect(),
        ),
        (
            "photo_shorter_side",
            images.iter().filter_map(short).collect(),
        ),
        (
            "depth_min",
            kept.iter().filter_map(|r| r.depth_min).collect(),
        ),
        (
            "depth_max",
            kept.iter().filter_map(|r| r.depth_max).collect(),
        ),
        (
            "observations_per_view",
            images.iter().map(|r| r.num_observations as f64).collect(),
        ),
    ];
    series
        .iter()
        .filter_map(|(name, v)| Summary::of(v).map(|s| (name.to_string(), s)))
        .collect()
}

/// Photos by licence, and warnings for photos without one and photos whose EXIF orientation
/// is not 1; nothing when the dataset records no provenance.
fn provenance_warnings(
    images: &[ImageRow],
    attributions: &BTreeMap<u32, nrw_dataset::photo_info::Attribution>,
    warnings: &mut Vec<Warning>,
) -> BTreeMap<String, usize> {
    if attributions.is_empty() {
        return BTreeMap::new();
    }
    let nrw_dataset::photo_info::Tally {
        licences,
        without_licence: without,
        rotated_by_exif: rotated,
    } = nrw_dataset::photo_info::tally(
        images.iter().map(|r| (r.image_id, r.name.as_str())),
        attributions,
    );
    if !without.is_empty() {
        warnings.push(Warning {
            kind: "licence_unknown".into(),
            message: format!("{} photos have no licence: export --licences leaves them out unless `unknown` is listed", without.len()),
            photos: without,
        });
    }
    if !rotated.is_empty() {
        warnings.push(Warning {
            kind: "exif_orientation".into(),
            message: format!("{} photos have an EXIF orientation other than 1: COLMAP reads pixels as stored, and so does nrw-etl, so these views are as the model saw them, not as a photo viewer shows them", rotated.len()),
            photos: rotated,
        });
    }
    licences
}

fn warnings(images: &[ImageRow], counts: &Counts, max_empty: f64) -> Vec<Warning> {
    let mut w = Vec::new();
    let mut add = |kind: &str, message: String, photos: Vec<String>| {
        if !photos.is_empty() || kind == "small_validation_set" || kind == "nothing_kept" {
            w.push(Warning {
                kind: kind.into(),
                message,
                photos,
            });
        }
    };
    let names = |f: &dyn Fn(&ImageRow) -> bool| -> Vec<String> {
        images
            .iter()
            .filter(|r| f(r))
            .map(|r| r.name.clone())
            .collect()
    };
    let mismatch = names(&|r| r.photo_matches_camera == Some(false));
    add(
        "photo_size_disagrees_with_camera",
        format!(
            "{} photo(s) differ in size from their COLMAP camera: intrinsics were scaled to the photo; check that these are the images COLMAP saw",
            mismatch.len()
        ),
        mismatch,
    );
    let renorm = names(&|r| r.quat_renormalized);
    add(
        "quaternion_renormalized",
        format!(
            "{} pose quaternion(s) were not unit length and were normalised; the model may have been edited by hand",
            renorm.len()
        ),
        renorm,
    );
    let edge = names(&|r| {
        r.verdict == nrw_dataset::scene::VERDICT_KEPT
            && r.empty_ratio.is_some_and(|e| e > max_empty - 0.02)
    });
    add(
        "coverage_near_threshold",
        format!(
            "{} kept view(s) are within 2 points of the {:.0}% empty threshold: a slightly different radius or cloud would drop them",
            edge.len(),
            max_empty * 100.0
        ),
        edge,
    );
    let dense = names(&|r| {
        r.verdict == nrw_dataset::scene::VERDICT_KEPT && r.empty_ratio.is_some_and(|e| e < 0.01)
    });
    add(
        "suspiciously_full_render",
        format!(
            "{} view(s) are rendered with under 1% empty pixels: a camera inside the cloud or a wrong scale?",
            dense.len()
        ),
        dense,
    );
    if counts.kept == 0 {
        add(
            "nothing_kept",
            "every view was dropped: there is nothing to train on (see Drops)".into(),
            Vec::new(),
        );
    }
    if counts.train + counts.val > 0 && counts.val < 10 {
        add(
            "small_validation_set",
            format!(
                "the validation split holds {} photo(s): its metrics will be noisy",
                counts.val
            ),
            Vec::new(),
        );
    }
    w
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn summaries_skip_non_finite_values() {
        let s = Summary::of(&[5.0, 1.0, f64::NAN, 3.0, 2.0, 4.0]).unwrap();
        assert_eq!((s.n, s.min, s.median, s.max), (5, 1.0, 3.0, 5.0));
        assert_eq!((s.p25, s.p75), (2.0, 4.0));
        assert!(Summary::of(&[f64::NAN]).is_none());
    }

    #[test]
    fn timings_accumulate_per_stage() {
        let d = tempfile::tempdir().unwrap();
        record_timing(&d.path().into(), "ingest", 2.5).unwrap();
        record_timing(&d.path().into(), "split", 0.5).unwrap();
        record_timing(&d.path().into(), "ingest", 3.0).unwrap();
        let t: BTreeMap<String, f64> =
            serde_json::from_str(&std::fs::read_to_string(d.path().join(TIMINGS_FILE)).unwrap())
                .unwrap();
        assert_eq!(t.len(), 2);
        assert_eq!(t["ingest"], 3.0);
    }
}
