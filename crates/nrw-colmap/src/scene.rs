//! A scene folder as COLMAP lays it out: the model in `sparse/0/` (or `sparse/`, or the
//! folder itself; with several sub-models `sparse/0`, `sparse/1`, … the one with the most
//! registered images), the photos in `images/`, the dense cloud in `dense/fused.ply`. One
//! place says where each is looked for, for every stage that reads a scene.

use std::path::{Path, PathBuf};

use crate::error::{ColmapError, Record};
use crate::{Format, Reconstruction, Result};

/// A scene: its folder and the model folder found in it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Scene {
    /// The folder given (a scene folder, or a model folder itself).
    pub dir: PathBuf,
    /// Where cameras/images/points3D were found.
    pub model_dir: PathBuf,
    /// How the model was chosen among the scene's sub-models (`sparse/N`).
    pub choice: ModelChoice,
}

/// One of a scene's numbered sub-models, `sparse/N`: COLMAP's mapper writes one per part of
/// the collection it could not connect to the others.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SubModel {
    /// N of `sparse/N`.
    pub index: u32,
    /// The folder `sparse/N`.
    pub dir: PathBuf,
    /// How many images it registered.
    pub images: usize,
}

/// Why a scene's model is the one read: users of COLMAP ask why their best model sits in
/// `sparse/1`, so every stage can say which it took.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum ModelChoice {
    /// No numbered sub-models, or just one.
    Only,
    /// The sub-model with the most registered images (ties: the lowest N) among these.
    Largest(Vec<SubModel>),
    /// The sub-model asked for (`--model N`) among these.
    Given(Vec<SubModel>),
}

impl ModelChoice {
    /// The sentence a stage prints about its choice, `None` when there was nothing to choose.
    pub fn explain(&self, model_dir: &Path) -> Option<String> {
        let (of, why) = match self {
            ModelChoice::Only => return None,
            ModelChoice::Largest(of) => (
                of,
                "the one with the most registered images; --model N takes another",
            ),
            ModelChoice::Given(of) => (of, "as --model asked"),
        };
        let listed: Vec<String> = of
            .iter()
            .map(|m| format!("sparse/{}: {} images", m.index, m.images))
            .collect();
        Some(format!(
            "the scene has {} sub-models ({}); took {} ({why})",
            of.len(),
            listed.join(", "),
            model_dir.display()
        ))
    }
}

/// The numbered sub-models of a scene folder (`sparse/N` holding a model), by N; their
/// images are counted only when there are two or more to choose from.
pub fn sub_models(dir: &Path) -> Result<Vec<SubModel>> {
    let sparse = dir.join("sparse");
    let Ok(entries) = std::fs::read_dir(&sparse) else {
        return Ok(Vec::new());
    };
    let mut found = Vec::new();
    for entry in entries {
        let entry = entry.map_err(|e| ColmapError::io(&sparse, e))?;
        // A folder name is data until it parses as N; only then is it joined into a path.
        let Some(index) = entry
            .file_name()
            .to_str()
            .and_then(|n| n.parse::<u32>().ok())
        else {
            continue;
        };
        let dir = sparse.join(index.to_string());
        if crate::load::has_model(&dir) {
            found.push(SubModel {
                index,
                dir,
                images: 0,
            });
        }
    }
    found.sort_by_key(|m| m.index);
    if found.len() >= 2 {
        for m in &mut found {
            m.images = registered_images(&m.dir)?;
        }
    }
    Ok(found)
}

/// How many images a model folder registered: images.bin's count, or the text model read.
fn registered_images(dir: &Path) -> Result<usize> {
    let bin = dir.join("images.bin");
    if crate::detect_format(dir)? == Format::Binary {
        use std::io::Read;
        let mut head = [0u8; 8];
        std::fs::File::open(&bin)
            .and_then(|mut f| f.read_exact(&mut head))
            .map_err(|e| ColmapError::io(&bin, e))?;
        return usize::try_from(u64::from_le_bytes(head)).map_err(|_| {
            ColmapError::invalid(
                &bin,
                Record::File,
                "num_reg_images",
                "does not fit in memory",
            )
        });
    }
    Ok(crate::read_model(dir, Some(Format::Text))?.images.len())
}

/// The dense cloud's place in a scene, as COLMAP's stereo fusion writes it.
pub const DENSE_CLOUD: &str = "dense/fused.ply";

impl Scene {
    /// Find the model of `dir`: the folder itself, the sub-model `sparse/N` with the most
    /// registered images, or `sparse/` below it.
    pub fn find(dir: &Path) -> Result<Scene> {
        Scene::find_sub_model(dir, None)
    }

    /// Find the model of `dir` as [`Scene::find`] does, or the sub-model `sparse/N` when
    /// `pick` is `Some(N)` (an error listing the sub-models when there is no such one).
    pub fn find_sub_model(dir: &Path, pick: Option<u32>) -> Result<Scene> {
        let subs = sub_models(dir)?;
        let scene = |model_dir: PathBuf, choice| Scene {
            dir: dir.to_path_buf(),
            model_dir,
            choice,
        };
        if let Some(n) = pick {
            let Some(m) = subs.iter().find(|m| m.index == n) else {
                let have: Vec<String> =
                    subs.iter().map(|m| format!("sparse/{}", m.index)).collect();
                return Err(ColmapError::NoSubModel {
                    path: dir.join("sparse").join(n.to_string()),
                    have: if have.is_empty() {
                        "none".into()
                    } else {
                        have.join(", ")
                    },
                });
            };
            return Ok(scene(m.dir.clone(), ModelChoice::Given(subs.clone())));
        }
        match subs.as_slice() {
            _ if crate::load::has_model(dir) => {
                return Ok(scene(dir.to_path_buf(), ModelChoice::Only))
            }
            [] => return Ok(scene(crate::find_model_dir(dir)?, ModelChoice::Only)),
            [only] => return Ok(scene(only.dir.clone(), ModelChoice::Only)),
            _ => {}
        }
        // max_by_key keeps the last of equals: iterate in reverse so ties go to the lowest N.
        let largest = subs
            .iter()
            .rev()
            .max_by_key(|m| m.images)
            .expect("two or more");
        Ok(scene(
            largest.dir.clone(),
            ModelChoice::Largest(subs.clone()),
        ))
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
