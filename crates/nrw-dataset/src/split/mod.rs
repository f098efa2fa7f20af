//! `splits.parquet`: which kept photo is for training and which for validation. Assignment
//! is a pure function of (seed, photo name), so it is the same on any machine and thread
//! count; re-running after new photos arrive assigns only the new ones, so a validation photo
//! never moves to training.

use crate::store::Store;
use std::collections::BTreeMap;
use std::sync::Arc;

use arrow_array::{RecordBatch, StringArray, UInt32Array, UInt64Array};
use arrow_schema::{DataType, Field, Schema, SchemaRef};
use sha2::{Digest, Sha256};

use crate::error::{DatasetError, Result};

/// Table path of the split inside a dataset.
pub const SPLITS_TABLE: &str = "splits.parquet";

/// The split the paper trains on, as every table and export names it.
pub const TRAIN: &str = "train";
/// The held-out split (NeRF-W's `test`, the published code's `val/`).
pub const VAL: &str = "val";

/// One photo's assignment.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Assignment {
    pub image_id: u32,
    pub name: String,
    /// `train` or `val`.
    pub split: String,
    /// The seed in force when this photo was assigned.
    pub seed: u64,
}

/// Arrow schema of `splits.parquet` (documented in schemas/splits.toml).
pub fn splits_schema() -> SchemaRef {
    Arc::new(Schema::new(vec![
        Field::new("image_id", DataType::UInt32, false),
        Field::new("name", DataType::Utf8, false),
        Field::new("split", DataType::Utf8, false),
        Field::new("seed", DataType::UInt64, false),
    ]))
}

/// Rank of a photo for a seed: the first 8 bytes of SHA-256(seed ‖ name), platform-independent.
pub fn rank(seed: u64, name: &str) -> u64 {
    let mut h = Sha256::new();
    h.update(seed.to_le_bytes());
    h.update(name.as_bytes());
    u64::from_be_bytes(h.finalize()[..8].try_into().expect("8 bytes"))
}

/// What a split run changed.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct SplitChange {
    pub kept_train: usize,
    pub kept_val: usize,
    pub new_train: usize,
    pub new_val: usize,
    /// Assigned photos no longer kept by ingest (removed from the table).
    pub gone: Vec<String>,
}

/// Assign `eligible` (image id, name) photos given earlier assignments, so that `val`
/// photos are in validation. Earlier assignments are never changed.
pub fn assign(
    eligible: &[(u32, String)],
    previous: &[Assignment],
    val: usize,
    seed: u64,
) -> std::result::Result<(Vec<Assignment>, SplitChange), String> {
    assign_grouped(eligible, previous, val, seed, &BTreeMap::new())
}

/// New photos in units that go to one side together: a near-duplicate group's new members
/// (ranked by their best-ranked member), or one photo; a unit whose group already has an
/// assigned member goes that member's way (`follows`).
struct Unit<'a> {
    rank: u64,
    members: Vec<(&'a str, u32)>,
    follows: Option<&'a str>,
}

fn units<'a>(
    fresh: &[(u64, &'a str, u32)],
    groups: &BTreeMap<String, u32>,
    assigned: &BTreeMap<u32, &'a str>,
) -> Vec<Unit<'a>> {
    let mut by_group: BTreeMap<u32, Unit<'a>> = BTreeMap::new();
    let mut out = Vec::new();
    for &(rank, name, id) in fresh {
        match groups.get(name) {
            Some(g) => {
                let u = by_group.entry(*g).or_insert(Unit {
                    rank,
                    members: Vec::new(),
                    follows: assigned.get(g).copied(),
                });
                u.rank = u.rank.min(rank);
                u.members.push((name, id));
            }
            None => out.push(Unit {
                rank,
                members: vec![(name, id)],
                follows: None,
            }),
        }
    }
    out.extend(by_group.into_values());
    out.sort_by(|a, b| (a.rank, a.members[0].0).cmp(&(b.rank, b.members[0].0)));
    out
}

