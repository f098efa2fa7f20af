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

#[derive(Deserialize)]
struct Row {
    x: f64,
    y: f64,
    z: f64,
    nx: Option<f32>,
    ny: Option<f32>,
    nz: Option<f32>,
    red: Option<u8>,
    green: Option<u8>,
    blue: Option<u8>,
}

/// Receives rows straight into the cloud's columns, counting them so errors can name the row.
struct Columns<'a> {
    cloud: &'a mut PointCloud,
    capacity: usize,
    rows: &'a mut u64,
    bad: &'a mut Option<(u64, &'static str, String)>,
}

impl<'de> Visitor<'de> for Columns<'_> {
    type Value = ();

    fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
        f.write_str("a sequence of vertex rows")
    }

    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> std::result::Result<(), A::Error> {
        let cap = self.capacity;
        self.cloud.positions.reserve(cap);
        if let Some(c) = self.cloud.colors.as_mut() {
            c.reserve(cap);
        }
        if let Some(n) = self.cloud.normals.as_mut() {
            n.reserve(cap);
        }
        while let Some(r) = seq.next_element::<Row>()? {
            let i = *self.rows;
            for (name, v) in [("x", r.x), ("y", r.y), ("z", r.z)] {
                if !v.is_finite() {
                    *self.bad = Some((i, name, format!("not a finite number: {v}")));
                    return Ok(());
                }
            }
            self.cloud.positions.push(DVec3::new(r.x, r.y, r.z));
            if let Some(c) = self.cloud.colors.as_mut() {
                c.push([
                    r.red.unwrap_or(0),
                    r.green.unwrap_or(0),
                    r.blue.unwrap_or(0),
                ]);
            }
            if let Some(n) = self.cloud.normals.as_mut() {
                let v = [
                    r.nx.unwrap_or(0.0),
                    r.ny.unwrap_or(0.0),
                    r.nz.unwrap_or(0.0),
                ];
                if !v.iter().all(|c| c.is_finite()) {
                    *self.bad = Some((i, "nx/ny/nz", format!("normal not finite: {v:?}")));
                    return Ok(());
                }
                n.push(v);
            }
            *self.rows += 1;
        }
        Ok(())
    }
}

/// Deserialize entry point for [`Columns`]: the element arrives as a sequence.
struct ColumnsSeed<'a>(Columns<'a>);

impl<'de> serde::de::DeserializeSeed<'de> for ColumnsSeed<'_> {
    type Value = ();
    fn deserialize<D: Deserializer<'de>>(self, d: D) -> std::result::Result<(), D::Error> {
        d.deserialize_seq(self.0)
    }
}

/// Read the `vertex` element of a PLY file.
pub fn read_ply(path: &Path) -> Result<PointCloud> {
    let file = File::open(path).map_err(|e| ColmapError::io(path, e))?;
    let file_len = file.metadata().map_err(|e| ColmapError::io(path, e))?.len();
    let mut reader = PlyReader::from_reader(BufReader::with_capacity(1 << 20, file))
        .map_err(|e| ColmapError::invalid(path, Record::File, "header", e.to_string()))?;
    let header = reader.header().clone();
    let mut cloud = PointCloud {
        path: path.to_path_buf(),
        ..Default::default()
    };
    for (index, elem) in header.elem_defs.iter().enumerate() {
        if elem.name != "vertex" {
            reader.next_element::<IgnoredAny>().map_err(|e| {
                ColmapError::invalid(
                    path,
                    Record::Nth {
                        kind: "element",
                        index: index as u64,
                        id: None,
                    },
                    elem.name.clone(),
                    format!("cannot skip element: {e}"),
                )
            })?;
            continue;
        }
        let has = |n: &str| elem.properties.iter().any(|p| p.name == n);
        for p in &elem.properties {
            if matches!(p.property_type, PropertyType::List { .. })
                && ["x", "y", "z", "nx", "ny", "nz", "red", "green", "blue"]
                    .contains(&p.name.as_str())
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
        if has("nx") {
            cloud.normals = Some(Vec::new());
        }
        if has("red") {
            cloud.colors = Some(Vec::new());
        }
        // Never trust the header's count for allocation: a row takes at least one byte a property.
        let min_row = elem.properties.len().max(1) as u64;
        let capacity = (elem.count as u64).min(file_len / min_row) as usize;
        let mut rows = 0u64;
        let mut bad = None;
        let seed = ColumnsSeed(Columns {
            cloud: &mut cloud,
            capacity,
            rows: &mut rows,
            bad: &mut bad,
        });
        // PlyReader is a map of elements; take the current element's value with our seed.
        let result = MapAccess::next_value_seed(&mut &mut reader, seed);
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
        return Ok(cloud);
    }
    Err(ColmapError::invalid(
        path,
        Record::File,
        "element vertex",
        "the file has no vertex element",
    ))
}
