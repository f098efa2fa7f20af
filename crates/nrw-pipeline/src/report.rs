//! What each stage says when it is done, as lines for stdout (what a script reads: results,
//! where they went) and stderr (what a person reads: counts, warnings, advice). The binary
//! prints them (and chooses exit codes); the judgments in them (a train split too small for
//! the published sampler, a threshold printed with its own digits) live here with the
//! stages. Nothing here prints.

use nrw_dataset::split::TRAIN;
use nrw_dataset::Location;

use nrw_export::{ExportSummary, Layout};

use crate::error::Setting;
use crate::ingest::{IngestSummary, UnitSummary};
use crate::inspect::{DatasetSummary, Inspected, ModelSummary};
use crate::runner::StageDone;
use crate::segment::SegmentSummary;
use crate::split::{SplitConfig, SplitSummary};
use crate::style::StyleSummary;
use crate::triplets::TripletsSummary;

/// Fewest train views the published triplet sampler can index (`randint(1, 5 + 1)`).
pub const PUBLISHED_MIN_TRAIN: usize = 6;

/// One line of a report and the stream it belongs on.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Line {
    /// stdout: a result.
    Out(String),
    /// stderr: a count, warning or piece of advice.
    Err(String),
}

/// The lines a finished stage prints, in order.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Report(pub Vec<Line>);

impl Report {
    fn out(&mut self, s: String) {
        self.0.push(Line::Out(s));
    }

    fn err(&mut self, s: String) {
        self.0.push(Line::Err(s));
    }
}

/// A fraction as a percentage with the digits it has (0.85 → 85, 0.995 → 99.5), never
/// rounded across the threshold it describes.
pub fn percent(fraction: f64) -> String {
    let p = (fraction * 100.0 * 1e6).round() / 1e6;
    format!("{p}")
}

/// " (unit I/N)" for a work unit, nothing for a whole stage.
fn unit_suffix(unit: crate::Unit) -> String {
    if unit.is_whole() {
        String::new()
    } else {
        format!(" (unit {unit})")
    }
}

/// A whole ingest: warnings, the verdict counts with their thresholds, and advice when
/// nothing was kept.
pub fn ingest(s: &IngestSummary) -> Report {
    let mut r = Report::default();
    for w in &s.warnings {
        r.err(format!("warning: {w}"));
    }
    r.err(format!(
        "ingested {}: {} registered, {} kept, {} too sparse (>{}% empty), {} too small (<{} px), {} unreadable; {} shards; {} points ({}) in {:.1} s",
        s.dataset,
        s.registered,
        s.kept,
        s.too_sparse,
        percent(s.max_empty),
        s.too_small,
        s.min_photo_side,
        s.unreadable,
        s.shards,
        s.points,
        s.point_source,
        s.seconds
    ));
    if let Some(min) = s.min_sharpness {
        r.err(format!(
            "{} too blurry (sharpness under {min}; each one's value is its verdict_value in scene/images.parquet)",
            s.too_blurry
        ));
    }
    if s.duplicate_groups > 0 {
        r.err(format!(
            "{} photos are copies of one another in {} groups (scene/duplicates.parquet): split keeps each group on one side",
            s.duplicate_photos, s.duplicate_groups
        ));
    }
    if s.kept == 0 {
        r.err(format!(
            "no view survived the filters{}: the dataset records every verdict but holds no view (`nrw-etl inspect {}` shows each verdict)",
            s.least_empty.map_or(String::new(), |m| format!(" (least empty render: {:.1}% empty)", m * 100.0)),
            s.dataset
        ));
    }
    r
}

/// One ingest work unit, and what to run once every unit has.
pub fn ingest_unit(s: &UnitSummary) -> Report {
    let mut r = Report::default();
    for w in &s.warnings {
        r.err(format!("warning: {w}"));
    }
    r.err(format!(
        "ingest unit {} of {}: {} of {} groups ({} already done), {} views kept, in {:.1} s; run `nrw-etl finalize {}` once every unit has run",
        s.unit, s.dataset, s.groups_owned, s.groups_total, s.resumed_groups, s.views, s.seconds, s.dataset
    ));
    r
}