/// [`assign`] keeping each near-duplicate group (`groups`: photo name → group) on one side:
/// groups are drawn whole, in the order of their best-ranked member, and one that would
/// overfill validation goes to training. A photo joining a group that already has assigned
/// members goes their way.
pub fn assign_grouped(
    eligible: &[(u32, String)],
    previous: &[Assignment],
    val: usize,
    seed: u64,
    groups: &BTreeMap<String, u32>,
) -> std::result::Result<(Vec<Assignment>, SplitChange), String> {
    let (mut out, mut fresh, mut change) = carried_over(eligible, previous, seed);
    if val < change.kept_val {
        return Err(format!(
            "`split.val` {val} is below the {} validation photos already assigned; assignments are never undone (remove {SPLITS_TABLE} to start over)",
            change.kept_val
        ));
    }
    let need = val - change.kept_val;
    if need > fresh.len() {
        return Err(format!(
            "`split.val` {val} asks for {need} more validation photos but only {} unassigned kept photos exist ({} kept in all)",
            fresh.len(),
            eligible.len()
        ));
    }
    fresh.sort();
    // The side each group's earlier-assigned members are on.
    let assigned: BTreeMap<u32, &str> = out
        .iter()
        .filter_map(|a| groups.get(&a.name).map(|g| (*g, a.split.as_str())))
        .map(|(g, s)| (g, if s == VAL { VAL } else { TRAIN }))
        .collect();
    let mut left = need;
    for unit in units(&fresh, groups, &assigned) {
        let split = match unit.follows {
            Some(side) => side,
            None if unit.members.len() <= left => VAL,
            None => TRAIN,
        };
        for (name, id) in unit.members {
            if split == VAL {
                change.new_val += 1;
                left = left.saturating_sub(1);
            } else {
                change.new_train += 1;
            }
            out.push(Assignment {
                image_id: id,
                name: name.to_string(),
                split: split.into(),
                seed,
            });
        }
    }
    out.sort_by_key(|a| a.image_id);
    Ok((out, change))
}

/// A photo no split has assigned yet: its seeded rank, name and image id.
type Fresh<'a> = (u64, &'a str, u32);

/// The eligible photos an earlier split assigned, kept where they were; the others with
/// their seeded rank (unsorted), to be assigned; and what changed so far (the photos the
/// earlier split had that are no longer eligible).
fn carried_over<'a>(
    eligible: &'a [(u32, String)],
    previous: &[Assignment],
    seed: u64,
) -> (Vec<Assignment>, Vec<Fresh<'a>>, SplitChange) {
    let by_name: BTreeMap<&str, &Assignment> =
        previous.iter().map(|a| (a.name.as_str(), a)).collect();
    let mut out = Vec::with_capacity(eligible.len());
    let mut change = SplitChange::default();
    let mut fresh: Vec<Fresh> = Vec::new();
    for (id, name) in eligible {
        match by_name.get(name.as_str()) {
            Some(a) => {
                if a.split == VAL {
                    change.kept_val += 1;
                } else {
                    change.kept_train += 1;
                }
                out.push(Assignment {
                    image_id: *id,
                    ..(*a).clone()
                });
            }
            None => fresh.push((rank(seed, name), name.as_str(), *id)),
        }
    }
    let still: std::collections::BTreeSet<&str> =
        eligible.iter().map(|(_, n)| n.as_str()).collect();
    change.gone = previous
        .iter()
        .filter(|a| !still.contains(a.name.as_str()))
        .map(|a| a.name.clone())
        .collect();
    (out, fresh, change)
}

/// Near-duplicate groups with members on both sides of a split: (group, its members'
/// names), for the warning a published split earns.
pub fn straddling(rows: &[Assignment], groups: &BTreeMap<String, u32>) -> Vec<(u32, Vec<String>)> {
    let mut sides: BTreeMap<u32, (bool, bool, Vec<String>)> = BTreeMap::new();
    for a in rows {
        if let Some(g) = groups.get(&a.name) {
            let e = sides.entry(*g).or_default();
            if a.split == VAL {
                e.1 = true;
            } else {
                e.0 = true;
            }
            e.2.push(a.name.clone());
        }
    }
    sides
        .into_iter()
        .filter(|(_, (t, v, _))| *t && *v)
        .map(|(g, (_, _, n))| (g, n))
        .collect()
}

