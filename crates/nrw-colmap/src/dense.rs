//! The files of COLMAP's dense workspace that are not a sparse model: depth and normal maps
//! (`stereo/{depth_maps,normal_maps}/NAME.{photometric,geometric}.bin`) and the visibility of
//! fused points (`fused.ply.vis`), read and written byte for byte as COLMAP 3.8 does, so that
//! `colmap stereo_fusion`, COLMAP's scripts and the densify stage share one workspace.
//!
//! A map file is the text header `WIDTH&HEIGHT&CHANNELS&` followed by WIDTH × HEIGHT ×
//! CHANNELS little-endian float32 in column-major order: channel-planar, each plane with x
//! varying fastest (COLMAP's `mvs::Mat<T>::Write`; `scripts/python/read_write_dense.py`
//! reshapes it as `(width, height, channels)` with `order="F"`). In memory a [`DenseMap`] is
//! row-major and interleaved (`(y × width + x) × channels + c`), as every image here is.

use std::path::Path;

use crate::error::{ColmapError, Record, Result};
pub use crate::map_file::MapFile;
use crate::map_file::{split_header, MAX_HEADER};

/// A depth map (1 channel), a normal map (3 channels) or a confidence map, in float32 as
/// COLMAP stores them (depth in the camera's z; normals unit vectors in camera space).
#[derive(Debug, Clone, PartialEq)]
pub struct DenseMap {
    pub width: usize,
    pub height: usize,
    pub channels: usize,
    /// Row-major, interleaved: `data[(y * width + x) * channels + c]`.
    pub data: Vec<f32>,
}

impl DenseMap {
    /// A map of `channels` channels filled with `value`.
    pub fn filled(width: usize, height: usize, channels: usize, value: f32) -> DenseMap {
        DenseMap {
            width,
            height,
            channels,
            data: vec![value; width * height * channels],
        }
    }

    /// The value of channel `c` at pixel (x, y).
    pub fn get(&self, x: usize, y: usize, c: usize) -> f32 {
        self.data[(y * self.width + x) * self.channels + c]
    }

    /// Set channel `c` at pixel (x, y).
    pub fn set(&mut self, x: usize, y: usize, c: usize, value: f32) {
        self.data[(y * self.width + x) * self.channels + c] = value;
    }

    /// The file's bytes: COLMAP's header, then the values in its column-major order.
    pub fn to_bytes(&self) -> Vec<u8> {
        let header = format!("{}&{}&{}&", self.width, self.height, self.channels);
        let mut out = Vec::with_capacity(header.len() + self.data.len() * 4);
        out.extend_from_slice(header.as_bytes());
        for c in 0..self.channels {
            for y in 0..self.height {
                for x in 0..self.width {
                    out.extend_from_slice(&self.get(x, y, c).to_le_bytes());
                }
            }
        }
        out
    }

    /// A map from a file's bytes (`name` is the file, for messages): the header must hold
    /// three whole numbers, and exactly their product of float32 must follow.
    pub fn from_bytes(bytes: &[u8], name: &Path) -> Result<DenseMap> {
        let bad =
            |field: &str, problem: String| ColmapError::invalid(name, Record::File, field, problem);
        let (dims, body) = split_header(bytes).ok_or_else(|| {
            bad(
                "header",
                format!(
                    "no `WIDTH&HEIGHT&CHANNELS&` header in the first {MAX_HEADER} bytes (not a COLMAP depth or normal map)"
                ),
            )
        })?;
        let [width, height, channels] = dims;
        let fields = ["width", "height", "channels"];
        for (v, f) in dims.iter().zip(fields) {
            if *v == 0 {
                return Err(bad(f, "is 0".into()));
            }
        }
        let values = width
            .checked_mul(height)
            .and_then(|n| n.checked_mul(channels))
            .filter(|n| n.checked_mul(4).is_some())
            .ok_or_else(|| {
                bad(
                    "width",
                    format!("{width} × {height} × {channels} overflows"),
                )
            })?;
        // Checked against the bytes present before anything is allocated.
        if body.len() != values * 4 {
            return Err(bad(
                "data",
                format!(
                    "{width} × {height} × {channels} float32 need {} bytes after the header, the file has {}",
                    values * 4,
                    body.len()
                ),
            ));
        }
        let mut map = DenseMap::filled(width, height, channels, 0.0);
        let mut words = body.chunks_exact(4);
        for c in 0..channels {
            for y in 0..height {
                for x in 0..width {
                    let w = words.next().expect("length checked above");
                    map.set(x, y, c, f32::from_le_bytes([w[0], w[1], w[2], w[3]]));
                }
            }
        }
        Ok(map)
    }
}