/// What was exported, what was skipped, and the style distances.
pub fn export(dataset: &Location, out: &Location, s: &ExportSummary) -> Report {
    let mut r = Report::default();
    let per: Vec<String> = s
        .splits
        .iter()
        .map(|p| format!("{} {}", p.split, p.image_ids.len()))
        .collect();
    r.out(format!(
        "exported {} views ({}) of {} to {} ({} layout)",
        s.views(),
        per.join(", "),
        dataset,
        out,
        s.layout
    ));
    if let Some(l) = &s.licences {
        r.out(format!(
            "licences {}: {} views under other licences (or none known) left out; attribution.csv lists the photos exported",
            l.kept.join(", "),
            l.left_out
        ));
    }
    for k in &s.skipped {
        r.err(format!(
            "skipped {} (image {}, {} split): {}×{} is {}",
            k.name, k.image_id, k.split, k.width, k.height, k.reason
        ));
    }
    for w in &s.warnings {
        r.err(format!("warning: {w}"));
    }
    for e in &s.empty_splits {
        r.err(format!(
            "split {e} has no view: not written (the published code's {e} glob will find nothing; the split stage's {} N holds out N photos)",
            Setting::Key("split.val")
        ));
    }
    let train = s
        .splits
        .iter()
        .find(|p| p.split == TRAIN)
        .map_or(0, |p| p.image_ids.len());
    if s.dist_pickle.is_some() && train < PUBLISHED_MIN_TRAIN {
        r.err(format!(
            "warning: {train} train views: the published get_triplet_input_fn draws positives at sorted index 1..5 and fails (IndexError) below {PUBLISHED_MIN_TRAIN}"
        ));
    }
    match &s.dist_pickle {
        Some(p) => r.out(format!(
            "style distances: {} (pretrain_appearance loads it)",
            out.join(p)
        )),
        None if s.layout == Layout::Official.name() => r.err(
            format!(
                "no dist_NAME.pckl: the dataset has no official style descriptors (the style stage with {} official and {} VGG16)",
                Setting::Key("style.tier"),
                Setting::Weights
            ),
        ),
        None => {}
    }
    r
}

/// The report's counts, and where it is.
pub fn qa(w: &nrw_qa::Written) -> Report {
    let mut r = Report::default();
    let c = &w.figures.counts;
    r.err(format!(
        "QA: {} registered → {} rendered → {} kept → {} train / {} val; {} warning(s)",
        c.registered,
        c.rendered,
        c.kept,
        c.train,
        c.val,
        w.figures.warnings.len()
    ));
    r.out(w.report.to_string());
    r
}

/// What split assigned, and photos that left the split.
pub fn split(cfg: &SplitConfig, s: &SplitSummary) -> Report {
    let mut r = Report::default();
    for g in &s.gone {
        r.err(format!(
            "warning: {g} was assigned earlier but is no longer kept; removed from the split"
        ));
    }
    for names in &s.straddling {
        r.err(format!(
            "warning: near-duplicates on both sides of the split (one picture in train and val): {}",
            names.join(", ")
        ));
    }
    let Some(tsv) = &cfg.settings.from_tsv else {
        r.out(format!(
            "split {}: {} train, {} val ({} kept as before, {} newly assigned with seed {}){}",
            cfg.dataset,
            s.train,
            s.val,
            s.kept,
            s.new,
            cfg.settings.seed,
            match s.duplicate_groups {
                0 => String::new(),
                n => format!("; {n} near-duplicate groups each kept on one side"),
            }
        ));
        return r;
    };
    r.out(format!(
        "split {}: {} train, {} val, as {} lists them",
        cfg.dataset,
        s.train,
        s.val,
        tsv.display()
    ));
    if let Some(first) = s.listed_not_kept.first() {
        r.err(format!(
            "{} listed photo(s) were dropped by ingest and are in no split, e.g. {first}",
            s.listed_not_kept.len(),
        ));
    }
    if s.unlisted > 0 {
        r.err(format!(
            "{} kept photo(s) are not listed and are in no split",
            s.unlisted
        ));
    }
    r
}

