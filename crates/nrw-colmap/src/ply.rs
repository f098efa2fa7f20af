//! Dense point clouds (`fused.ply`): binary little/big endian or ASCII, properties in any
//! order, normals and colours optional. Parsing is the `serde-ply` crate's (measured fast
//! enough: see docs/benchmarks.md); this module streams its rows into columns, bounds every
//! allocation by the file's size, and names the vertex and field of any bad value.

use std::fs::File;
use std::io::BufReader;
use std::path::{Path, PathBuf};

use glam::DVec3;
use serde::de::{Deserializer, IgnoredAny, MapAccess, SeqAccess, Visitor};
use serde::Deserialize;
use serde_ply::{PlyReader, PropertyType};

use crate::error::{ColmapError, Record, Result};

/// A dense cloud in columns; channels the file lacks are `None`, so nothing downstream pays for them.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct PointCloud {
    pub path: PathBuf,
    /// Positions in f64 (f32 files widen exactly), in the model's world frame.
    pub positions: Vec<DVec3>,
    pub colors: Option<Vec<[u8; 3]>>,
    /// Unit normals as stored (f32 in COLMAP's layout).
    pub normals: Option<Vec<[f32; 3]>>,
}

impl PointCloud {
    /// Number of points.
    pub fn len(&self) -> usize {
        self.positions.len()
    }

    /// Whether the cloud has no point.
    pub fn is_empty(&self) -> bool {
        self.positions.is_empty()
    }
}

/// One vertex as this module needs it, whichever channels the file has.
trait VertexRow {
    fn xyz(&self) -> [f64; 3];
    fn normal(&self) -> Option<[f32; 3]> {
        None
    }
    fn color(&self) -> Option<[u8; 3]> {
        None
    }
}

// One row type per channel set: serde-ply 0.2.2's fast binary path rejects structs with
// `Option` fields the file lacks ("invalid length 3, expected struct with 9 elements"),
// so every field of the chosen type must exist in the file.
#[derive(Deserialize)]
struct Xyz {
    x: f64,
    y: f64,
    z: f64,
}
#[derive(Deserialize)]
struct XyzN {
    x: f64,
    y: f64,
    z: f64,
    nx: f32,
    ny: f32,
    nz: f32,
}
#[derive(Deserialize)]
struct XyzC {
    x: f64,
    y: f64,
    z: f64,
    red: u8,
    green: u8,
    blue: u8,
}
#[derive(Deserialize)]
struct XyzNC {
    x: f64,
    y: f64,
    z: f64,
    nx: f32,
    ny: f32,
    nz: f32,
    red: u8,
    green: u8,
    blue: u8,
}

impl VertexRow for Xyz {
    fn xyz(&self) -> [f64; 3] {
        [self.x, self.y, self.z]
    }
}
impl VertexRow for XyzN {
    fn xyz(&self) -> [f64; 3] {
        [self.x, self.y, self.z]
    }
    fn normal(&self) -> Option<[f32; 3]> {
        Some([self.nx, self.ny, self.nz])
    }
}
impl VertexRow for XyzC {
    fn xyz(&self) -> [f64; 3] {
        [self.x, self.y, self.z]
    }
    fn color(&self) -> Option<[u8; 3]> {
        Some([self.red, self.green, self.blue])
    }
}
impl VertexRow for XyzNC {
    fn xyz(&self) -> [f64; 3] {
        [self.x, self.y, self.z]
    }
    fn normal(&self) -> Option<[f32; 3]> {
        Some([self.nx, self.ny, self.nz])
    }
    fn color(&self) -> Option<[u8; 3]> {
        Some([self.red, self.green, self.blue])
    }
}

/// Where a PLY's vertices go as they are read: a whole [`PointCloud`], or a caller's own
/// compact columns (the renderer keeps f32 positions, so it never holds the f64 ones).
pub trait VertexSink {
    /// Before the first vertex: room for `capacity` vertices, and which channels come.
    fn begin(&mut self, capacity: usize, normals: bool, colors: bool);
    /// One vertex (position finite, normal finite when present).
    fn push(&mut self, xyz: DVec3, normal: Option<[f32; 3]>, color: Option<[u8; 3]>);
}