/// One row of a published Phototourism split file that nerf_pl keeps (it has an id).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TsvRow {
    /// 1-based line number in the file, for messages.
    pub line: usize,
    pub filename: String,
    /// Our split: `train`, or `val` for the file's `test`.
    pub split: String,
}

/// Lines a split file may have: far above any Phototourism scene, a bound on a hostile file.
pub const MAX_TSV_ROWS: usize = 10_000_000;

/// Parse NeRF-W's split file (`filename  id  split  dataset`, tab-separated, header row) as
/// nerf_pl's final loader (branch `nerfw`, `datasets/phototourism.py`) reads it: rows whose
/// `id` is empty or NaN are dropped (`files[~files['id'].isnull()]`); `train` and `test` are
/// the two sets. Any other split value is refused, naming its line.
pub fn parse_phototourism_tsv(path: &std::path::Path, text: &str) -> Result<Vec<TsvRow>> {
    let bad = |line: usize, field: &str, problem: String| DatasetError::Value {
        path: path.into(),
        record: format!("line {line}"),
        field: field.into(),
        problem,
    };
    let mut lines = text.lines().enumerate();
    let (_, header) = lines
        .next()
        .ok_or_else(|| bad(1, "header", "the file is empty".into()))?;
    let cols: Vec<&str> = header.split('\t').map(str::trim).collect();
    let col = |name: &str| {
        cols.iter().position(|c| *c == name).ok_or_else(|| {
            bad(
                1,
                name,
                format!("no `{name}` column in the header {cols:?} (NeRF-W's split files have filename, id, split, dataset)"),
            )
        })
    };
    let (f, i, s) = (col("filename")?, col("id")?, col("split")?);
    let mut out = Vec::new();
    for (k, l) in lines {
        let line = k + 1;
        if line > MAX_TSV_ROWS {
            return Err(bad(
                line,
                "filename",
                format!("more than {MAX_TSV_ROWS} rows"),
            ));
        }
        if l.trim().is_empty() {
            continue;
        }
        let v: Vec<&str> = l.split('\t').collect();
        let get = |c: usize| v.get(c).map_or("", |x| x.trim());
        let id = get(i);
        if id.is_empty() || id.eq_ignore_ascii_case("nan") {
            continue;
        }
        let filename = get(f);
        if filename.is_empty() {
            return Err(bad(line, "filename", "empty".into()));
        }
        let split = match get(s) {
            "train" => TRAIN,
            "test" => VAL,
            other => {
                return Err(bad(
                    line,
                    "split",
                    format!("{other:?} is neither train nor test"),
                ))
            }
        };
        out.push(TsvRow {
            line,
            filename: filename.into(),
            split: split.into(),
        });
    }
    Ok(out)
}

/// The photo a split-file name stands for: the model's image name itself, or the one photo
/// with the same name but for the extension (an export may have re-encoded it, `a.jpg` →
/// `a.png`). None when no photo, or more than one, matches.
fn match_name<'a>(
    name: &str,
    exact: &BTreeMap<&'a str, u32>,
    by_stem: &BTreeMap<String, Vec<(&'a str, u32)>>,
) -> Option<(&'a str, u32)> {
    if let Some((&n, &id)) = exact.get_key_value(name) {
        return Some((n, id));
    }
    match by_stem.get(&stem(name))?.as_slice() {
        [one] => Some(*one),
        _ => None,
    }
}

fn stem(name: &str) -> String {
    let p = std::path::Path::new(name);
    p.with_extension("").to_string_lossy().into_owned()
}

/// What a split from a file assigned, and the listed photos it could not assign.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct TsvAssignment {
    pub rows: Vec<Assignment>,
    /// Listed photos that are in the model but not kept (dropped by ingest's filters).
    pub not_kept: Vec<String>,
    /// Kept photos the file does not list (they are in no split, as in nerf_pl).
    pub unlisted: usize,
}

