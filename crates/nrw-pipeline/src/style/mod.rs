//! Style: descriptors of a dataset's kept photos into `descriptors/part-NNNNN.parquet`, in
//! parts of [`PART_PHOTOS`] photos in id order (the unit of resumption and of work units),
//! parallel over photos; or the exact Gram matrices of one image ([`image_grams`]).

use std::path::PathBuf;
use std::time::Instant;

use nrw_dataset::descriptors::{
    existing_parts, part_path, read_part, write_part, DescriptorKind, DescriptorRow,
};
use nrw_dataset::reader::Dataset;
use nrw_dataset::units::{self, UnitRecord};
use nrw_dataset::{Manifest, Store};
use nrw_style::{Backend, Preprocess, Tier};
use rayon::prelude::*;

use crate::error::{PipelineError, Result, Setting};
use crate::settings::style::StyleSettings;
use crate::stage::GroupStage;
use crate::units::{check_units, close_stage, units_error};
use crate::{Progress, Unit};

use nrw_dataset::provenance::{from_parameters, to_parameters, StyleParameters};

mod weights;

pub use weights::{image_grams, load_weights};

pub use crate::settings::style::PART_PHOTOS;

/// A style run: the dataset, its settings (declared once, in [`crate::settings::style`]),
/// the tier they name and the weights file the caller gave.
#[derive(Debug, Clone)]
pub struct StyleConfig {
    pub dataset: nrw_dataset::Location,
    /// The tier that runs: `settings.tier` parsed (the stage reads this, never the name).
    pub tier: Tier,
    /// VGG weights (safetensors, torchvision names); required by the VGG tiers.
    pub weights: Option<PathBuf>,
    /// Replace descriptors of another kind instead of refusing.
    pub overwrite: bool,
    pub settings: StyleSettings,
}

impl StyleConfig {
    /// The reference tier (VGG16, 512² crop) with ImageNet scaling.
    pub fn new(dataset: impl Into<nrw_dataset::Location>) -> StyleConfig {
        StyleConfig {
            dataset: dataset.into(),
            tier: Tier::reference(),
            weights: None,
            overwrite: false,
            settings: StyleSettings::default(),
        }
    }

    /// The network input scaling asked for (the official tier always uses its own).
    fn preprocess(&self) -> Preprocess {
        self.tier.preprocess(self.settings.preprocess.into())
    }
}

impl StyleSettings {
    /// The style run over `dataset` these settings ask for, with the weights the caller was
    /// given (a tier that needs them and has none is refused when they are loaded).
    pub fn config(
        &self,
        dataset: &nrw_dataset::Location,
        weights: Option<PathBuf>,
    ) -> Result<StyleConfig> {
        let tier = self
            .tier
            .parse::<Tier>()
            .map_err(|e| PipelineError::config(Setting::Key("style.tier"), e))?;
        Ok(StyleConfig {
            dataset: dataset.clone(),
            tier,
            weights,
            overwrite: false,
            settings: self.clone(),
        })
    }
}

/// What a style run (or unit) did.
#[derive(Debug, Clone, serde::Serialize)]
pub struct StyleSummary {
    pub dataset: String,
    /// The work unit, `I/N` (`0/1`: the whole stage).
    pub unit: crate::Unit,
    pub tier: String,
    pub photos: usize,
    pub parts_written: usize,
    pub parts_skipped: usize,
    pub seconds: f64,
}

fn kind(cfg: &StyleConfig, net: Option<&dyn Backend>) -> DescriptorKind {
    DescriptorKind {
        tier: cfg.tier.name(),
        weights_sha256: net.map_or(String::new(), |n| n.weights_sha256().to_string()),
        // color-stats ignores the network's input scaling, so it never tells descriptors apart
        preprocess: if cfg.tier.needs_weights() {
            cfg.preprocess().name().to_string()
        } else {
            String::new()
        },
    }
}

/// What a tier's descriptors depend on: the backend's device for the VGG tiers (on the CPU
/// their convolutions and Grams are GEMMs, whose sums the AVX-512 and AVX2 kernels order
/// differently, so values agree to about 1e-6 relative across machines, not bit for bit);
/// none for colour statistics, summed in plain f64 the same way everywhere.
fn device_of(net: Option<&dyn Backend>) -> Option<String> {
    net.map(|n| n.device())
}

/// Manifest key listing the instruction sets the descriptors were computed with.
pub const INSTRUCTION_SETS_KEY: &str = "style_instruction_sets";