impl VertexSink for PointCloud {
    fn begin(&mut self, capacity: usize, normals: bool, colors: bool) {
        self.positions.reserve(capacity);
        self.normals = normals.then(|| Vec::with_capacity(capacity));
        self.colors = colors.then(|| Vec::with_capacity(capacity));
    }
    fn push(&mut self, xyz: DVec3, normal: Option<[f32; 3]>, color: Option<[u8; 3]>) {
        self.positions.push(xyz);
        if let (Some(c), Some(v)) = (self.colors.as_mut(), color) {
            c.push(v);
        }
        if let (Some(n), Some(v)) = (self.normals.as_mut(), normal) {
            n.push(v);
        }
    }
}

/// Receives rows straight into the sink's columns, counting them so errors can name the row.
struct Columns<'a, R> {
    sink: &'a mut dyn VertexSink,
    capacity: usize,
    channels: (bool, bool),
    rows: &'a mut u64,
    bad: &'a mut Option<(u64, &'static str, String)>,
    row: std::marker::PhantomData<R>,
}

impl<'de, R: VertexRow + Deserialize<'de>> Visitor<'de> for Columns<'_, R> {
    type Value = ();

    fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
        f.write_str("a sequence of vertex rows")
    }

    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> std::result::Result<(), A::Error> {
        self.sink
            .begin(self.capacity, self.channels.0, self.channels.1);
        while let Some(r) = seq.next_element::<R>()? {
            let i = *self.rows;
            let p = r.xyz();
            for (name, v) in ["x", "y", "z"].into_iter().zip(p) {
                if !v.is_finite() {
                    *self.bad = Some((i, name, format!("not a finite number: {v}")));
                    return Ok(());
                }
            }
            let normal = r.normal();
            if let Some(v) = normal.filter(|v| !v.iter().all(|c| c.is_finite())) {
                *self.bad = Some((i, "nx/ny/nz", format!("normal not finite: {v:?}")));
                return Ok(());
            }
            self.sink.push(DVec3::from_array(p), normal, r.color());
            *self.rows += 1;
        }
        Ok(())
    }
}

/// Consumes an element we do not read (faces, edges), row by row, storing nothing.
struct SkipRows;

impl<'de> Deserialize<'de> for SkipRows {
    fn deserialize<D: Deserializer<'de>>(d: D) -> std::result::Result<Self, D::Error> {
        struct Rows;
        impl<'de> Visitor<'de> for Rows {
            type Value = SkipRows;
            fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                f.write_str("rows")
            }
            fn visit_seq<A: SeqAccess<'de>>(
                self,
                mut s: A,
            ) -> std::result::Result<SkipRows, A::Error> {
                while s.next_element::<SkipRow>()?.is_some() {}
                Ok(SkipRows)
            }
        }
        d.deserialize_seq(Rows)
    }
}

struct SkipRow;

impl<'de> Deserialize<'de> for SkipRow {
    fn deserialize<D: Deserializer<'de>>(d: D) -> std::result::Result<Self, D::Error> {
        struct Row;
        impl<'de> Visitor<'de> for Row {
            type Value = SkipRow;
            fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                f.write_str("a row")
            }
            fn visit_map<A: MapAccess<'de>>(
                self,
                mut m: A,
            ) -> std::result::Result<SkipRow, A::Error> {
                while m.next_entry::<IgnoredAny, IgnoredAny>()?.is_some() {}
                Ok(SkipRow)
            }
        }
        d.deserialize_map(Row)
    }
}

/// Deserialize entry point for [`Columns`]: the element arrives as a sequence.
struct ColumnsSeed<'a, R>(Columns<'a, R>);

impl<'de, R: VertexRow + Deserialize<'de>> serde::de::DeserializeSeed<'de> for ColumnsSeed<'_, R> {
    type Value = ();
    fn deserialize<D: Deserializer<'de>>(self, d: D) -> std::result::Result<(), D::Error> {
        d.deserialize_seq(self.0)
    }
}