/// `fused.ply.vis`: for each fused point, the indices (in the workspace's image order, not
/// image ids) of the images whose pixels were fused into it.
pub fn visibility_to_bytes(points: &[Vec<u32>]) -> Vec<u8> {
    let total: usize = points.iter().map(|p| 4 + 4 * p.len()).sum();
    let mut out = Vec::with_capacity(8 + total);
    out.extend_from_slice(&(points.len() as u64).to_le_bytes());
    for p in points {
        out.extend_from_slice(&(p.len() as u32).to_le_bytes());
        for i in p {
            out.extend_from_slice(&i.to_le_bytes());
        }
    }
    out
}

/// The visibility lists of a `fused.ply.vis` (COLMAP's `uint64` point count, then per point a
/// `uint32` count and that many `uint32` image indices); every count is checked against the
/// bytes left before it is allocated.
pub fn visibility_from_bytes(bytes: &[u8], name: &Path) -> Result<Vec<Vec<u32>>> {
    let short = |record: Record, field: &str| {
        ColmapError::invalid(name, record, field, "the file ends inside it")
    };
    let word = |at: usize| -> Option<u32> {
        let b = bytes.get(at..at + 4)?;
        Some(u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
    };
    let head = bytes
        .get(..8)
        .ok_or_else(|| short(Record::File, "num_points"))?;
    let n = u64::from_le_bytes(head.try_into().expect("8 bytes"));
    // Each point takes at least its 4-byte count.
    let left = (bytes.len() - 8) as u64 / 4;
    if n > left {
        return Err(ColmapError::invalid(
            name,
            Record::File,
            "num_points",
            format!(
                "{n} points cannot fit in the {} bytes after the count",
                bytes.len() - 8
            ),
        ));
    }
    let mut points = Vec::with_capacity(n as usize);
    let mut at = 8;
    for index in 0..n {
        let record = Record::Nth {
            kind: "point",
            index,
            id: None,
        };
        let count = word(at).ok_or_else(|| short(record, "num_visible_images"))? as usize;
        at += 4;
        if count > (bytes.len() - at) / 4 {
            return Err(short(record, "image_idx"));
        }
        points.push(
            (0..count)
                .map(|k| word(at + 4 * k).expect("checked"))
                .collect(),
        );
        at += 4 * count;
    }
    if at != bytes.len() {
        return Err(ColmapError::invalid(
            name,
            Record::File,
            "num_points",
            format!("{} bytes follow the last point", bytes.len() - at),
        ));
    }
    Ok(points)
}

/// A name a `.cfg` line can hold as COLMAP reads it back (one name per line; source lists
/// split at commas and trimmed): no line break, no comma, no space at either end.
fn cfg_name<'a>(name: &'a str, file: &Path, index: usize) -> Result<&'a str> {
    if name.is_empty() || name.contains([',', '\n', '\r']) || name.trim() != name {
        return Err(ColmapError::invalid(
            file,
            Record::Nth {
                kind: "image",
                index: index as u64,
                id: None,
            },
            "name",
            format!("{name:?} cannot be written to a COLMAP .cfg (a comma, a line break or a space at either end)"),
        ));
    }
    Ok(name)
}

/// `stereo/patch-match.cfg`: each reference image on one line and its source images on the
/// next, comma-separated, as COLMAP's `patch_match_stereo` reads them (an explicit list, so
/// COLMAP matches against the same sources as we did, not its own `__auto__` choice).
pub fn patch_match_cfg(images: &[(String, Vec<String>)], file: &Path) -> Result<String> {
    let mut out = String::new();
    for (i, (name, sources)) in images.iter().enumerate() {
        out.push_str(cfg_name(name, file, i)?);
        out.push('\n');
        if sources.is_empty() {
            // COLMAP skips blank lines: the next image's name would become these sources.
            return Err(ColmapError::invalid(
                file,
                Record::Nth {
                    kind: "image",
                    index: i as u64,
                    id: None,
                },
                "sources",
                format!("{name:?} has no source image; leave it out of the file"),
            ));
        }
        let list: Vec<&str> = sources
            .iter()
            .map(|s| cfg_name(s, file, i))
            .collect::<Result<_>>()?;
        out.push_str(&list.join(", "));
        out.push('\n');
    }
    Ok(out)
}