/// Record in the manifest which instruction sets the style units ran with (sorted, once
/// each), or remove the key when no descriptor value depends on them.
fn record_instruction_sets(manifest: &mut Manifest, records: &[UnitRecord]) {
    let sets: std::collections::BTreeSet<&str> = records
        .iter()
        .filter_map(|r| r.instruction_set.as_deref())
        .collect();
    if sets.is_empty() {
        manifest.parameters.remove(INSTRUCTION_SETS_KEY);
    } else {
        manifest
            .parameters
            .insert(INSTRUCTION_SETS_KEY.into(), serde_json::json!(sets));
    }
}

/// The descriptor kind a style unit record describes (its typed parameters).
pub(crate) fn kind_of(dataset: &Store, r: &UnitRecord) -> Result<DescriptorKind> {
    let file = dataset.name(&units::unit_record_path(units::STYLE, r.index, r.count));
    let p: StyleParameters = from_parameters(&file, &r.parameters)?;
    Ok(DescriptorKind {
        tier: p.tier,
        weights_sha256: p.weights_sha256,
        preprocess: p.preprocess,
    })
}

/// Remove parts of another kind among `parts` (or refuse without `overwrite`).
fn clear_other_kinds(
    cfg: &StyleConfig,
    store: &Store,
    kind: &DescriptorKind,
    parts: impl Iterator<Item = usize>,
) -> Result<()> {
    for k in parts {
        let rel = part_path(k);
        let path = store.name(&rel);
        if !store.exists(&rel)? {
            continue;
        }
        let (pk, _) = read_part(store, &rel)?;
        if pk.as_ref().is_some_and(|p| p != kind) {
            if !cfg.overwrite {
                return Err(PipelineError::input(
                    &path,
                    format!(
                        "holds descriptors of {:?}, not {kind:?}; set {} to replace them",
                        pk.expect("some"),
                        Setting::Overwrite
                    ),
                ));
            }
            store.delete(&rel)?;
        }
    }
    Ok(())
}

/// List parts `0..groups` in the manifest and remove parts past them (of a larger earlier run).
pub(crate) fn list_parts(dataset: &Store, manifest: &mut Manifest, groups: usize) -> Result<()> {
    for k in existing_parts(dataset)?
        .into_iter()
        .filter(|k| *k >= groups)
    {
        dataset.delete(&part_path(k))?;
    }
    manifest.remove_tables(nrw_dataset::descriptors::is_part);
    for k in 0..groups {
        manifest.replace_table(nrw_dataset::FileEntry::of(dataset, &part_path(k))?);
    }
    Ok(())
}

/// Whether part `k` is already done for these photos and this kind.
fn part_done(dataset: &Store, k: usize, kind: &DescriptorKind, ids: &[u32]) -> Result<bool> {
    let rel = part_path(k);
    if !dataset.exists(&rel)? {
        return Ok(false);
    }
    let (pk, rows) = read_part(dataset, &rel)?;
    Ok(pk.as_ref() == Some(kind) && rows.iter().map(|r| r.image_id).eq(ids.iter().copied()))
}

/// Describe one group of photos into part `k`: colour statistics photo by photo in parallel;
/// VGG tiers in the backend's batches, each batch's photos decoded and prepared in parallel.
#[allow(clippy::too_many_arguments)]
fn describe_part(
    cfg: &StyleConfig,
    ds: &Dataset,
    net: Option<&dyn Backend>,
    kind: &DescriptorKind,
    k: usize,
    ids: &[u32],
    progress: &dyn Progress,
) -> Result<()> {
    // Read the group's photos a row group at a time (sequential I/O).
    let views: Vec<_> = ds.iter_ids(ids)?.collect::<std::result::Result<_, _>>()?;
    let mut rows: Vec<DescriptorRow> = match net {
        None => views
            .par_iter()
            .map(|v| {
                let d = nrw_style::color_stats(&v.photo()?);
                progress.inc(1);
                Ok(row(v, d))
            })
            .collect::<Result<_>>()?,
        Some(net) => {
            let mut rows = Vec::with_capacity(views.len());
            for batch in views.chunks(net.batch_size().max(1)) {
                rows.extend(describe_batch(cfg, net, k, batch)?);
                progress.inc(batch.len() as u64);
            }
            rows
        }
    };
    rows.sort_by_key(|r| r.image_id);
    write_part(&ds.store, k, kind, &rows)?;
    Ok(())
}

/// The descriptor row of a view.
fn row(v: &nrw_dataset::ViewRow, descriptor: Vec<f32>) -> DescriptorRow {
    DescriptorRow {
        image_id: v.image_id,
        name: v.name.clone(),
        descriptor,
    }
}

