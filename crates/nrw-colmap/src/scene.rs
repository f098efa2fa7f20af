//! A scene folder as COLMAP lays it out: the model in `sparse/0/` (or `sparse/`, or the
//! folder itself), the photos in `images/`, the dense cloud in `dense/fused.ply`. One place
//! says where each is looked for, for every stage that reads a scene.

use std::path::{Path, PathBuf};

use crate::{Format, Reconstruction, Result};

/// A scene: its folder and the model folder found in it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Scene {
    /// The folder given (a scene folder, or a model folder itself).
    pub dir: PathBuf,
    /// Where cameras/images/points3D were found.
    pub model_dir: PathBuf,
}

/// The dense cloud's place in a scene, as COLMAP's stereo fusion writes it.
pub const DENSE_CLOUD: &str = "dense/fused.ply";

impl Scene {
    /// Find the model of `dir`: the folder itself, `sparse/0/` or `sparse/` below it.
    pub fn find(dir: &Path) -> Result<Scene> {
        Ok(Scene {
            dir: dir.to_path_buf(),
            model_dir: crate::find_model_dir(dir)?,
        })
    }

    /// Read the model, in `format` or the encoding present (binary first).
    pub fn read(&self, format: Option<Format>) -> Result<Reconstruction> {
        crate::read_model(&self.model_dir, format)
    }

    /// The folders a scene's other files are looked for in, in order: the scene folder, then
    /// the model folder's parent and grandparent (a model given as `SCENE/sparse/0`).
    pub fn roots(&self) -> Vec<PathBuf> {
        std::iter::once(self.dir.clone())
            .chain(
                self.model_dir
                    .ancestors()
                    .skip(1)
                    .take(2)
                    .map(Path::to_path_buf),
            )
            .collect()
    }

    /// Where the photo folder is looked for, in order (`images/` in each root).
    pub fn image_dir_candidates(&self) -> Vec<PathBuf> {
        self.roots().iter().map(|r| r.join("images")).collect()
    }

    /// The photo folder, if one of the candidates is a folder.
    pub fn images_dir(&self) -> Option<PathBuf> {
        self.image_dir_candidates().into_iter().find(|d| d.is_dir())
    }

    /// The dense cloud (`dense/fused.ply` in the first root that has one), if any.
    pub fn dense_cloud(&self) -> Option<PathBuf> {
        self.roots()
            .iter()
            .map(|r| r.join(DENSE_CLOUD))
            .find(|p| p.is_file())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn files_are_found_beside_the_model_or_in_the_scene_folder() {
        let tmp = std::env::temp_dir().join(format!("nrw-scene-{}", std::process::id()));
        let model = tmp.join("sparse/0");
        std::fs::create_dir_all(&model).unwrap();
        std::fs::write(model.join("cameras.txt"), "").unwrap();
        let s = Scene::find(&tmp).unwrap();
        assert_eq!(s.model_dir, model);
        assert_eq!(s.images_dir(), None);
        assert_eq!(s.dense_cloud(), None);
        std::fs::create_dir_all(tmp.join("images")).unwrap();
        std::fs::create_dir_all(tmp.join("dense")).unwrap();
        std::fs::write(tmp.join(DENSE_CLOUD), "ply").unwrap();
        assert_eq!(s.images_dir(), Some(tmp.join("images")));
        assert_eq!(s.dense_cloud(), Some(tmp.join(DENSE_CLOUD)));
        // Given the model folder itself, the scene's files are found two levels up.
        let m = Scene::find(&model).unwrap();
        assert_eq!(m.model_dir, model);
        assert_eq!(m.images_dir(), Some(tmp.join("images")));
        assert_eq!(m.dense_cloud(), Some(tmp.join(DENSE_CLOUD)));
        std::fs::remove_dir_all(&tmp).unwrap();
    }
}
