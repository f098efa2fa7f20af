//! `nrw-etl style`: style descriptors of a dataset's kept photos (parallel over photos,
//! progress bar, resumable by part), or the exact Gram matrices of one image (`--image`) so
//! anyone can check parity against another implementation without writing code.

use std::path::{Path, PathBuf};

use clap::{Args, ValueEnum};
use nrw_dataset::descriptors::{
    part_path, read_part, write_part, DescriptorKind, DescriptorRow, DESCRIPTORS_DIR,
};
use nrw_dataset::reader::Dataset;
use nrw_style::{describe, Parallelism, Preprocess, Tier, Vgg};
use rayon::prelude::*;

use crate::error::{EtlError, Result};

/// `--preprocess` values.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum Pre {
    /// RGB in [0,1], minus ImageNet mean, divided by std (what the weights were trained with)
    Imagenet,
    /// v/127.5 − 1, as the paper's official code scaled its inputs
    MinusOneToOne,
}

/// Photos per descriptor part: the unit of resumption.
pub const PART_PHOTOS: usize = 64;

/// Arguments of `style`.
#[derive(Debug, Args)]
pub struct StyleArgs {
    /// Dataset folder: describe every kept photo into DATASET/descriptors/
    pub dataset: Option<PathBuf>,
    /// Descriptor tier: vgg16-<128|256|512|full>[-l<layers 1-5>], the same with vgg19,
    /// official[-N] (the published code's distance: N×N centre crop, default 512, no resize,
    /// v·2/255 − 1, per-layer mean squared Gram difference; needed for the official export's
    /// dist_<name>.pckl), or color-stats (no weights needed)
    #[arg(long, default_value = "vgg16-512")]
    pub tier: String,
    /// VGG16 or VGG19 weights: safetensors with torchvision names (features.N.weight / .bias); never downloaded
    #[arg(long)]
    pub weights: Option<PathBuf>,
    /// Replace existing descriptors of another tier or weights
    #[arg(long)]
    pub overwrite: bool,
    /// Instead of a dataset: one image as given (no resize, no crop; 8/16-bit, grey or colour; 16×16 to 2 MP)
    #[arg(long, requires = "out")]
    pub image: Option<PathBuf>,
    /// With --image: output safetensors with f32 tensors gram_relu1_2 … gram_relu5_2
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Network input scaling: torchvision's ImageNet mean/std, or the official code's v/127.5 − 1 (recorded with the descriptors; the official tier always uses the latter)
    #[arg(long, value_enum, default_value = "imagenet")]
    pub preprocess: Pre,
    /// No progress bar
    #[arg(long)]
    pub quiet: bool,
}

fn load_weights(path: Option<&Path>, tier: &Tier) -> Result<Option<Vgg>> {
    match (tier.needs_weights(), path) {
        (false, _) => Ok(None),
        (true, None) => Err(EtlError::Usage(format!(
            "--weights FILE is required for tier {} (the tool never downloads weights; any safetensors with torchvision VGG16 names works); --tier color-stats is the explicit non-neural fallback",
            tier.name()
        ))),
        (true, Some(p)) => {
            let net = Vgg::load(p).map_err(|e| EtlError::Usage(e.to_string()))?;
            if let Some(arch) = tier.arch() {
                if net.arch != arch {
                    return Err(EtlError::Usage(format!(
                        "{}: these are {} weights but tier {} needs {}",
                        p.display(),
                        net.arch.name(),
                        tier.name(),
                        arch.name()
                    )));
                }
            }
            Ok(Some(net))
        }
    }
}

/// Run `style`.
pub fn run(args: &StyleArgs) -> Result<()> {
    super::qa::timed(
        args.dataset.as_deref().filter(|_| args.image.is_none()),
        "style",
        || run_stage(args),
    )
}