/// One backend call: the batch's photos prepared (each error names its photo), their Grams,
/// their descriptors.
fn describe_batch(
    cfg: &StyleConfig,
    net: &dyn Backend,
    k: usize,
    batch: &[nrw_dataset::ViewRow],
) -> Result<Vec<DescriptorRow>> {
    let pre = cfg.preprocess();
    let inputs: Vec<nrw_style::NetInput> = batch
        .par_iter()
        .map(|v| {
            let named = |source| PipelineError::Style {
                name: v.name.clone(),
                image_id: v.image_id,
                source,
            };
            let input = nrw_style::network_input(&cfg.tier, &v.photo()?, pre).map_err(named)?;
            Ok(input.expect("a tier with weights feeds its network"))
        })
        .collect::<Result<_>>()?;
    let named_batch = |source| PipelineError::StyleBatch {
        part: k,
        first: batch[0].name.clone(),
        last: batch[batch.len() - 1].name.clone(),
        source,
    };
    let grams = net
        .style_grams(&inputs, &cfg.tier.taps())
        .map_err(named_batch)?;
    if grams.len() != batch.len() {
        return Err(named_batch(nrw_style::StyleError::Backend {
            device: net.device(),
            problem: format!("{} Grams for {} inputs", grams.len(), batch.len()),
        }));
    }
    Ok(batch
        .iter()
        .zip(&grams)
        .map(|(v, g)| row(v, nrw_style::from_grams(&cfg.tier, g)))
        .collect())
}

/// Run one unit of style: describe the parts `unit` owns (skipping those done) and record
/// the unit. Writes only its own parts; with `overwrite` removes only its own stale parts.
pub fn style_unit(cfg: &StyleConfig, unit: Unit, progress: &dyn Progress) -> Result<StyleSummary> {
    let net = load_weights(cfg.weights.as_deref(), &cfg.tier)?;
    style_unit_on(cfg, unit, net.as_ref().map(|n| n as &dyn Backend), progress)
}

/// Style as a group stage: one descriptor part per group of `photos_per_part` photos.
struct StyleStage<'a> {
    cfg: &'a StyleConfig,
    ds: &'a Dataset,
    net: Option<&'a dyn Backend>,
    kind: &'a DescriptorKind,
}

impl GroupStage for StyleStage<'_> {
    const STAGE: &'static str = units::STYLE;
    const ITEMS: &'static str = "photos";
    type Merge = StyleMerge;

    fn done(&self, k: usize, ids: &[u32]) -> Result<bool> {
        part_done(&self.ds.store, k, self.kind, ids)
    }

    fn run(&self, k: usize, ids: &[u32], progress: &dyn Progress) -> Result<usize> {
        describe_part(self.cfg, self.ds, self.net, self.kind, k, ids, progress)?;
        Ok(ids.len())
    }

    fn merge(dataset: &Store) -> Result<StyleMerge> {
        finalize_style(dataset)
    }
}

/// Style's merge, as `finalize` runs it.
pub fn merge(dataset: &Store) -> Result<Option<StyleMerge>> {
    crate::stage::merge_stage::<StyleStage>(dataset)
}

/// Whether style units started here but none finished.
pub fn started_unfinished(dataset: &Store) -> Result<bool> {
    crate::stage::started_unfinished::<StyleStage>(dataset)
}

/// A tier with a network needs a backend of its architecture.
fn check_backend(tier: &Tier, net: Option<&dyn Backend>) -> Result<()> {
    match (tier.arch(), net) {
        (None, _) => Ok(()),
        (Some(_), None) => Err(PipelineError::config(
            Setting::Weights,
            format!("tier {} runs a network and none was given", tier.name()),
        )),
        (Some(want), Some(n)) if n.arch() != want => Err(PipelineError::config(
            Setting::Weights,
            format!(
                "tier {} runs {} and the backend holds {}",
                tier.name(),
                want.name(),
                n.arch().name()
            ),
        )),
        _ => Ok(()),
    }
}