/// Read the `vertex` element of a PLY file.
pub fn read_ply(path: &Path) -> Result<PointCloud> {
    let file = File::open(path).map_err(|e| ColmapError::io(path, e))?;
    let file_len = file.metadata().map_err(|e| ColmapError::io(path, e))?.len();
    read_ply_from(BufReader::with_capacity(1 << 20, file), file_len, path)
}

/// Read a PLY from any reader of `byte_len` bytes, reporting errors under the name `path`.
pub fn read_ply_from<R: std::io::BufRead>(
    input: R,
    byte_len: u64,
    path: &Path,
) -> Result<PointCloud> {
    let mut cloud = PointCloud {
        path: path.to_path_buf(),
        ..Default::default()
    };
    read_ply_into(input, byte_len, path, &mut cloud)?;
    Ok(cloud)
}

/// Stream the `vertex` element of a PLY file into `sink`, one vertex at a time.
pub fn read_ply_file_into(path: &Path, sink: &mut dyn VertexSink) -> Result<()> {
    let file = File::open(path).map_err(|e| ColmapError::io(path, e))?;
    let file_len = file.metadata().map_err(|e| ColmapError::io(path, e))?.len();
    read_ply_into(
        BufReader::with_capacity(1 << 20, file),
        file_len,
        path,
        sink,
    )
}

/// [`read_ply_from`] into a sink: nothing but the sink's columns grows with the file.
pub fn read_ply_into<R: std::io::BufRead>(
    input: R,
    byte_len: u64,
    path: &Path,
    cloud: &mut dyn VertexSink,
) -> Result<()> {
    let file_len = byte_len;
    let mut reader = PlyReader::from_reader(input)
        .map_err(|e| ColmapError::invalid(path, Record::File, "header", e.to_string()))?;
    let header = reader.header().clone();
    for (index, elem) in header.elem_defs.iter().enumerate() {
        if elem.name != "vertex" {
            skip_element(&mut reader, elem, index, path, file_len)?;
            continue;
        }
        check_vertex_properties(elem, path)?;
        let has = |n: &str| elem.properties.iter().any(|p| p.name == n);
        // Never trust the header's count for allocation: a row takes at least one byte a property.
        let min_row = elem.properties.len().max(1) as u64;
        let capacity = (elem.count as u64).min(file_len / min_row) as usize;
        let mut rows = 0u64;
        let mut bad = None;
        // PlyReader is a map of elements; take the current element's value with our seed.
        macro_rules! read_as {
            ($row:ty) => {{
                let seed = ColumnsSeed(Columns::<$row> {
                    sink: &mut *cloud,
                    capacity,
                    channels: (has("nx"), has("red")),
                    rows: &mut rows,
                    bad: &mut bad,
                    row: std::marker::PhantomData,
                });
                MapAccess::next_value_seed(&mut &mut reader, seed)
            }};
        }
        let result = match (has("nx"), has("red")) {
            (false, false) => read_as!(Xyz),
            (true, false) => read_as!(XyzN),
            (false, true) => read_as!(XyzC),
            (true, true) => read_as!(XyzNC),
        };
        if let Some((i, field, problem)) = bad {
            return Err(ColmapError::invalid(
                path,
                Record::Nth {
                    kind: "vertex",
                    index: i,
                    id: None,
                },
                field,
                problem,
            ));
        }
        result.map_err(|e| {
            ColmapError::invalid(
                path,
                Record::Nth {
                    kind: "vertex",
                    index: rows,
                    id: None,
                },
                "row",
                format!("{e} (header promised {} vertices)", elem.count),
            )
        })?;
        return Ok(());
    }
    Err(ColmapError::invalid(
        path,
        Record::File,
        "element vertex",
        "the file has no vertex element",
    ))
}

