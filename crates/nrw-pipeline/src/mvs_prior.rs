//! Depth priors from `densify`'s multi-view stereo: when a dataset was rendered from a dense
//! workspace's `fused.ply`, each view's geometric depth map is carried into the stored view's
//! pixels, for the exports that write depth priors.
//!
//! A workspace view and a dataset view of one photo share the pose (the model's), so a ray
//! keeps its camera-space z in both: each stored pixel centre's ray through the stored camera
//! is projected by the workspace's (undistorted, resized) camera and takes the depth of the
//! map pixel it lands in (nearest; 0 where the map has none or the ray leaves the map).

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use glam::DVec2;
use nrw_colmap::dense::{DenseMap, MapKind, MapPass, Workspace};
use nrw_colmap::{Camera, CameraModel, Reconstruction};
use nrw_dataset::depth::DepthMap;
use nrw_dataset::ViewRow;

use crate::error::{PipelineError, Result};

/// How far the workspace's pose of a photo may differ from the dataset's before the maps are
/// not trusted to belong to it (rotation entries and translation, model units).
const POSE_TOLERANCE: f64 = 1e-9;

/// A dense workspace's geometric depth maps, by photo name.
pub struct MvsPriors {
    ws: Workspace,
    model: Reconstruction,
    by_name: HashMap<String, u32>,
}

impl MvsPriors {
    /// The workspace a dataset was rendered from, when its cloud is a `densify` workspace's
    /// `fused.ply` (a folder with `densify.json` and geometric depth maps); None otherwise.
    pub fn of_dataset(store: &nrw_dataset::Store) -> Result<Option<MvsPriors>> {
        let m = nrw_dataset::Manifest::read(store)?;
        let Some(root) = m
            .inputs
            .iter()
            .find_map(|f| workspace_of(Path::new(&f.path)))
        else {
            return Ok(None);
        };
        let ws = Workspace::new(&root);
        let model = nrw_colmap::read_model(&ws.sparse(), None)?;
        let by_name = model
            .images
            .iter()
            .map(|(id, i)| (i.name.clone(), *id))
            .collect();
        Ok(Some(MvsPriors { ws, model, by_name }))
    }

    /// Where the priors come from, for `export.json`.
    pub fn source(&self) -> String {
        format!("densify geometric depth maps ({})", self.ws.root.display())
    }

    /// View `v`'s MVS depth at its stored size with its confidence (the mean NCC of the
    /// agreeing source views, clamped to [0, 1]), or None when the workspace has no map of it.
    pub fn depth(&self, v: &ViewRow) -> Result<Option<nrw_export::Prior>> {
        let Some(id) = self.by_name.get(&v.name) else {
            return Ok(None);
        };
        let img = &self.model.images[id];
        let ws_cam = &self.model.cameras[&img.camera_id];
        let (pose, _) = nrw_colmap::Rigid3::from_colmap(v.qvec, v.tvec).ok_or_else(|| {
            PipelineError::input(v.name.as_str(), "the view's pose is not a rotation")
        })?;
        let same = (pose.matrix() - img.cam_from_world.matrix())
            .abs_diff_eq(glam::DMat3::ZERO, POSE_TOLERANCE)
            && pose
                .translation
                .abs_diff_eq(img.cam_from_world.translation, POSE_TOLERANCE);
        if !same {
            return Err(PipelineError::input(
                self.ws.sparse(),
                format!(
                    "image {:?}: the workspace's pose differs from the dataset's, so its depth \
                     map does not belong to this view (densify and ingest read different models)",
                    v.name
                ),
            ));
        }
        let path = self
            .ws
            .map(MapKind::Depth, MapPass::Geometric, &v.name)
            .map_err(|p| PipelineError::input(self.ws.root.as_path(), p))?;
        if !path.is_file() {
            return Ok(None);
        }
        let map = read_map(&path)?;
        let stored = stored_camera(v)?;
        let (w, h) = (v.width as usize, v.height as usize);
        let at = landing(ws_cam, &stored, (map.width, map.height));
        let depth = DepthMap {
            width: w,
            height: h,
            data: carry(&map, 0, &at),
        };
        let conf_path = self
            .ws
            .map(MapKind::Confidence, MapPass::Geometric, &v.name)
            .map_err(|p| PipelineError::input(self.ws.root.as_path(), p))?;
        let confidence = if conf_path.is_file() {
            let conf = read_map(&conf_path)?;
            if (conf.width, conf.height) != (map.width, map.height) {
                return Err(PipelineError::input(
                    conf_path.as_path(),
                    format!(
                        "{}×{}, but the depth map beside it is {}×{}",
                        conf.width, conf.height, map.width, map.height
                    ),
                ));
            }
            let c = carry(&conf, 0, &at);
            // No depth, no confidence: the two maps keep one validity.
            let c = c
                .iter()
                .zip(&depth.data)
                .map(|(c, z)| if *z > 0.0 { c.clamp(0.0, 1.0) } else { 0.0 })
                .collect();
            Some(c)
        } else {
            None
        };
        Ok(Some(nrw_export::Prior { depth, confidence }))
    }
}

/// A dense map file.
fn read_map(path: &Path) -> Result<DenseMap> {
    let bytes = std::fs::read(path).map_err(|e| PipelineError::io(path, e))?;
    Ok(DenseMap::from_bytes(&bytes, path)?)
}

/// The workspace folder of a cloud file named `fused.ply` beside `densify.json`.
fn workspace_of(cloud: &Path) -> Option<PathBuf> {
    let root = cloud.parent()?;
    let ws = Workspace::new(root);
    (cloud.file_name()? == "fused.ply" && ws.settings().is_file()).then(|| root.to_path_buf())
}

/// The camera of a stored view (its model and parameters at the stored size).
fn stored_camera(v: &ViewRow) -> Result<Camera> {
    let model = CameraModel::from_name(&v.model).ok_or_else(|| {
        PipelineError::input(v.name.as_str(), format!("unknown camera model {}", v.model))
    })?;
    Ok(Camera {
        id: v.camera_id,
        model,
        width: v.width as u64,
        height: v.height as u64,
        params: v.params.clone(),
    })
}

/// For each stored pixel (row-major), the workspace map pixel its centre's ray lands in
/// (same pose), or None where the ray leaves a `size` map: computed once, sampled per map.
fn landing(ws_cam: &Camera, stored: &Camera, size: (usize, usize)) -> Vec<Option<(usize, usize)>> {
    let (w, h) = (stored.width as usize, stored.height as usize);
    let mut out = Vec::with_capacity(w * h);
    for y in 0..h {
        for x in 0..w {
            let centre = DVec2::new(x as f64 + 0.5, y as f64 + 0.5);
            let p = stored
                .cam_ray_from_img(centre)
                .and_then(|ray| ws_cam.img_from_cam(ray));
            out.push(p.and_then(|p| {
                let (u, v) = (p.x.floor(), p.y.floor());
                let inside = u >= 0.0 && v >= 0.0 && u < size.0 as f64 && v < size.1 as f64;
                inside.then_some((u as usize, v as usize))
            }));
        }
    }
    out
}

/// Channel `c` of a workspace map at the stored pixels' landing places; 0 where the map has
/// no finite positive value or the ray leaves it.
fn carry(map: &DenseMap, c: usize, at: &[Option<(usize, usize)>]) -> Vec<f32> {
    at.iter()
        .map(|p| match p.map(|(u, v)| map.get(u, v, c)) {
            Some(z) if z > 0.0 && z.is_finite() => z,
            _ => 0.0,
        })
        .collect()
}
