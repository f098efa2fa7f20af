//! What the paper's published code expects inside its files: the semantic colour coding of
//! `segment_dataset.py`, depth in 0…255 (its loaders scale every channel by 2/255 − 1), and
//! `utils.get_central_crop`.

use std::sync::OnceLock;

use image::{GrayImage, RgbImage};
use serde::Serialize;

/// The official colour coding: `schemas/official_colors.csv`.
pub const OFFICIAL_COLORS_CSV: &str = include_str!("../../../../../schemas/official_colors.csv");

/// RGB of each ADE20K id 0…150 in the official coding.
pub fn official_colors() -> &'static [[u8; 3]; 151] {
    static TABLE: OnceLock<[[u8; 3]; 151]> = OnceLock::new();
    TABLE.get_or_init(|| {
        let rows: Vec<Vec<&str>> = OFFICIAL_COLORS_CSV
            .lines()
            .filter(|l| !l.starts_with('#') && !l.starts_with("id,") && !l.is_empty())
            .map(|l| l.split(',').collect())
            .collect();
        let rgb = |f: &[&str]| -> [u8; 3] {
            [2, 3, 4].map(|i| {
                f[i].trim()
                    .parse()
                    .expect("schemas/official_colors.csv: r, g, b are 0-255")
            })
        };
        let other = rows
            .iter()
            .find(|f| f[0] == "other")
            .expect("schemas/official_colors.csv has an `other` row");
        let mut t = [rgb(other); 151];
        for f in rows.iter().filter(|f| f[0] != "other") {
            let id: usize = f[0].parse().expect("schemas/official_colors.csv: id");
            t[id] = rgb(f);
        }
        t
    })
}

/// The crop the published pipeline leaves every channel at: `segment_dataset.py` writes
/// `*_seg_rgb.png` as the 512 × 512 centre crop, `dataset_utils.AlignedRenderedDataset` crops
/// the other channels to it, and `pretrain_appearance` crops all but seg to its resolution.
pub const PUBLISHED_CROP: u32 = 512;

/// What the paper's layouts (official, tfrecord) are written with; [`PaperOptions::published`]
/// is what the published code runs with.
#[derive(Debug, Clone, PartialEq)]
pub struct PaperOptions {
    /// A centred `crop` × `crop` of every channel (the published code's 512); views smaller
    /// than it are skipped and listed. The files layout refuses one (it keeps views whole).
    pub crop: Option<u32>,
    /// Write semantics: a dataset without them is refused unless this is false.
    pub semantics: bool,
    /// How depth becomes the 8-bit levels the published code reads.
    pub depth: DepthMapping,
    /// TFRecord files per split (1: `<name>_<split>.tfrecord`).
    pub tfrecord_files: usize,
}

impl PaperOptions {
    /// The published code's: a 512 crop, semantics, linear depth, one TFRecord file a split.
    pub fn published() -> PaperOptions {
        PaperOptions {
            crop: Some(PUBLISHED_CROP),
            semantics: true,
            depth: DepthMapping::Linear,
            tfrecord_files: 1,
        }
    }
}

/// ADE20K class ids → the official colour-coded RGB image (`*_seg_rgb.png`).
pub fn official_seg_rgb(labels: &GrayImage) -> RgbImage {
    let t = official_colors();
    let mut out = RgbImage::new(labels.width(), labels.height());
    for (o, l) in out.pixels_mut().zip(labels.pixels()) {
        // Ids are checked to be ≤ 150 at ingest; anything else takes the `other` colour.
        o.0 = t[(l[0] as usize).min(150)];
    }
    out
}

/// How camera-space depth becomes the 0…255 the published loaders expect.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum DepthMapping {
    /// Levels evenly spaced in depth between the dataset's near and far.
    Linear,
    /// Levels evenly spaced in inverse depth (disparity): finer near the camera.
    Inverse,
}

impl DepthMapping {
    /// Every mapping, in the order help lists them.
    pub const ALL: [DepthMapping; 2] = [DepthMapping::Linear, DepthMapping::Inverse];

    /// The mapping's name on the command line, in pipeline files and in `export.json`.
    pub fn name(self) -> &'static str {
        match self {
            DepthMapping::Linear => "linear",
            DepthMapping::Inverse => "inverse",
        }
    }

    /// What the mapping does, in one line (the CLI's help for each value).
    pub fn summary(self) -> &'static str {
        match self {
            DepthMapping::Linear => "Levels even in depth between the dataset's nearest and farthest depth (more levels on the landmark in docs/bench/official_export.md)",
            DepthMapping::Inverse => "Levels even in inverse depth between the dataset's nearest and farthest depth (finer near the camera)",
        }
    }
}

