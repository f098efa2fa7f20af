//! `nrw-etl ingest`: read and validate a scene and write its dataset tables and manifest.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use clap::Args;
use nrw_dataset::{FileEntry, Manifest, SceneSource, Tool, SCHEMA_VERSION};

use super::{describe, load_model, Encoding};
use crate::error::{EtlError, Result};

/// Arguments of `ingest`.
#[derive(Debug, Args)]
pub struct IngestArgs {
    /// Scene folder holding sparse/0/ (or sparse/) and images/, or a model folder itself
    pub scene: PathBuf,
    /// Dataset folder to write (created if missing; files in it are replaced atomically)
    #[arg(long)]
    pub out: PathBuf,
    /// Folder of the photos named in the model [default: <scene>/images]
    #[arg(long)]
    pub images: Option<PathBuf>,
    /// Read this encoding even if the other exists [default: bin when present, else txt]
    #[arg(long, value_enum)]
    pub format: Option<Encoding>,
}

/// The photo folder: given, or `images/` next to the model as COLMAP lays scenes out.
fn images_dir(args: &IngestArgs, model_dir: &Path) -> Result<PathBuf> {
    if let Some(d) = &args.images {
        if !d.is_dir() {
            return Err(EtlError::Usage(format!(
                "{}: --images is not a folder",
                d.display()
            )));
        }
        return Ok(d.clone());
    }
    let mut tried = vec![args.scene.join("images")];
    for up in model_dir.ancestors().skip(1).take(2) {
        tried.push(up.join("images"));
    }
    tried.iter().find(|d| d.is_dir()).cloned().ok_or_else(|| {
        EtlError::Usage(format!(
            "no photo folder found (tried {}); pass --images DIR",
            tried
                .iter()
                .map(|d| d.display().to_string())
                .collect::<Vec<_>>()
                .join(", ")
        ))
    })
}

/// Run `ingest`.
pub fn run(args: &IngestArgs) -> Result<()> {
    let (model_dir, rec) = load_model(&args.scene, args.format)?;
    let photos_dir = images_dir(args, &model_dir)?;
    let mut photos: BTreeMap<u32, Option<(u32, u32)>> = BTreeMap::new();
    let mut missing = Vec::new();
    let mut warnings: Vec<String> = rec.warnings.iter().map(|w| w.to_string()).collect();
    for img in rec.images.values() {
        let path = photos_dir.join(&img.name);
        if !path.is_file() {
            missing.push(img.name.clone());
            continue;
        }
        // Header only: no pixel is decoded here.
        let (w, h) = image::ImageReader::open(&path)
            .map_err(|e| EtlError::Photo {
                path: path.clone(),
                source: image::ImageError::IoError(e),
            })?
            .with_guessed_format()
            .map_err(|e| EtlError::Photo {
                path: path.clone(),
                source: image::ImageError::IoError(e),
            })?
            .into_dimensions()
            .map_err(|e| EtlError::Photo {
                path: path.clone(),
                source: e,
            })?;
        let cam = &rec.cameras[&img.camera_id];
        if (w as u64, h as u64) != (cam.width, cam.height) {
            warnings.push(format!(
                "{}: photo is {w}x{h} but camera {} is {}x{}",
                path.display(),
                cam.id,
                cam.width,
                cam.height
            ));
        }
        photos.insert(img.id, Some((w, h)));
    }
    if !missing.is_empty() {
        let shown: Vec<_> = missing.iter().take(5).cloned().collect();
        return Err(EtlError::Usage(format!(
            "{}: {} of {} registered photos are missing ({}{})",
            photos_dir.display(),
            missing.len(),
            rec.images.len(),
            shown.join(", "),
            if missing.len() > 5 { ", …" } else { "" }
        )));
    }
    std::fs::create_dir_all(&args.out).map_err(|e| nrw_dataset::DatasetError::io(&args.out, e))?;
    let tables = nrw_dataset::write_scene_tables(&args.out, &rec, &photos)?;
    let inputs = rec
        .files
        .iter()
        .map(|p| {
            let (bytes, sha256) = nrw_dataset::manifest::sha256_file(p)?;
            Ok(FileEntry {
                path: p.display().to_string(),
                bytes,
                sha256,
                rows: None,
            })
        })
        .collect::<Result<Vec<_>>>()?;
    let (enc, layout) = describe(&rec);
    let mut parameters = serde_json::Map::new();
    parameters.insert("format".into(), enc.into());
    let manifest = Manifest {
        schema_version: SCHEMA_VERSION,
        tool: Tool {
            name: "nrw-etl".into(),
            version: env!("CARGO_PKG_VERSION").into(),
        },
        scene: SceneSource {
            scene_dir: args.scene.display().to_string(),
            model_dir: model_dir.display().to_string(),
            images_dir: Some(photos_dir.display().to_string()),
            encoding: enc.into(),
            layout: layout.into(),
        },
        inputs,
        parameters,
        tables,
        warnings: warnings.clone(),
    };
    manifest.write(&args.out)?;
    for w in &warnings {
        eprintln!("warning: {w}");
    }
    println!(
        "ingested {} images, {} cameras from {} into {}",
        rec.images.len(),
        rec.cameras.len(),
        model_dir.display(),
        args.out.display()
    );
    for t in &manifest.tables {
        println!(
            "  {:<28} {:>6} rows  {:>9} bytes",
            t.path,
            t.rows.unwrap_or(0),
            t.bytes
        );
    }
    Ok(())
}