/// The summary line of a style run or unit.
pub fn style(s: &StyleSummary) -> Report {
    let mut r = Report::default();
    r.err(format!(
        "described {} photos with {} into {}/{}{} ({} parts written, {} already there)",
        s.photos,
        s.tier,
        s.dataset,
        nrw_dataset::descriptors::DESCRIPTORS_DIR,
        unit_suffix(s.unit),
        s.parts_written,
        s.parts_skipped
    ));
    r
}

/// What finalize merged (or that there was nothing to merge).
pub fn finalize(s: &crate::finalize::FinalizeSummary) -> Report {
    let mut r = Report::default();
    if let Some(i) = &s.ingest {
        i.warnings
            .iter()
            .for_each(|w| r.err(format!("warning: {w}")));
        r.err(format!(
            "finalized ingest of {} from {} units: {} registered, {} kept, {} too sparse, {} too small, {} unreadable; {} shards",
            s.dataset, i.units, i.registered, i.kept, i.too_sparse, i.too_small, i.unreadable, i.shards
        ));
    }
    if let Some(st) = &s.style {
        r.err(format!(
            "finalized style of {} from {} units: {} parts of {}",
            s.dataset, st.units, st.parts, st.tier
        ));
    }
    if s.merged_nothing() {
        r.err(format!(
            "{}: nothing to finalize (no unit records; the dataset is final)",
            s.dataset
        ));
    }
    r
}

/// The triplet table's summary (and the approximate path's recall).
pub fn triplets(dataset: &Location, s: &TripletsSummary) -> Report {
    let mut r = Report::default();
    if let Some((n, f)) = s.recall {
        r.err(format!(
            "{}: recall@{} against the exact path: nearest {n:.3}, furthest {f:.3}",
            s.method, s.k
        ));
    }
    r.out(format!(
        "triplets {}: {} anchors × {} nearest / {} furthest ({}, scope {}, {})",
        dataset, s.anchors, s.k, s.k, s.tier, s.scope, s.method
    ));
    r
}

/// What segment labelled.
pub fn segment(s: &SegmentSummary) -> Report {
    let mut r = Report::default();
    r.err(format!(
        "segmented {} of {} photos{} into {} ({} already there, {} unreadable) with {} (mode {}) in {:.1} s",
        s.segmented,
        s.photos,
        unit_suffix(s.unit),
        s.out,
        s.resumed,
        s.unreadable.len(),
        s.model,
        s.mode,
        s.seconds
    ));
    r
}

/// What was synthesised.
pub fn synth(s: &nrw_synth::SynthReport) -> Report {
    let mut r = Report::default();
    r.err(format!(
        "synthesised: {} photos ({} small, {} looking away), {} sparse points, {} observations, {} dense points",
        s.photos, s.small_photos, s.away_photos, s.sparse_points, s.observations, s.dense_points
    ));
    r
}

