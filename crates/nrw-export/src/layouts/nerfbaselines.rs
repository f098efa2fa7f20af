//! The Phototourism folder nerfbaselines' downloader makes (`external://phototourism/SCENE`)
//! and its `colmap` loader reads, which WildGaussians and the other in-the-wild methods
//! nerfbaselines runs train on:
//!
//! ```text
//! OUT/images/FILE                 each view's photo as stored (FILE = its name with .png)
//! OUT/sparse/{cameras,images,points3D}.bin   PINHOLE, one camera per image, the SfM points the
//!                                 images observe with their tracks (`crate::colmap_model`)
//! OUT/masks/FILE                  with labels: 255 = use the pixel, 0 = ignore (transient)
//! OUT/nerfw_split.csv             NeRF-W's split file (tab-separated: filename id split dataset)
//! OUT/train_list.txt, test_list.txt   the split as the loader reads it (test = our val)
//! OUT/nb-info.json                loader `colmap` (images, sparse), id `phototourism`,
//!                                 evaluation protocol `nerfw`
//! ```
//!
//! `nb-info.json`'s id `phototourism` is what selects the methods' in-the-wild settings
//! (appearance embeddings, the NeRF-W evaluation that optimises an embedding on the left half of
//! each test image); `scene` is the export's name. The loader reads its initialisation points
//! from `points3D.bin` only (as it does on the Phototourism release, whose model is COLMAP's
//! SfM), so a dense cloud the dataset was rendered from is not written here: the gsplat layout
//! carries it for graphdeco.

use serde_json::json;

use crate::error::Result;
use crate::nerfw::{write_phototourism, Places};
use crate::staging::Staged;
use crate::writer::{About, Job, WithModel};
use crate::SplitExport;

/// The `nerfbaselines` layout, as the CLI, pipeline files and `export.json` name it.
pub const ABOUT: About = About {
    name: "nerfbaselines",
    summary: "the Phototourism folder nerfbaselines reads (WildGaussians and other in-the-wild methods): images/, sparse/ (one PINHOLE camera per image, the scene's points), masks/ (255 = use), nerfw_split.csv, train_list.txt / test_list.txt and nb-info.json (loader colmap, id phototourism, NeRF-W evaluation); needs PINHOLE cameras (`ingest.undistort`)",
    needs_points: true,
    writes_depth_priors: false,
    default_crop: None,
};

/// nerfbaselines' Phototourism layout.
pub static NERFBASELINES: WithModel = WithModel(write);

/// Write the layout into `staged`. Returns the splits written and the consumer warnings.
fn write(
    job: &Job,
    model: &nrw_colmap::Reconstruction,
    staged: &Staged,
) -> Result<(Vec<SplitExport>, Vec<String>)> {
    let places = Places {
        images: "images",
        sparse: "sparse",
    };
    let masks = |v: &nrw_dataset::ViewRow, file: &str| -> Result<()> {
        if let Some(m) = crate::gsplat::use_mask(v)? {
            let png = nrw_dataset::codec::encode_gray(&v.name, v.width, v.height, &m)?;
            staged.write(&format!("masks/{file}"), &png)?;
        }
        Ok(())
    };
    let w = write_phototourism(job, model, staged, &places, &masks)?;
    staged.write("nerfw_split.csv", crate::nerfw::tsv(&w.rows).as_bytes())?;
    crate::gsplat::write_split_lists(&w.splits, staged)?;
    let info = json!({
        "loader": "colmap",
        "loader_kwargs": {"images_path": "images", "colmap_path": "sparse"},
        "id": "phototourism",
        "scene": job.cfg.name,
        "type": null,
        "evaluation_protocol": "nerfw",
    });
    staged.write(
        "nb-info.json",
        &serde_json::to_vec_pretty(&info).expect("json"),
    )?;
    Ok((w.splits, Vec::new()))
}