/// Assign exactly the sets a split file lists. `model` is every image (id, name) of the
/// scene, `kept` the ids ingest kept. A name that is not in the model is refused (up to five
/// named, with the count), as is a photo listed twice.
pub fn assign_from_tsv(
    path: &std::path::Path,
    rows: &[TsvRow],
    model: &[(u32, String)],
    kept: &std::collections::BTreeSet<u32>,
) -> Result<TsvAssignment> {
    let exact: BTreeMap<&str, u32> = model.iter().map(|(i, n)| (n.as_str(), *i)).collect();
    let mut by_stem: BTreeMap<String, Vec<(&str, u32)>> = BTreeMap::new();
    for (i, n) in model {
        by_stem.entry(stem(n)).or_default().push((n.as_str(), *i));
    }
    let mut out = TsvAssignment::default();
    let mut unknown = Vec::new();
    let mut seen: BTreeMap<u32, usize> = BTreeMap::new();
    for r in rows {
        let Some((name, id)) = match_name(&r.filename, &exact, &by_stem) else {
            unknown.push(format!("{:?} (line {})", r.filename, r.line));
            continue;
        };
        if let Some(first) = seen.insert(id, r.line) {
            return Err(DatasetError::Value {
                path: path.into(),
                record: format!("line {}", r.line),
                field: "filename".into(),
                problem: format!("{:?} is listed again (first on line {first})", r.filename),
            });
        }
        if !kept.contains(&id) {
            out.not_kept.push(name.to_string());
            continue;
        }
        out.rows.push(Assignment {
            image_id: id,
            name: name.to_string(),
            split: r.split.clone(),
            seed: 0,
        });
    }
    if !unknown.is_empty() {
        return Err(DatasetError::Value {
            path: path.into(),
            record: unknown[0].clone(),
            field: "filename".into(),
            problem: format!(
                "{} name(s) match no image of the scene's model: {}",
                unknown.len(),
                unknown
                    .iter()
                    .take(5)
                    .cloned()
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        });
    }
    out.unlisted = kept.len() - out.rows.len();
    out.rows.sort_by_key(|a| a.image_id);
    Ok(out)
}

/// Write `splits.parquet` atomically.
pub fn write_splits(dir: &Store, rows: &[Assignment]) -> Result<crate::manifest::FileEntry> {
    let batch = RecordBatch::try_new(
        splits_schema(),
        vec![
            Arc::new(UInt32Array::from_iter_values(
                rows.iter().map(|a| a.image_id),
            )),
            Arc::new(StringArray::from_iter_values(
                rows.iter().map(|a| a.name.as_str()),
            )),
            Arc::new(StringArray::from_iter_values(
                rows.iter().map(|a| a.split.as_str()),
            )),
            Arc::new(UInt64Array::from_iter_values(rows.iter().map(|a| a.seed))),
        ],
    )
    .map_err(|e| DatasetError::Arrow {
        table: SPLITS_TABLE.into(),
        source: e,
    })?;
    crate::parquet_io::write_table(dir, SPLITS_TABLE, &batch)
}

/// Read `splits.parquet`, or nothing if the dataset has no split yet.
pub fn read_splits(dir: &Store) -> Result<Vec<Assignment>> {
    let path = dir.name(SPLITS_TABLE);
    if !dir.exists(SPLITS_TABLE)? {
        return Ok(Vec::new());
    }
    use crate::parquet_io::column;
    let mut out = Vec::new();
    for b in crate::parquet_io::read_batches(dir, SPLITS_TABLE, None)? {
        let ids = column::<UInt32Array>(&b, "image_id", &path)?;
        let names = column::<StringArray>(&b, "name", &path)?;
        let splits = column::<StringArray>(&b, "split", &path)?;
        let seeds = column::<UInt64Array>(&b, "seed", &path)?;
        for i in 0..ids.len() {
            out.push(Assignment {
                image_id: ids.value(i),
                name: names.value(i).into(),
                split: splits.value(i).into(),
                seed: seeds.value(i),
            });
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests;