/// What densify made: views with depth, the verdicts of the others, the cloud, the time.
pub fn densify(d: &crate::densify::DensifyReport) -> Report {
    use crate::densify::DensifyVerdict;
    let mut r = Report::default();
    let (mut no_source, mut no_range, mut unreadable) = (0, 0, Vec::new());
    for v in &d.views {
        match &v.verdict {
            DensifyVerdict::Densified { .. } => {}
            DensifyVerdict::NoSourceView => no_source += 1,
            DensifyVerdict::NoDepthRange => no_range += 1,
            DensifyVerdict::Unreadable(why) => unreadable.push(format!("  {}: {why}", v.name)),
        }
    }
    let pixels: usize = d
        .views
        .iter()
        .map(|v| match v.verdict {
            DensifyVerdict::Densified { pixels } => pixels,
            _ => 0,
        })
        .sum();
    r.err(format!(
        "densified {} of {} views ({} depth pixels kept); {} without a source view, {} seeing no sparse point, {} unreadable",
        d.densified(),
        d.views.len(),
        pixels,
        no_source,
        no_range,
        unreadable.len()
    ));
    for line in unreadable {
        r.err(line);
    }
    let phases: Vec<String> = ["undistorting", "photometric", "geometric", "fusing"]
        .iter()
        .zip(d.seconds)
        .filter_map(|(what, s)| s.map(|s| format!("{s:.1} s {what}")))
        .collect();
    r.err(format!("fused {} points; {}", d.points, phases.join(", ")));
    let mib = |b: usize| b as f64 / (1024.0 * 1024.0);
    r.err(format!(
        "fusion read {} bands of {} rows ({} in {} views), holding at most {:.1} MiB of their {:.1} MiB (--fusion-cache-mb){}",
        d.fusion.reads,
        nrw_stereo::BAND_ROWS,
        d.fusion.bands,
        d.densified(),
        mib(d.fusion.peak_bytes),
        mib(d.fusion_all_bytes),
        if d.fusion.reads > d.fusion.bands {
            format!(
                ": bands were read again; --fusion-cache-mb {} reads each once",
                d.fusion_all_bytes.div_ceil(1024 * 1024)
            )
        } else {
            String::new()
        }
    ));
    r.out(d.out.join("fused.ply").to_string());
    r
}

/// One work unit of a densify pass: what it owned, ran and found done.
pub fn densify_unit(u: &crate::densify::UnitReport) -> Report {
    let mut r = Report::default();
    r.err(format!(
        "densify unit {} ({} pass): {} of {} views; {} matched, {} found done; {:.1} s{}",
        u.unit,
        u.pass.name(),
        u.owned,
        u.planned,
        u.computed,
        u.resumed,
        u.seconds,
        u.undistort_seconds
            .map(|s| format!(" ({s:.1} s of it undistorting the photos)"))
            .unwrap_or_default()
    ));
    r.err(match u.pass {
        nrw_colmap::dense::MapPass::Photometric => "next, once every unit of this pass has run: the units of `--pass geometric` (or, with --no-geometric, `--finalize`)",
        nrw_colmap::dense::MapPass::Geometric => "next, once every unit of this pass has run: `densify SCENE --finalize` fuses the maps and publishes the workspace",
    }.to_string());
    r.out(u.staging.to_string());
    r
}

/// A finished stage of a pipeline run, as its own command reports it.
pub fn stage(dataset: &Location, done: StageDone) -> Report {
    match done {
        StageDone::Densify(d) => densify(d),
        StageDone::Ingest(s) => ingest(s),
        StageDone::Split(s) => Report(vec![Line::Out(format!(
            "split {}: {} train, {} val",
            dataset, s.train, s.val
        ))]),
        StageDone::Style(s) => style(s),
        StageDone::Triplets(s) => triplets(dataset, s),
        StageDone::Export(out, s) => export(dataset, out, s),
        StageDone::Qa(w) => qa(w),
    }
}

/// A model's or a dataset's summary, as `inspect` prints it.
pub fn inspected(found: &Inspected) -> Report {
    match found {
        Inspected::Model(m) => model(m),
        Inspected::Dataset(d) => dataset(d),
    }
}