/// Read past an element that is not the vertices, refusing a count of property-less rows
/// larger than the file (its rows take no bytes, so such a count would spin).
fn skip_element<R: std::io::BufRead>(
    reader: &mut PlyReader<R>,
    elem: &serde_ply::ElementDef,
    index: usize,
    path: &Path,
    file_len: u64,
) -> Result<()> {
    let bad = |problem: String| {
        ColmapError::invalid(
            path,
            Record::Nth {
                kind: "element",
                index: index as u64,
                id: None,
            },
            elem.name.clone(),
            problem,
        )
    };
    // Every row takes at least a byte unless the element has no property; then its rows
    // take none and a count in the billions would spin (found by fuzzing).
    if elem.properties.is_empty() && elem.count as u64 > file_len {
        return Err(bad(format!(
            "{} rows without properties in a {file_len}-byte file",
            elem.count
        )));
    }
    reader
        .next_element::<SkipRows>()
        .map_err(|e| bad(format!("cannot skip element: {e}")))?;
    Ok(())
}

/// The vertex element's properties a cloud is read from: x, y and z present, normals and
/// colours all three or none, and none of them a list.
fn check_vertex_properties(elem: &serde_ply::ElementDef, path: &Path) -> Result<()> {
    let has = |n: &str| elem.properties.iter().any(|p| p.name == n);
    for p in &elem.properties {
        if matches!(p.property_type, PropertyType::List { .. })
            && ["x", "y", "z", "nx", "ny", "nz", "red", "green", "blue"].contains(&p.name.as_str())
        {
            return Err(ColmapError::invalid(
                path,
                Record::File,
                p.name.clone(),
                "is a list property; a scalar is expected",
            ));
        }
    }
    for n in ["x", "y", "z"] {
        if !has(n) {
            return Err(ColmapError::invalid(
                path,
                Record::File,
                n,
                "vertex element has no such property",
            ));
        }
    }
    for group in [["nx", "ny", "nz"], ["red", "green", "blue"]] {
        let present = group.iter().filter(|n| has(n)).count();
        if present != 0 && present != 3 {
            let missing: Vec<_> = group.iter().filter(|n| !has(n)).copied().collect();
            return Err(ColmapError::invalid(
                path,
                Record::File,
                missing.join(", "),
                format!("vertex has only part of {{{}}}", group.join(", ")),
            ));
        }
    }
    Ok(())
}

/// Write a cloud as binary little-endian PLY in COLMAP's fused.ply layout (float x y z,
/// float nx ny nz, uchar red green blue), leaving out the channels the cloud lacks.
///
/// Positions are stored as f32 like COLMAP's, unless a coordinate exceeds 10⁵ in magnitude
/// (georeferenced clouds), where f32 would round to decimetres: then x y z are doubles.
pub fn write_ply(cloud: &PointCloud, path: &Path) -> std::io::Result<()> {
    use std::io::Write;
    let double = cloud.positions.iter().any(|p| p.abs().max_element() > 1e5);
    let mut header = format!(
        "ply\nformat binary_little_endian 1.0\nelement vertex {}\n",
        cloud.len()
    );
    let ty = if double { "double" } else { "float" };
    header.push_str(&format!(
        "property {ty} x\nproperty {ty} y\nproperty {ty} z\n"
    ));
    if cloud.normals.is_some() {
        header.push_str("property float nx\nproperty float ny\nproperty float nz\n");
    }
    if cloud.colors.is_some() {
        header.push_str("property uchar red\nproperty uchar green\nproperty uchar blue\n");
    }
    header.push_str("end_header\n");
    let tmp = path.with_extension("ply.tmp");
    let mut w = std::io::BufWriter::new(File::create(&tmp)?);
    w.write_all(header.as_bytes())?;
    for i in 0..cloud.len() {
        for v in cloud.positions[i].to_array() {
            if double {
                w.write_all(&v.to_le_bytes())?;
            } else {
                // Precision given up here: COLMAP's layout stores f32 positions.
                w.write_all(&(v as f32).to_le_bytes())?;
            }
        }
        if let Some(n) = &cloud.normals {
            for v in n[i] {
                w.write_all(&v.to_le_bytes())?;
            }
        }
        if let Some(c) = &cloud.colors {
            w.write_all(&c[i])?;
        }
    }
    w.into_inner().map_err(|e| e.into_error())?.sync_all()?;
    std::fs::rename(&tmp, path)
}
