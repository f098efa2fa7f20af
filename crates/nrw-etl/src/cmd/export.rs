//! `nrw-etl export`: a dataset as plain files. `official` is the layout the paper's published
//! TensorFlow code reads; `files` is one folder per photo for ordinary viewers.

use std::path::{Path, PathBuf};

use clap::{Args, ValueEnum};
use nrw_dataset::atomic::write_bytes_atomic;

use crate::error::{EtlError, Result};

/// `--layout` values.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum Layout {
    /// train/ and val/ with %04d_reference.png, %04d_color.png (RGBA), %04d_depth.png (16-bit), %04d_seg_rgb.png
    Official,
    /// SPLIT/NAME/{photo.png, color.png, depth.exr, normal.png, semantics.png, transient.png, meta.json}
    Files,
}

/// Arguments of `export`.
#[derive(Debug, Args)]
pub struct ExportArgs {
    /// Dataset folder written by `ingest` (and `split`)
    pub dataset: PathBuf,
    /// Which layout to write
    #[arg(long, value_enum, default_value = "official")]
    pub layout: Layout,
    /// Folder to write into
    #[arg(long)]
    pub out: PathBuf,
}

/// 16-bit depth PNG: value = round(depth / depth_max · 65535), at least 1 where depth > 0, 0 where empty.
pub fn depth_png(depth: &nrw_dataset::depth::DepthMap, depth_max: f64) -> Result<Vec<u8>> {
    use image::ImageEncoder;
    let mut raw = Vec::with_capacity(depth.data.len() * 2);
    for &d in &depth.data {
        let v = if d > 0.0 {
            ((d as f64 / depth_max * 65535.0).round() as u32).clamp(1, 65535) as u16
        } else {
            0
        };
        raw.extend_from_slice(&v.to_ne_bytes()); // the encoder takes native-endian samples
    }
    let mut out = Vec::new();
    image::codecs::png::PngEncoder::new(&mut out)
        .write_image(
            &raw,
            depth.width as u32,
            depth.height as u32,
            image::ExtendedColorType::L16,
        )
        .map_err(|e| EtlError::Usage(format!("cannot encode 16-bit depth PNG: {e}")))?;
    Ok(out)
}

fn write(path: &Path, bytes: &[u8]) -> Result<()> {
    write_bytes_atomic(path, bytes)?;
    Ok(())
}

/// Run `export`.
pub fn run(args: &ExportArgs) -> Result<()> {
    super::qa::timed(Some(args.dataset.as_path()), "export", || run_stage(args))
}

fn run_stage(args: &ExportArgs) -> Result<()> {
    let ds = super::require_views(&args.dataset)?;
    let splits: Vec<String> = ds.splits().into_iter().map(|(k, _)| k).collect();
    if args.layout == Layout::Official && !splits.iter().any(|s| s == "train") {
        return Err(EtlError::Usage(format!(
            "{}: the official layout needs train/ and val/; run `nrw-etl split {} --val N` first (--val 0 puts every photo in train)",
            args.dataset.display(),
            args.dataset.display()
        )));
    }
    // The depth scale: the largest depth of the dataset (recorded per view by ingest) maps to 65535.
    let depth_max = nrw_dataset::scene::read_depth_max(&args.dataset)?.unwrap_or(1.0);
    let mut written = 0usize;
    for split in &splits {
        let dir = args.out.join(split);
        for (k, v) in ds.iter_split(split)?.enumerate() {
            let v = v?;
            match args.layout {
                Layout::Official => {
                    write(&dir.join(format!("{k:04}_reference.png")), &v.photo_png)?;
                    write(&dir.join(format!("{k:04}_color.png")), &v.color_png)?;
                    write(
                        &dir.join(format!("{k:04}_depth.png")),
                        &depth_png(&v.depth()?, depth_max)?,
                    )?;
                    if let Some(s) = &v.semantics_png {
                        write(&dir.join(format!("{k:04}_seg_rgb.png")), s)?;
                    }
                }
                Layout::Files => {
                    let d = dir.join(Path::new(&v.name).with_extension(""));
                    write(&d.join("photo.png"), &v.photo_png)?;
                    write(&d.join("color.png"), &v.color_png)?;
                    write(&d.join("depth.exr"), &v.depth_exr)?;
                    for (name, payload) in [
                        ("normal.png", &v.normal_png),
                        ("semantics.png", &v.semantics_png),
                        ("transient.png", &v.transient_png),
                    ] {
                        if let Some(p) = payload {
                            write(&d.join(name), p)?;
                        }
                    }
                    let meta = serde_json::json!({
                        "image_id": v.image_id, "name": v.name, "camera_id": v.camera_id, "model": v.model,
                        "width": v.width, "height": v.height, "params": v.params,
                        "qvec": v.qvec, "tvec": v.tvec, "empty_ratio": v.empty_ratio,
                    });
                    write(
                        &d.join("meta.json"),
                        serde_json::to_string_pretty(&meta)
                            .expect("json")
                            .as_bytes(),
                    )?;
                }
            }
            written += 1;
        }
    }
    if args.layout == Layout::Official {
        // Beside the split folders, not in them: those hold exactly the paper's files.
        let index: serde_json::Map<String, serde_json::Value> = splits
            .iter()
            .map(|s| Ok((s.clone(), serde_json::json!(ds.ids(s)?))))
            .collect::<Result<_>>()?;
        write(
            &args.out.join("index.json"),
            serde_json::to_string_pretty(&index)
                .expect("json")
                .as_bytes(),
        )?;
    }
    let scale = serde_json::json!({
        "depth_max": depth_max,
        "depth_png": "value = round(depth / depth_max * 65535), at least 1 where depth > 0; 0 = empty; depth = value / 65535 * depth_max (camera-space z, model units)",
    });
    write(
        &args.out.join("depth_scale.json"),
        serde_json::to_string_pretty(&scale)
            .expect("json")
            .as_bytes(),
    )?;
    println!(
        "exported {written} views of {} to {} ({:?} layout)",
        args.dataset.display(),
        args.out.display(),
        args.layout
    );
    Ok(())
}
