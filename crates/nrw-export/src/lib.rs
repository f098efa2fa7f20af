//! Exports of a dataset as files other tools read: the paper's published code (`official`
//! PNG folders and `tfrecord`), one folder per photo (`files`), NeRF-W's Phototourism layout
//! (`nerfw`), nerfstudio's `transforms.json` (`nerfstudio`) and the COLMAP folder the 3DGS
//! family reads (`gsplat`: image, mask and depth pyramids, graphdeco's depth priors) and
//! MegaDepth's (`megadepth`: depth `.h5`, the undistorted text model, D2-Net's `scene_info`).
//!
//! One entry point, [`export`]; one seam per layout, [`writer::LayoutWriter`] (the layouts of one
//! file set per view share [`stream`]). Every file is claimed in a hidden staging folder
//! ([`staging::Staged`]: the name check and the collision check) and the export is published
//! whole, to a local folder or under an object-store URL.

mod colmap_model;
pub mod encoders;
pub mod error;
pub mod inputs;
pub mod layouts;
pub mod staging;
pub mod stream;
pub mod summary;
pub mod writer;

// The layouts and encoders by their short names (one path per module, whatever its folder).
pub use encoders::{hdf5, inverse_depth, pyramid, record};
pub use layouts::megadepth::{self, imc};
pub use layouts::paper::{self, official, published, tfrecord};
pub use layouts::{files, gsplat, nerfbaselines, nerfstudio, nerfw};
pub use nrw_npy::{npz, pickle};

pub use error::{ExportError, Result};
pub use inputs::{DepthPrior, DistMatrix, DistRows, Inputs, Prior, ScenePoint, RENDER_DEPTH};
pub use layouts::Layout;
pub use staging::{join_under, EXPORT_JSON};
pub use stream::index_width;
pub use summary::{DepthRecord, ExportConfig, ExportSummary, LicenceFilter, Skipped, SplitExport};
pub use tfrecord::tfrecord_name;
pub use writer::About;

use nrw_dataset::reader::Dataset;

/// Export `ds` in `layout` as `cfg` says into `cfg.out` (a folder or an object-store URL),
/// replacing an earlier export there whole; `tick` is called once per view done.
pub fn export(
    ds: &Dataset,
    layout: Layout,
    cfg: &ExportConfig,
    inputs: &Inputs,
    tick: &(dyn Fn() + Sync),
) -> Result<ExportSummary> {
    let attributions = nrw_dataset::photo_info::read_attributions(&ds.store)?;
    let filtered;
    let (ds, licences) = match &cfg.licences {
        Some(kept) => {
            let left_out: std::collections::BTreeSet<u32> = ds
                .all_ids()
                .into_iter()
                .filter(|id| {
                    let licence = attributions
                        .get(id)
                        .map_or(nrw_dataset::photo_info::UNKNOWN, |a| a.licence.as_str());
                    !kept.iter().any(|k| k == licence)
                })
                .collect();
            filtered = ds.without(&left_out);
            let filter = LicenceFilter {
                kept: kept.clone(),
                left_out: left_out.len(),
            };
            (&filtered, Some(filter))
        }
        None => (ds, None),
    };
    let (about, writer) = layout.parts();
    let job = writer::Job {
        ds,
        about,
        cfg,
        splits: ds.splits(),
        inputs,
        tick,
    };
    writer.check(&job)?;
    let staged = staging::Staged::new(&cfg.out)?;
    let mut summary = ExportSummary::begin(&ds.dir.to_string(), about.name, cfg);
    summary.licences = licences;
    let written = writer.write(&job, &staged, &mut summary).and_then(|()| {
        staged.write(
            nrw_dataset::photo_info::ATTRIBUTION_FILE,
            &attribution(&summary, &attributions),
        )?;
        staged.write(
            EXPORT_JSON,
            &serde_json::to_vec_pretty(&summary).expect("json"),
        )
    });
    match written {
        Ok(()) => {
            staged.publish()?;
            Ok(summary)
        }
        Err(e) => {
            staged.abandon();
            Err(e)
        }
    }
}

/// `attribution.csv` of what the export wrote: one row per exported photo, in split order,
/// "unknown" where the dataset records no licence.
fn attribution(
    summary: &ExportSummary,
    attributions: &std::collections::BTreeMap<u32, nrw_dataset::photo_info::Attribution>,
) -> Vec<u8> {
    let unknown = nrw_dataset::photo_info::Attribution::default();
    let rows = summary.splits.iter().flat_map(|s| {
        s.image_ids
            .iter()
            .zip(&s.names)
            .map(|(id, name)| (name.as_str(), attributions.get(id).unwrap_or(&unknown)))
    });
    nrw_dataset::photo_info::attribution_csv(rows)
}