/// [`style_unit`] on a backend the caller holds (`None` for `color-stats`): the seam another
/// backend (a GPU's) plugs into; `cfg.weights` is not read.
pub fn style_unit_on(
    cfg: &StyleConfig,
    unit: Unit,
    net: Option<&dyn Backend>,
    progress: &dyn Progress,
) -> Result<StyleSummary> {
    let t0 = Instant::now();
    check_backend(&cfg.tier, net)?;
    // A backend given with color-stats computes nothing: dropped here, it names no weights
    // and no device either (as the loading path, which loads none).
    let net = net.filter(|_| cfg.tier.needs_weights());
    if cfg.settings.photos_per_part == 0 {
        return Err(PipelineError::config(
            Setting::Key("style.photos_per_part"),
            "must be at least 1",
        ));
    }
    let kind = kind(cfg, net);
    let ds = Dataset::open(Store::open(&cfg.dataset)?)?;
    let store = &ds.store.clone();
    let mut ids: Vec<u32> = ds
        .splits()
        .iter()
        .flat_map(|(s, _)| ds.ids(s).expect("listed split").to_vec())
        .collect();
    ids.sort_unstable();
    let groups: Vec<(usize, &[u32])> = ids
        .chunks(cfg.settings.photos_per_part)
        .enumerate()
        .filter(|(k, _)| unit.owns(*k))
        .collect();
    let owned_photos: usize = groups.iter().map(|(_, g)| g.len()).sum();
    // A whole run owns every part: it refuses (or clears) other kinds anywhere; a unit only
    // among its own parts.
    if unit.is_whole() {
        clear_other_kinds(cfg, store, &kind, existing_parts(store)?.into_iter())?;
    } else {
        clear_other_kinds(cfg, store, &kind, groups.iter().map(|(k, _)| *k))?;
    }
    let stage = StyleStage {
        cfg,
        ds: &ds,
        net,
        kind: &kind,
    };
    let d = crate::stage::drive(
        &stage,
        unit,
        &ids,
        cfg.settings.photos_per_part,
        &kind.tier,
        progress,
        &|_, _| Ok(()),
    )?;
    let record = unit_record(cfg, unit, &kind, &ids, net, t0);
    crate::stage::record_unit::<StyleStage>(store, unit, &record)?;
    Ok(StyleSummary {
        dataset: store.root().to_string(),
        unit,
        tier: kind.tier,
        photos: owned_photos,
        parts_written: d.ran,
        parts_skipped: d.resumed,
        seconds: record.seconds,
    })
}

/// A style unit's record: its settings, the kept ids it covered (by hash) and its time.
fn unit_record(
    cfg: &StyleConfig,
    unit: Unit,
    kind: &DescriptorKind,
    ids: &[u32],
    net: Option<&dyn Backend>,
    t0: Instant,
) -> UnitRecord {
    let parameters = to_parameters(&StyleParameters {
        tier: kind.tier.clone(),
        weights_sha256: kind.weights_sha256.clone(),
        preprocess: kind.preprocess.clone(),
        photos: ids.len(),
        photos_per_part: cfg.settings.photos_per_part,
    });
    let ids_entry = nrw_dataset::FileEntry {
        path: "kept image ids".into(),
        bytes: ids.len() as u64,
        sha256: crate::sha256_hex(&ids.iter().flat_map(|i| i.to_le_bytes()).collect::<Vec<_>>()),
        rows: None,
    };
    UnitRecord {
        stage: units::STYLE.into(),
        index: unit.index,
        count: unit.count,
        fingerprint: crate::units::fingerprint(std::slice::from_ref(&ids_entry), &parameters),
        parameters,
        inputs: vec![ids_entry],
        scene: None,
        warnings: Vec::new(),
        groups: ids.len().div_ceil(cfg.settings.photos_per_part),
        seconds: t0.elapsed().as_secs_f64(),
        instruction_set: device_of(net),
    }
}

/// Describe every kept photo in this process, then list the parts in the manifest. Parts
/// of another kind are replaced only with `overwrite`.
pub fn style(cfg: &StyleConfig, progress: &dyn Progress) -> Result<StyleSummary> {
    let store = &Store::open(&cfg.dataset)?;
    let (s, _) = crate::stage::whole::<StyleStage, _>(store, || {
        let net = load_weights(cfg.weights.as_deref(), &cfg.tier)?;
        style_unit_on(
            cfg,
            Unit::WHOLE,
            net.as_ref().map(|n| n as &dyn Backend),
            progress,
        )
    })?;
    Ok(s)
}

/// What finalize merged for style.
#[derive(Debug, Clone, serde::Serialize)]
pub struct StyleMerge {
    pub units: usize,
    pub parts: usize,
    pub tier: String,
}
/// Merge style's units: every part present and of the units' kind, parts past the end
/// (of an earlier, larger run) removed, all parts listed in the manifest.
pub fn finalize_style(dataset: &Store) -> Result<StyleMerge> {
    let unit = check_units(dataset, units::STYLE)?;
    let kind = kind_of(dataset, &unit)?;
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
    record_instruction_sets(&mut manifest, &units::unit_records(dataset, units::STYLE)?);
    manifest.write(dataset)?;
    close_stage(dataset, units::STYLE)?;
    Ok(StyleMerge {
        units: unit.count,
        parts: unit.groups,
        tier: kind.tier,
    })
}

#[cfg(test)]
mod tests;
