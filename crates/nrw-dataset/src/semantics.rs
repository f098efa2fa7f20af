//! Semantic label maps (ADE20K class ids) as the paper's pipeline stores them: the standard
//! 150-class colour coding and a transient mask. The table is data, `schemas/ade20k.csv`,
//! embedded at build time so the binary needs no file.

use std::path::Path;
use std::sync::OnceLock;

use image::GrayImage;

use crate::error::{DatasetError, Result};

/// The ADE20K table: `schemas/ade20k.csv`.
pub const ADE20K_CSV: &str = include_str!("../../../schemas/ade20k.csv");

/// One class of the table.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ClassInfo {
    pub id: u8,
    pub name: String,
    pub color: [u8; 3],
    pub transient: bool,
}

/// The 150 classes indexed by id (index 0 is "unlabelled": black, not transient).
pub fn classes() -> &'static [ClassInfo] {
    static TABLE: OnceLock<Vec<ClassInfo>> = OnceLock::new();
    TABLE.get_or_init(|| {
        let mut out = vec![ClassInfo {
            id: 0,
            name: "unlabelled".into(),
            color: [0, 0, 0],
            transient: false,
        }];
        for line in ADE20K_CSV
            .lines()
            .filter(|l| !l.starts_with('#') && !l.starts_with("id,"))
        {
            let f: Vec<&str> = line.split(',').collect();
            let n = |i: usize| {
                f[i].trim()
                    .parse::<u8>()
                    .expect("schemas/ade20k.csv: numeric field")
            };
            out.push(ClassInfo {
                id: n(0),
                name: f[1].into(),
                color: [n(2), n(3), n(4)],
                transient: n(5) == 1,
            });
        }
        assert_eq!(out.len(), 151, "schemas/ade20k.csv lists 150 classes");
        out
    })
}

/// Where a photo's label map lives in a label folder: its name with `.png` (subfolders
/// kept), joined through the one name check so no photo name reaches outside the folder.
pub fn label_path(dir: &Path, photo: &str) -> Result<std::path::PathBuf> {
    let rel = Path::new(photo).with_extension("png");
    nrw_colmap::names::join_checked(dir, &rel.to_string_lossy()).map_err(|problem| {
        DatasetError::Value {
            path: dir.into(),
            record: format!("label map of photo {photo:?}"),
            field: "name".into(),
            problem,
        }
    })
}

/// Read a label map (8-bit class ids, 0 = unlabelled) and check its size against the photo's.
pub fn load_labels(path: &Path, width: u32, height: u32) -> Result<GrayImage> {
    let bytes = std::fs::read(path).map_err(|e| DatasetError::io(path, e))?;
    // Corrupt or truncated bytes make the view `unreadable` like a bad photo; a readable map
    // of the wrong kind, size or classes is a mistake of the tool that made it: an error.
    let img =
        image::load_from_memory_with_format(&bytes, image::ImageFormat::Png).map_err(|e| {
            DatasetError::Unreadable {
                path: path.into(),
                problem: format!("label map (PNG): {e}"),
            }
        })?;
    if img.color() != image::ColorType::L8 {
        return Err(DatasetError::Schema {
            path: path.into(),
            problem: format!(
                "label map must be 8-bit single-channel class ids, found {:?}",
                img.color()
            ),
        });
    }
    let g = img.into_luma8();
    if (g.width(), g.height()) != (width, height) {
        return Err(DatasetError::Schema {
            path: path.into(),
            problem: format!(
                "label map is {}x{} but its photo is {width}x{height}",
                g.width(),
                g.height()
            ),
        });
    }
    if let Some(bad) = g.as_raw().iter().find(|&&c| c as usize >= classes().len()) {
        return Err(DatasetError::Schema {
            path: path.into(),
            problem: format!("class id {bad} is not an ADE20K id (0–150)"),
        });
    }
    Ok(g)
}

/// Nearest-neighbour resize (labels must not be blended): each output pixel takes the
/// input pixel under its centre, with pixel edges mapped to edges.
pub fn resize_labels(labels: &GrayImage, width: u32, height: u32) -> GrayImage {
    let (sx, sy) = (
        labels.width() as f64 / width as f64,
        labels.height() as f64 / height as f64,
    );
    GrayImage::from_fn(width, height, |x, y| {
        let px = (((x as f64 + 0.5) * sx) as u32).min(labels.width() - 1);
        let py = (((y as f64 + 0.5) * sy) as u32).min(labels.height() - 1);
        *labels.get_pixel(px, py)
    })
}

/// The colour-coded map (RGB8) and the transient mask (255 where transient) of a label map.
pub fn colorize(labels: &GrayImage) -> (Vec<u8>, Vec<u8>) {
    let table = classes();
    let mut rgb = Vec::with_capacity(labels.as_raw().len() * 3);
    let mut mask = Vec::with_capacity(labels.as_raw().len());
    for &c in labels.as_raw() {
        let info = &table[c as usize];
        rgb.extend_from_slice(&info.color);
        mask.push(if info.transient { 255 } else { 0 });
    }
    (rgb, mask)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn label_paths_keep_subfolders_and_refuse_names_that_leave_the_folder() {
        let d = Path::new("/labels");
        assert_eq!(
            label_path(d, "cam0/0001.jpg").unwrap(),
            d.join("cam0/0001.png")
        );
        for bad in [
            "../x.jpg",
            "/etc/x.jpg",
            "a\\..\\x.jpg",
            "a/../../x.jpg",
            "a\0.jpg",
        ] {
            let e = label_path(d, bad).unwrap_err().to_string();
            assert!(
                e.contains("/labels") && e.contains("field `name`") && e.contains("label map"),
                "{bad:?}: {e}"
            );
        }
    }

    #[test]
    fn table_has_the_classes_the_synthetic_scenes_use() {
        let t = classes();
        assert_eq!(
            (t[13].name.as_str(), t[13].color, t[13].transient),
            ("person", [150, 5, 61], true)
        );
        assert_eq!((t[2].name.as_str(), t[2].transient), ("building", false));
        assert_eq!(t[43].name, "column");
        assert_eq!(t[3].name, "sky");
    }

    #[test]
    fn nearest_resize_never_invents_a_class() {
        let l = GrayImage::from_fn(7, 5, |x, y| image::Luma([((x + y) % 3) as u8 * 13]));
        let r = resize_labels(&l, 20, 13);
        assert!(r.as_raw().iter().all(|v| [0, 13, 26].contains(v)));
        let back = resize_labels(&l, 7, 5);
        assert_eq!(back, l);
    }
}
