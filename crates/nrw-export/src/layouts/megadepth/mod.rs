//! MegaDepth's layout, as D2-Net's `megadepth_utils/preprocess_scene.py` reads a scene and as
//! matcher trainers (D2-Net, LoFTR and its family) read the `scene_info` it writes:
//!
//! ```text
//! OUT/Undistorted_SfM/NAME/images/FILE                       photos (FILE = name with .png)
//! OUT/Undistorted_SfM/NAME/sparse-txt/{cameras,images,points3D}.txt
//! OUT/phoenix/S6/zl548/MegaDepth_v1/NAME/dense0/depths/STEM.h5   key `depth`, float32 h × w,
//!                                                           z in model units, 0 = none
//! OUT/scene_info/NAME.npz                                   what preprocess_scene.py writes
//! OUT/dust3r/NAME/0/STEM.{jpg,exr,npz}                       DUSt3R's preprocessed MegaDepth:
//!                                                           photo, depth ("Y"), {intrinsics,
//!                                                           cam2world}
//! OUT/dust3r/all_metadata.npz                               scenes, images, scored pairs
//! OUT/index/scene_info_0.1_0.7/NAME_LO_HI.npz                LoFTR's index, one file an overlap
//!                                                           band (0.1_0.3, 0.3_0.5, 0.5_0.7)
//! OUT/index/trainvaltest_list/train_list.txt                 those files' stems
//! OUT/prep_scene_info/NAME.npy                               RoMa's / DKM's scene info: every
//!                                                           pair sharing points, its overlap
//! OUT/imc2022/train/…                                       IMC 2022's training layout: see
//!                                                           [`crate::imc`]
//! ```
//!
//! The model is PINHOLE, one camera per image with the image's id (the script reads
//! `params[0..4]` as fx, fy, cx, cy), the views' poses, and each view's SfM observations: the
//! scene model's keypoints carried into the stored view through its camera (scaled, and
//! undistorted when the dataset was), so tracks and depth maps share one image frame.
//! `scene_info` follows the script line by line (see [`SceneInfo`]); every view has a depth
//! file, so no entry is `None`.
//!
//! A pair's overlap score in LoFTR's, RoMa's and DUSt3R's files is the smaller of its two
//! `overlap_matrix` entries (shared points over each view's points): LoFTR publishes its index,
//! not how it was scored. LoFTR's `central_matches` hold one match a pair in D2-Net's
//! `central_match` layout `[y_i, x_i, y_j, x_j]`: the shared point nearest view i's principal
//! point (D2-Net draws one at random; LoFTR's loader does not read it). LoFTR's and RoMa's
//! files are pickled dicts as their loaders `np.load(…, allow_pickle=True)` them: LoFTR's a
//! bare pickle (numpy falls back to `pickle.load`), RoMa's a 0-d object array in an `.npy`.

pub mod imc;
mod scene_info;
mod view;

use std::collections::BTreeMap;

use nrw_colmap::{Camera, Reconstruction};
use nrw_dataset::ViewRow;

use crate::error::{ExportError, Result};
use crate::imc::ImcView;
use crate::npz::{self, Array};
use crate::staging::Staged;
use crate::writer::{About, Job, LayoutWriter};
use crate::{ExportSummary, SplitExport};
use scene_info::{rotation, write_pair_indices};
pub use scene_info::{SceneInfo, SceneView, LOFTR_BANDS};
use view::View;

/// The script's rule for a depth file: under this size it is taken for a mask and the image
/// is dropped (`file_size < 100 * 1024`).
pub const D2NET_MIN_DEPTH_BYTES: usize = 100 * 1024;

/// The `megadepth` layout, as the CLI, pipeline files and `export.json` name it.
pub const ABOUT: About = About {
    name: "megadepth",
    summary: "MegaDepth's layout for matcher trainers: Undistorted_SfM/NAME/{images/, sparse-txt/ (PINHOLE, the views' SfM observations)}, phoenix/S6/zl548/MegaDepth_v1/NAME/dense0/depths/*.h5 (key `depth`, float32, 0 = none) and scene_info/NAME.npz as D2-Net's preprocess_scene.py writes it (paths, K, poses, overlap, scale ratios, angles), LoFTR's index/, RoMa's prep_scene_info/, DUSt3R's dust3r/ and IMC 2022's imc2022/train/NAME/{calibration,pair_covisibility}.csv; needs PINHOLE cameras (`ingest.undistort`)",
    needs_points: true,
    writes_depth_priors: true,
    default_crop: None,
};