fn dataset(d: &DatasetSummary) -> Report {
    let mut r = Report::default();
    r.out(format!(
        "dataset      {} (schema {})",
        d.dataset, d.schema_version
    ));
    r.out(format!("registered   {}", d.registered));
    for (k, n) in &d.verdicts {
        r.out(format!("  {k:<10} {n}"));
    }
    r.out(format!("views        {} in {} shards", d.views, d.shards));
    for (k, n) in &d.splits {
        r.out(format!("split {k:<6} {n}"));
    }
    r.out("licences".into());
    for (k, n) in &d.licences {
        r.out(format!("  {k:<10} {n}"));
    }
    if !d.near_duplicates.is_empty() {
        r.out(format!(
            "near-duplicates: {} groups of photos that are one picture (split keeps each on one side), e.g. {}",
            d.near_duplicates.len(),
            d.near_duplicates[0].join(" = ")
        ));
    }
    if !d.rotated_by_exif.is_empty() {
        r.err(format!(
            "warning: {} photos have an EXIF orientation other than 1 ({}); COLMAP reads pixels as stored, and so does nrw-etl: their views are as the model saw them, not as a viewer shows them",
            d.rotated_by_exif.len(),
            d.rotated_by_exif.iter().take(5).cloned().collect::<Vec<_>>().join(", ")
        ));
    }
    r
}

fn model(m: &ModelSummary) -> Report {
    let mut r = Report::default();
    let fmt_px = |v: Option<f64>| v.map_or("n/a".to_string(), |v| format!("{v:.4} px"));
    r.out(format!(
        "model        {} ({}, {})",
        m.model_dir, m.encoding, m.layout
    ));
    r.out(format!(
        "cameras      {} ({})",
        m.cameras,
        m.camera_models.join(", ")
    ));
    r.out(format!("images       {}", m.images));
    r.out(format!("points       {}", m.points));
    r.out(format!(
        "observations {} (mean track length {:.2})",
        m.observations,
        m.mean_track_length()
    ));
    let hidden = if m.not_visible_observations > 0 {
        format!(
            "; {} observations not visible (behind the camera)",
            m.not_visible_observations
        )
    } else {
        String::new()
    };
    r.out(format!(
        "reprojection mean {}, max {} over {} observations{hidden}",
        fmt_px(m.mean_reprojection_error_px),
        fmt_px(m.max_reprojection_error_px),
        m.observations_projected,
    ));
    if m.layout == "colmap4" {
        r.out(format!("rigs/frames  {} / {}", m.rigs, m.frames));
    }
    if !m.sub_models.is_empty() {
        r.out("sub-models   images  points  mean reprojection".into());
        for s in &m.sub_models {
            r.out(format!(
                "  sparse/{:<4} {:>6}  {:>6}  {}",
                s.index,
                s.images,
                s.points,
                fmt_px(s.mean_reprojection_error_px)
            ));
        }
    }
    if let Some(c) = &m.chosen {
        r.out(format!("chosen       {c}"));
    }
    for w in &m.warnings {
        r.out(format!("warning: {w}"));
    }
    r
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn thresholds_print_with_their_own_digits() {
        assert_eq!(percent(0.85), "85");
        assert_eq!(percent(0.995), "99.5");
        assert_eq!(percent(1.0), "100");
        assert_eq!(percent(0.0), "0");
    }

    #[test]
    fn a_train_split_the_published_sampler_cannot_index_is_warned_about() {
        let mut s = ExportSummary {
            tool: "t".into(),
            dataset: "d".into(),
            layout: Layout::Official.name(),
            name: "n".into(),
            crop: None,
            depth: None,
            semantics: None,
            splits: vec![nrw_export::SplitExport {
                split: "train".into(),
                image_ids: vec![1, 2, 3, 4, 5],
                names: vec![String::new(); 5],
                files: Vec::new(),
            }],
            skipped: Vec::new(),
            empty_splits: Vec::new(),
            dist_pickle: Some("dist_n.pckl".into()),
            depth_source: None,
            warnings: Vec::new(),
            licences: None,
        };
        let warned = |s: &ExportSummary| {
            export(&"d".into(), &"o".into(), s)
                .0
                .iter()
                .any(|l| matches!(l, Line::Err(e) if e.contains("IndexError")))
        };
        assert!(warned(&s), "5 train views");
        s.splits[0].image_ids.push(6);
        assert!(!warned(&s), "6 train views");
    }
}