fn run_stage(args: &StyleArgs) -> Result<()> {
    let pre = match args.preprocess {
        Pre::Imagenet => Preprocess::Imagenet,
        Pre::MinusOneToOne => Preprocess::MinusOneToOne,
    };
    if let Some(image) = &args.image {
        // Exact mode runs whichever VGG the weights are.
        let net = load_weights(args.weights.as_deref(), &Tier::reference())
            .or_else(|_| {
                load_weights(
                    args.weights.as_deref(),
                    &Tier::parse("vgg19-512").expect("valid tier"),
                )
            })?
            .expect("VGG tier");
        let bytes = nrw_style::image_grams_safetensors(&net, image, pre, Parallelism::Rayon(0))
            .map_err(|e| EtlError::Usage(e.to_string()))?;
        let out = args.out.as_ref().expect("clap requires --out with --image");
        nrw_dataset::atomic::write_bytes_atomic(out, &bytes)?;
        println!("{}", out.display());
        return Ok(());
    }
    let Some(dir) = &args.dataset else {
        return Err(EtlError::Usage(
            "give a DATASET folder, or --image FILE --out FILE".into(),
        ));
    };
    let tier = Tier::parse(&args.tier).ok_or_else(|| {
        EtlError::Usage(format!(
            "--tier {:?} is not a tier (vgg16-512, vgg16-256-l12, vgg16-full, color-stats, …)",
            args.tier
        ))
    })?;
    let net = load_weights(args.weights.as_deref(), &tier)?;
    let pre = tier.preprocess(pre);
    let kind = DescriptorKind {
        tier: tier.name(),
        weights_sha256: net.as_ref().map_or(String::new(), |n| n.sha256.clone()),
        // color-stats ignores the network's input scaling, so it never tells descriptors apart
        preprocess: if tier.needs_weights() {
            format!("{pre:?}")
        } else {
            String::new()
        },
    };
    let ds = Dataset::open(dir)?;
    // Existing parts of another kind are never mixed with new ones.
    if let Ok(entries) = std::fs::read_dir(dir.join(DESCRIPTORS_DIR)) {
        for e in entries.flatten() {
            let (k, _) = read_part(&e.path())?;
            if k.as_ref().is_some_and(|k| *k != kind) {
                if !args.overwrite {
                    return Err(EtlError::Usage(format!(
                        "{}: holds descriptors of {:?}, not {:?}; pass --overwrite to replace them",
                        e.path().display(),
                        k.expect("some"),
                        kind
                    )));
                }
                std::fs::remove_file(e.path())
                    .map_err(|err| nrw_dataset::DatasetError::io(e.path(), err))?;
            }
        }
    }
    let mut ids: Vec<u32> = ds
        .splits()
        .iter()
        .flat_map(|(s, _)| ds.ids(s).expect("listed split").to_vec())
        .collect();
    ids.sort_unstable();
    let groups: Vec<&[u32]> = ids.chunks(PART_PHOTOS).collect();
    let bar = super::progress_bar(ids.len(), "photos", args.quiet);
    bar.set_message(tier.name());
    let (mut done, mut skipped) = (0usize, 0usize);
    for (k, group) in groups.iter().enumerate() {
        let path = dir.join(part_path(k));
        if path.is_file() {
            let (pk, rows) = read_part(&path)?;
            if pk.as_ref() == Some(&kind)
                && rows.iter().map(|r| r.image_id).eq(group.iter().copied())
            {
                bar.inc(group.len() as u64);
                skipped += 1;
                continue;
            }
        }
        // Read the group's photos a row group at a time (sequential I/O), then describe them
        // in parallel.
        let views: Vec<_> = ds.iter_ids(group)?.collect::<std::result::Result<_, _>>()?;
        let mut rows: Vec<DescriptorRow> = views
            .par_iter()
            .map(|v| {
                let d = describe(&tier, net.as_ref(), &v.photo()?, pre, Parallelism::None)
                    .map_err(|e| {
                        EtlError::Usage(format!("photo {} (image {}): {e}", v.name, v.image_id))
                    })?;
                bar.inc(1);
                Ok(DescriptorRow {
                    image_id: v.image_id,
                    name: v.name.clone(),
                    descriptor: d,
                })
            })
            .collect::<Result<_>>()?;
        rows.sort_by_key(|r| r.image_id);
        write_part(dir, k, &kind, &rows)?;
        done += 1;
    }
    bar.finish_and_clear();
    if !args.quiet {
        eprintln!(
            "described {} photos with {} into {} ({done} parts written, {skipped} already there)",
            ids.len(),
            tier.name(),
            dir.join(DESCRIPTORS_DIR).display()
        );
    }
    Ok(())
}