/// The MegaDepth layout.
pub struct Megadepth;

impl LayoutWriter for Megadepth {
    fn check(&self, job: &Job) -> Result<()> {
        job.scene_model().map(|_| ())?;
        let name = &job.cfg.name;
        if name.is_empty() || name.contains(['/', '\\']) || name.contains(char::is_whitespace) {
            return Err(ExportError::refused(
                &job.cfg.out,
                format!(
                    "the scene name {name:?} (`--name`) must be one folder name without spaces: \
                     MegaDepth's paths and preprocess_scene.py's --scene_id take it as one"
                ),
            ));
        }
        if job.splits.iter().all(|(_, n)| *n == 0) {
            return Err(ExportError::refused(&job.ds.dir, "the dataset has no view"));
        }
        Ok(())
    }

    fn write(&self, job: &Job, staged: &Staged, summary: &mut ExportSummary) -> Result<()> {
        let rec = job.scene_model()?;
        let name = &job.cfg.name;
        let mut views = BTreeMap::new();
        for (split, n) in &job.splits {
            if *n == 0 {
                summary.empty_splits.push(split.clone());
                continue;
            }
            let mut s = SplitExport::new(split);
            for v in job.ds.iter_split(split)? {
                let v = v?;
                let view = write_view(job, &v, rec, name, staged)?;
                s.image_ids.push(v.image_id);
                s.names.push(v.name.clone());
                s.files.push(view.image_path.clone());
                views.insert(v.image_id, view);
                (job.tick)();
            }
            summary.splits.push(s);
        }
        write_sparse_txt(&views, rec, name, staged)?;
        let info = SceneInfo::of(&views, rec);
        staged.write_seekable(&format!("scene_info/{name}.npz"), |w| info.write_npz(w))?;
        let stems: Vec<String> = views.values().map(|v| v.stem.clone()).collect();
        staged.write_seekable("dust3r/all_metadata.npz", |w| {
            info.write_dust3r(name, &stems, w)
        })?;
        write_pair_indices(name, &info, staged)?;
        let imc: Vec<ImcView> = views
            .values()
            .enumerate()
            .map(|(i, v)| info.imc_view(i, &v.stem, &v.jpg, v.camera.width, v.camera.height))
            .collect();
        let pairs_of = |i: usize| info.shared_pairs_of(i);
        let unit = job.cfg.imc.metres_per_unit;
        summary
            .warnings
            .extend(crate::imc::write(name, &imc, &pairs_of, unit, staged)?);
        summary.warnings.extend(consumer_warnings(&views));
        summary.depth_source = Some(job.depth_source());
        Ok(())
    }
}

/// The folder of a scene's model and photos.
fn sfm_dir(name: &str) -> String {
    format!("Undistorted_SfM/{name}")
}

/// The folder of a scene's depth files.
fn depth_dir(name: &str) -> String {
    format!("phoenix/S6/zl548/MegaDepth_v1/{name}/dense0/depths")
}

/// Write one view's photo and depth file; its model entries.
fn write_view(
    job: &Job,
    v: &ViewRow,
    rec: &Reconstruction,
    name: &str,
    staged: &Staged,
) -> Result<View> {
    let file = crate::nerfw::file_name(&v.name);
    if file.contains(char::is_whitespace) {
        return Err(ExportError::Value {
            path: v.name.clone().into(),
            record: format!("image {}", v.image_id),
            field: "name".into(),
            problem: "contains white space: COLMAP's text model and preprocess_scene.py split \
                      lines on spaces, so the name would be misread"
                .into(),
        });
    }
    let camera = crate::nerfw::pinhole(
        v,
        "MegaDepth's readers (D2-Net's preprocess_scene.py, the matchers' loaders) take a \
         PINHOLE camera's K and no distortion",
    )?;
    let image_path = format!("{}/images/{file}", sfm_dir(name));
    staged.write(&image_path, &v.photo_png)?;
    let depth = job.prior_depth(v)?;
    let stem = file.rsplit_once('.').map_or(file.as_str(), |(s, _)| s);
    let depth_path = format!("{}/{stem}.h5", depth_dir(name));
    let h5 = crate::hdf5::float32_2d(
        "depth",
        depth.height as u64,
        depth.width as u64,
        &depth.data,
    );
    staged.write(&depth_path, &h5)?;
    let image = crate::nerfw::model_image(v, &file)?;
    let jpg = write_dust3r_view(v, &depth, &camera, &image, name, stem, staged)?;
    Ok(View {
        points2d: crate::colmap_model::observations(v, rec, &camera)?,
        qvec: image.cam_from_world.qvec(),
        tvec: image.cam_from_world.translation.to_array(),
        depth_bytes: h5.len(),
        stem: stem.to_string(),
        jpg,
        file,
        image_path,
        depth_path,
        camera,
    })
}