impl std::str::FromStr for DepthMapping {
    type Err = String;

    /// A mapping by its name; the error lists the names.
    fn from_str(s: &str) -> std::result::Result<DepthMapping, String> {
        DepthMapping::ALL
            .into_iter()
            .find(|m| m.name() == s)
            .ok_or_else(|| format!("{s:?} is not a depth mapping: linear, inverse"))
    }
}

/// A depth mapping with the range it spans (the dataset's nearest and farthest rendered depth).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct DepthScale {
    pub mapping: DepthMapping,
    pub near: f64,
    pub far: f64,
}

impl DepthScale {
    /// The level of a depth: 0 = empty, 1 = near … 255 = far.
    pub fn level(&self, d: f32) -> u8 {
        if d <= 0.0 || !d.is_finite() {
            return 0;
        }
        let d = d as f64;
        let t = match self.mapping {
            DepthMapping::Linear => (d - self.near) / (self.far - self.near),
            DepthMapping::Inverse => {
                (1.0 / self.near - 1.0 / d) / (1.0 / self.near - 1.0 / self.far)
            }
        };
        let t = if t.is_finite() {
            t.clamp(0.0, 1.0)
        } else {
            0.0
        };
        1 + (t * 254.0).round() as u8
    }

    /// The depth a level stands for (the inverse of `level` up to its rounding).
    pub fn depth(&self, level: u8) -> Option<f64> {
        if level == 0 {
            return None;
        }
        let t = (level - 1) as f64 / 254.0;
        Some(match self.mapping {
            DepthMapping::Linear => self.near + t * (self.far - self.near),
            DepthMapping::Inverse => {
                1.0 / (1.0 / self.near - t * (1.0 / self.near - 1.0 / self.far))
            }
        })
    }

    /// The formula recorded in the export's JSON.
    pub fn formula(&self) -> &'static str {
        match self.mapping {
            DepthMapping::Linear => "level = 0 where empty, else 1 + round(254 * clamp((d - near) / (far - near), 0, 1)); d = near + (level - 1) / 254 * (far - near)",
            DepthMapping::Inverse => "level = 0 where empty, else 1 + round(254 * clamp((1/near - 1/d) / (1/near - 1/far), 0, 1)); d = 1 / (1/near - (level - 1) / 254 * (1/near - 1/far))",
        }
    }

    /// The 8-bit depth image of a depth map.
    pub fn image(&self, width: u32, height: u32, depth: &[f32]) -> GrayImage {
        GrayImage::from_vec(
            width,
            height,
            depth.iter().map(|d| self.level(*d)).collect(),
        )
        .expect("depth map has width × height values")
    }
}

/// The start of a centred crop along one axis, as `utils.get_central_crop` computes it.
pub fn crop_start(side: u32, crop: u32) -> u32 {
    (side - crop) / 2
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_table_is_the_published_coding() {
        let t = official_colors();
        assert_eq!(t[1], [111, 74, 0], "wall");
        assert_eq!(t[2], [81, 0, 81], "building");
        assert_eq!(t[3], [128, 64, 128], "sky");
        assert_eq!(t[4], t[7], "floor and road share a colour");
        assert_eq!(t[12], [102, 102, 156], "sidewalk");
        assert_eq!(t[133], [119, 11, 32], "sculpture");
        assert_eq!(t[0], [0, 0, 142], "unlabelled takes the last colour");
        assert_eq!(t[49], [0, 0, 142], "skyscraper is not chosen");
        assert_eq!(t[77], [0, 0, 142], "boat shares it");
        let mut distinct: Vec<[u8; 3]> = t.to_vec();
        distinct.sort();
        distinct.dedup();
        assert_eq!(distinct.len(), 28, "28 distinct colours in use");
    }

    #[test]
    fn depth_levels_span_1_to_255_and_invert() {
        for mapping in [DepthMapping::Linear, DepthMapping::Inverse] {
            let s = DepthScale {
                mapping,
                near: 2.0,
                far: 50.0,
            };
            assert_eq!(s.level(0.0), 0);
            assert_eq!(s.level(2.0), 1);
            assert_eq!(s.level(50.0), 255);
            assert_eq!(s.level(1000.0), 255, "beyond far clamps");
            assert_eq!(s.level(f32::NAN), 0);
            for d in [2.5f32, 7.0, 20.0, 49.0] {
                let l = s.level(d);
                assert_eq!(s.level(s.depth(l).unwrap() as f32), l, "{mapping:?} {d}");
            }
        }
        let flat = DepthScale {
            mapping: DepthMapping::Inverse,
            near: 3.0,
            far: 3.0,
        };
        assert_eq!(flat.level(3.0), 1, "a single depth is level 1, not NaN");
    }
}