/// `stereo/fusion.cfg`: the images `stereo_fusion` fuses, one name per line.
pub fn fusion_cfg(names: &[String], file: &Path) -> Result<String> {
    let mut out = String::new();
    for (i, name) in names.iter().enumerate() {
        out.push_str(cfg_name(name, file, i)?);
        out.push('\n');
    }
    Ok(out)
}

/// The pass a depth or normal map comes from, as COLMAP names the file.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MapPass {
    /// Photo-consistency alone (`NAME.photometric.bin`).
    Photometric,
    /// With the geometric-consistency pass (`NAME.geometric.bin`).
    Geometric,
}

impl MapPass {
    /// The word COLMAP puts in the file name.
    pub fn name(self) -> &'static str {
        match self {
            MapPass::Photometric => "photometric",
            MapPass::Geometric => "geometric",
        }
    }
}

/// Which map of a view.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MapKind {
    /// Depth along the camera's z, 1 channel (`stereo/depth_maps/`).
    Depth,
    /// Unit normal in camera coordinates, 3 channels (`stereo/normal_maps/`).
    Normal,
    /// Ours, not COLMAP's: the mean NCC of the source views that agree with the kept depth
    /// and their count, 2 channels, 0 where no depth (`stereo/confidence_maps/`).
    Confidence,
}

impl MapKind {
    /// The folder under `stereo/`.
    pub fn folder(self) -> &'static str {
        match self {
            MapKind::Depth => "depth_maps",
            MapKind::Normal => "normal_maps",
            MapKind::Confidence => "confidence_maps",
        }
    }
}

/// COLMAP's dense workspace: one place that says where each of its files lives. Image
/// names become paths only through [`crate::names::join_checked`].
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Workspace {
    pub root: std::path::PathBuf,
}

impl Workspace {
    /// The workspace at `root`.
    pub fn new(root: &Path) -> Workspace {
        Workspace {
            root: root.to_path_buf(),
        }
    }

    /// `images/`: the undistorted photos.
    pub fn images(&self) -> std::path::PathBuf {
        self.root.join("images")
    }

    /// `sparse/`: the undistorted model.
    pub fn sparse(&self) -> std::path::PathBuf {
        self.root.join("sparse")
    }

    /// `images/NAME`.
    pub fn image(&self, name: &str) -> std::result::Result<std::path::PathBuf, String> {
        crate::names::join_checked(&self.images(), name)
    }

    /// `stereo/`.
    pub fn stereo(&self) -> std::path::PathBuf {
        self.root.join("stereo")
    }

    /// `stereo/{depth,normal,confidence}_maps/NAME.{photometric,geometric}.bin`.
    pub fn map(
        &self,
        kind: MapKind,
        pass: MapPass,
        name: &str,
    ) -> std::result::Result<std::path::PathBuf, String> {
        crate::names::check_name(name).map_err(|p| format!("{name:?} {p}"))?;
        Ok(self
            .stereo()
            .join(kind.folder())
            .join(format!("{name}.{}.bin", pass.name())))
    }

    /// `stereo/patch-match.cfg`.
    pub fn patch_match_cfg(&self) -> std::path::PathBuf {
        self.stereo().join("patch-match.cfg")
    }

    /// `stereo/fusion.cfg`.
    pub fn fusion_cfg(&self) -> std::path::PathBuf {
        self.stereo().join("fusion.cfg")
    }

    /// `fused.ply`.
    pub fn fused_ply(&self) -> std::path::PathBuf {
        self.root.join("fused.ply")
    }

    /// `fused.ply.vis`.
    pub fn fused_vis(&self) -> std::path::PathBuf {
        self.root.join("fused.ply.vis")
    }

    /// `densify.json`: not COLMAP's; nrw-etl's record of the settings a workspace is built
    /// with and of the photos it could not read, so work units and resumed runs agree.
    pub fn settings(&self) -> std::path::PathBuf {
        self.root.join("densify.json")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn name() -> &'static Path {
        Path::new("d/stereo/depth_maps/a.jpg.geometric.bin")
    }