/// DUSt3R's three files of a view (its `preprocess_megadepth.py` output, at the stored size):
/// the photo as JPEG (quality 90, as that script saves it), the depth as a one-channel "Y"
/// EXR (OpenCV's reading), and `{intrinsics, cam2world}`; the JPEG's export-relative path.
fn write_dust3r_view(
    v: &ViewRow,
    depth: &nrw_dataset::depth::DepthMap,
    camera: &Camera,
    image: &nrw_colmap::Image,
    name: &str,
    stem: &str,
    staged: &Staged,
) -> Result<String> {
    let dir = format!("dust3r/{name}/0/{stem}");
    let jpg = nrw_dataset::codec::encode_jpeg(&v.name, &v.photo()?, 90)?;
    staged.write(&format!("{dir}.jpg"), &jpg)?;
    let exr = nrw_dataset::depth::encode_exr_channel(depth, "Y")?;
    staged.write(&format!("{dir}.exr"), &exr)?;
    let p = &camera.params;
    // OpenCV's convention (pixel centres at whole numbers), DUSt3R's: its preprocessing takes K
    // from cv2.getOptimalNewCameraMatrix and its cropping moves K to COLMAP's by +0.5 and back.
    let k = [p[0], 0.0, p[2] - 0.5, 0.0, p[1], p[3] - 0.5, 0.0, 0.0, 1.0];
    let r = rotation(image.cam_from_world.qvec());
    let t = image.cam_from_world.translation.to_array();
    let mut c2w = [0.0; 16];
    for row in 0..3 {
        for col in 0..3 {
            c2w[row * 4 + col] = r[col][row];
        }
        c2w[row * 4 + 3] = -(0..3).map(|m| r[m][row] * t[m]).sum::<f64>();
    }
    c2w[15] = 1.0;
    let npz = npz::npz(&[
        ("intrinsics", Array::f64(&[3, 3], &k).npy()),
        ("cam2world", Array::f64(&[4, 4], &c2w).npy()),
    ]);
    staged.write(&format!("{dir}.npz"), &npz)?;
    Ok(format!("{dir}.jpg"))
}

/// `sparse-txt`: the views' PINHOLE cameras and images with their observations, and the
/// points they observe with tracks rebuilt from those observations.
fn write_sparse_txt(
    views: &BTreeMap<u32, View>,
    rec: &Reconstruction,
    name: &str,
    staged: &Staged,
) -> Result<()> {
    let model = views.iter().map(|(&id, v)| {
        let (cam_from_world, norm) =
            nrw_colmap::Rigid3::from_colmap(v.qvec, v.tvec).expect("a pose read from the dataset");
        let image = nrw_colmap::Image {
            id,
            name: v.file.clone(),
            camera_id: id,
            cam_from_world,
            stored_quat_norm: norm,
            points2d: v.points2d.clone(),
        };
        (v.camera.clone(), image)
    });
    let out = crate::colmap_model::with_tracks(model, rec);
    let dir = format!("{}/sparse-txt", sfm_dir(name));
    crate::colmap_model::write(&out, staged, &dir, nrw_colmap::Format::Text)
}

/// Where D2-Net's script would silently misread or fail on this export.
fn consumer_warnings(views: &BTreeMap<u32, View>) -> Vec<String> {
    let mut out = Vec::new();
    let small: Vec<&str> = views
        .values()
        .filter(|v| v.depth_bytes < D2NET_MIN_DEPTH_BYTES)
        .map(|v| v.file.as_str())
        .collect();
    if let Some(first) = small.first() {
        out.push(format!(
            "D2-Net's preprocess_scene.py takes a depth file under 100 KiB for a mask and drops \
             the image: {} view(s) (first {first}) are that small (render at a larger \
             --min-dim); this export's scene_info keeps them",
            small.len()
        ));
    }
    let blind: Vec<&str> = views
        .values()
        .filter(|v| v.points2d.is_empty())
        .map(|v| v.file.as_str())
        .collect();
    if let Some(first) = blind.first() {
        out.push(format!(
            "D2-Net's preprocess_scene.py divides by a view's number of SfM points and fails \
             (ZeroDivisionError) on {} view(s) with none (first {first}); this export's \
             scene_info gives them overlap 0",
            blind.len()
        ));
    }
    out
}