    #[test]
    fn a_map_is_column_major_after_its_header_and_round_trips() {
        let mut m = DenseMap::filled(3, 2, 2, 0.0);
        for y in 0..2 {
            for x in 0..3 {
                for c in 0..2 {
                    m.set(x, y, c, (100 * c + 10 * y + x) as f32);
                }
            }
        }
        let b = m.to_bytes();
        assert!(b.starts_with(b"3&2&2&"));
        let floats: Vec<f32> = b[6..]
            .chunks_exact(4)
            .map(|w| f32::from_le_bytes(w.try_into().unwrap()))
            .collect();
        // Channel 0's plane, x fastest, then channel 1's.
        let want = [
            0., 1., 2., 10., 11., 12., 100., 101., 102., 110., 111., 112.,
        ];
        assert_eq!(floats, want);
        assert_eq!(DenseMap::from_bytes(&b, name()).unwrap(), m);
    }

    #[test]
    fn bad_maps_name_the_field_and_allocate_nothing_huge() {
        let err = |b: &[u8]| DenseMap::from_bytes(b, name()).unwrap_err().to_string();
        // A header promising 2^60 values in a few bytes is refused before allocating.
        let e = err(b"1073741824&1073741824&1&\0\0\0\0");
        assert!(
            e.contains("field `data`") && e.contains("the file has 4"),
            "{e}"
        );
        let e = err(b"18446744073709551615&2&1&");
        assert!(e.contains("overflows"), "{e}");
        assert!(err(b"2&2&1&\0\0\0\0").contains("need 16 bytes"));
        assert!(err(b"0&2&1&").contains("field `width`: is 0"));
        for junk in [
            &b""[..],
            b"2&2",
            b"a&b&c&",
            b"-2&2&1&",
            b" 2&2&1&",
            &[b'1'; 100],
        ] {
            assert!(err(junk).contains("field `header`"), "{junk:?}");
        }
        assert!(err(b"2&2&1&").contains("a.jpg.geometric.bin"));
    }

    #[test]
    fn visibility_round_trips_and_bad_counts_are_refused() {
        let pts = vec![vec![0, 3], vec![], vec![7]];
        let b = visibility_to_bytes(&pts);
        assert_eq!(b.len(), 8 + (4 + 8) + 4 + (4 + 4));
        assert_eq!(visibility_from_bytes(&b, name()).unwrap(), pts);
        let err = |b: &[u8]| visibility_from_bytes(b, name()).unwrap_err().to_string();
        let mut huge = u64::MAX.to_le_bytes().to_vec();
        huge.extend_from_slice(&[0; 8]);
        assert!(err(&huge).contains("cannot fit"), "{}", err(&huge));
        assert!(err(&b[..b.len() - 1]).contains("point #2: field `image_idx`"));
        let mut extra = b.clone();
        extra.push(0);
        assert!(err(&extra).contains("1 bytes follow"));
        assert!(err(&b[..5]).contains("field `num_points`"));
    }

    #[test]
    fn cfg_files_list_names_and_sources_and_refuse_what_colmap_would_split() {
        let f = Path::new("d/stereo/patch-match.cfg");
        let s = |v: &[&str]| v.iter().map(|x| x.to_string()).collect::<Vec<_>>();
        let cfg = patch_match_cfg(
            &[
                ("a/1.jpg".into(), s(&["2.jpg", "3.jpg"])),
                ("2.jpg".into(), s(&["a/1.jpg"])),
            ],
            f,
        )
        .unwrap();
        assert_eq!(cfg, "a/1.jpg\n2.jpg, 3.jpg\n2.jpg\na/1.jpg\n");
        let e = patch_match_cfg(&[("2.jpg".into(), s(&[]))], f).unwrap_err();
        assert!(e.to_string().contains("field `sources`"), "{e}");
        assert_eq!(
            fusion_cfg(&s(&["a/1.jpg", "2.jpg"]), f).unwrap(),
            "a/1.jpg\n2.jpg\n"
        );
        for bad in ["x,y.jpg", "x\ny.jpg", " x.jpg", ""] {
            let e = fusion_cfg(&s(&["ok.jpg", bad]), f).unwrap_err().to_string();
            assert!(e.contains("image #1") && e.contains("field `name`"), "{e}");
            let e = patch_match_cfg(&[("ok.jpg".into(), s(&[bad]))], f).unwrap_err();
            assert!(e.to_string().contains("patch-match.cfg"), "{e}");
        }
    }
}
