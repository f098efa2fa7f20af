//! Where each photo came from and under what licence. `ingest --photo-info FILE` reads a CSV
//! or JSON Lines file keyed by image name (licence, author, source URL, date taken, any other
//! column kept as given); the photos' EXIF (date taken, camera make and model, orientation)
//! is read where present. Both go into `scene/photos.parquet`, written only when there is
//! something to record; every export writes `attribution.csv` from it, and a photo it does
//! not name is "unknown", never guessed.
//!
//! Accepted licence spellings (case and spacing ignored), all stored as one SPDX id:
//! - SPDX ids: `CC-BY-2.0`, `CC-BY-SA-4.0`, `CC-BY-NC-ND-3.0`, `CC0-1.0`, …
//! - Creative Commons short names: `CC BY 2.0`, `CC BY-NC-SA 4.0`, `CC0`;
//! - Creative Commons URLs: `https://creativecommons.org/licenses/by-nc/2.0/`,
//!   `…/publicdomain/zero/1.0/`, `…/publicdomain/mark/1.0/` (YFCC100M's `license url`);
//! - Flickr's licence ids 0–10 and their names (`Attribution-NonCommercial License`, …), as
//!   `flickr.photos.licenses.getInfo` lists them (Flickr's licences are CC version 2.0);
//! - `All Rights Reserved`, `No known copyright restrictions`, `United States Government
//!   Work`, `Public Domain Mark` (stored as `LicenseRef-…` ids), and `unknown` or empty.

use std::collections::BTreeMap;
use std::path::Path;
use std::sync::Arc;

use arrow_array::{Array, ArrayRef, RecordBatch, StringArray, UInt16Array, UInt32Array};
use arrow_schema::{DataType, Field, Schema};

use crate::error::{DatasetError, Result};
use crate::store::Store;

/// Table path of the photos' provenance inside a dataset.
pub const PHOTOS_TABLE: &str = "scene/photos.parquet";
/// The file every export writes at its root: one row per exported photo.
pub const ATTRIBUTION_FILE: &str = "attribution.csv";
/// The licence of a photo nobody gave one for.
pub const UNKNOWN: &str = "unknown";

/// What a photo-info file says about one photo.
#[derive(Debug, Clone, PartialEq)]
pub struct PhotoInfo {
    /// The licence as an SPDX id (or `LicenseRef-…`, or [`UNKNOWN`]).
    pub licence: String,
    /// The licence as the file spelled it.
    pub licence_given: Option<String>,
    pub author: Option<String>,
    pub url: Option<String>,
    pub date_taken: Option<String>,
    /// Every other column, as given.
    pub extra: BTreeMap<String, String>,
}

impl Default for PhotoInfo {
    /// A photo nobody gave a row for: licence unknown, nothing else.
    fn default() -> Self {
        PhotoInfo {
            licence: UNKNOWN.into(),
            licence_given: None,
            author: None,
            url: None,
            date_taken: None,
            extra: BTreeMap::new(),
        }
    }
}

/// What a photo's own EXIF says, where it has one.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Exif {
    pub date_taken: Option<String>,
    pub make: Option<String>,
    pub model: Option<String>,
    /// EXIF orientation 1–8; COLMAP reads pixels as stored, and so does nrw-etl, so a photo
    /// with another value than 1 is shown rotated to the model's eyes (QA flags it).
    pub orientation: Option<u16>,
}

/// One registered image's provenance: the row of [`PHOTOS_TABLE`].
#[derive(Debug, Clone, PartialEq)]
pub struct PhotoRecord {
    pub image_id: u32,
    pub name: String,
    pub info: PhotoInfo,
    pub exif: Exif,
}

const FLICKR: [(&str, &str); 11] = [
    ("All Rights Reserved", "LicenseRef-All-Rights-Reserved"),
    (
        "Attribution-NonCommercial-ShareAlike License",
        "CC-BY-NC-SA-2.0",
    ),
    ("Attribution-NonCommercial License", "CC-BY-NC-2.0"),
    (
        "Attribution-NonCommercial-NoDerivs License",
        "CC-BY-NC-ND-2.0",
    ),
    ("Attribution License", "CC-BY-2.0"),
    ("Attribution-ShareAlike License", "CC-BY-SA-2.0"),
    ("Attribution-NoDerivs License", "CC-BY-ND-2.0"),
    (
        "No known copyright restrictions",
        "LicenseRef-No-Known-Copyright-Restrictions",
    ),
    (
        "United States Government Work",
        "LicenseRef-United-States-Government-Work",
    ),
    ("Public Domain Dedication (CC0)", "CC0-1.0"),
    ("Public Domain Mark", "LicenseRef-Public-Domain-Mark-1.0"),
];

const CC_KINDS: [&str; 6] = ["BY", "BY-SA", "BY-ND", "BY-NC", "BY-NC-SA", "BY-NC-ND"];
const CC_VERSIONS: [&str; 5] = ["1.0", "2.0", "2.5", "3.0", "4.0"];

/// The accepted spellings, for error messages.
pub const LICENCE_SPELLINGS: &str = "an SPDX id (CC-BY-2.0, CC-BY-NC-SA-4.0, CC0-1.0), a Creative Commons name (CC BY-SA 4.0) or URL (https://creativecommons.org/licenses/by/2.0/), a Flickr licence id 0-10 or name (Attribution License), All Rights Reserved, Public Domain Mark, or unknown";

/// `CC-<kind>-<version>` when both parts are Creative Commons'.
fn cc(kind: &str, version: &str) -> Option<String> {
    let kind = kind.to_ascii_uppercase();
    (CC_KINDS.contains(&kind.as_str()) && CC_VERSIONS.contains(&version))
        .then(|| format!("CC-{kind}-{version}"))
}

/// A Creative Commons URL's licence.
fn cc_url(url: &str) -> Option<String> {
    let rest = url.split_once("creativecommons.org/")?.1;
    let parts: Vec<&str> = rest.split('/').filter(|p| !p.is_empty()).collect();
    match parts.as_slice() {
        ["licenses", kind, version, ..] => cc(kind, version),
        ["publicdomain", "zero", "1.0", ..] => Some("CC0-1.0".into()),
        ["publicdomain", "mark", "1.0", ..] => Some("LicenseRef-Public-Domain-Mark-1.0".into()),
        _ => None,
    }
}

/// The SPDX id (or `LicenseRef-…`, or [`UNKNOWN`]) of a licence as a file or the command
/// line spells it; `None` for a spelling not among [`LICENCE_SPELLINGS`].
pub fn normalise_licence(given: &str) -> Option<String> {
    let g = given.trim();
    let folded = g.to_ascii_lowercase();
    if folded.is_empty() || folded == UNKNOWN {
        return Some(UNKNOWN.into());
    }
    if folded.contains("creativecommons.org/") {
        return cc_url(&folded);
    }
    if let Ok(id) = g.parse::<usize>() {
        return FLICKR.get(id).map(|(_, spdx)| spdx.to_string());
    }
    if let Some((_, spdx)) = FLICKR.iter().find(|(name, _)| name.eq_ignore_ascii_case(g)) {
        return Some(spdx.to_string());
    }
    if let Some((_, spdx)) = FLICKR.iter().find(|(_, spdx)| spdx.eq_ignore_ascii_case(g)) {
        return Some(spdx.to_string());
    }
    // SPDX ids and short names alike: `CC BY-SA 4.0`, `cc-by-sa-4.0`, `CC0`, `CC0 1.0`.
    let dashed = folded.split_whitespace().collect::<Vec<_>>().join("-");
    if dashed == "cc0" || dashed == "cc0-1.0" {
        return Some("CC0-1.0".into());
    }
    let body = dashed.strip_prefix("cc-")?;
    let (kind, version) = body.rsplit_once('-')?;
    cc(kind, version)
}

/// Which column of a photo-info file holds what, by the names such files use.
fn role(column: &str) -> Option<&'static str> {
    let c = column.trim().to_ascii_lowercase().replace([' ', '-'], "_");
    Some(match c.as_str() {
        "name" | "image" | "image_name" | "filename" | "file" => "name",
        "licence" | "license" | "licence_id" | "license_id" | "licence_url" | "license_url" => {
            "licence"
        }
        "author" | "owner" | "ownername" | "owner_name" | "photographer" | "creator" | "artist" => {
            "author"
        }
        "url" | "source" | "source_url" | "photo_url" | "page_url" | "flickr_url" => "url",
        "date_taken" | "datetaken" | "date" => "date_taken",
        _ => return None,
    })
}

/// One row's fields (column name, value) into (name, info); errors name the line and column.
fn row_info(path: &Path, line: u64, fields: Vec<(String, String)>) -> Result<(String, PhotoInfo)> {
    let bad = |column: &str, problem: String| DatasetError::Value {
        path: path.into(),
        record: format!("line {line}"),
        field: column.to_string(),
        problem,
    };
    let mut name = None;
    let mut info = PhotoInfo::default();
    for (column, value) in fields {
        let value = value.trim().to_string();
        let keep = (!value.is_empty()).then(|| value.clone());
        match role(&column) {
            Some("name") => name = keep,
            Some("licence") => {
                info.licence = normalise_licence(&value).ok_or_else(|| {
                    bad(
                        &column,
                        format!(
                            "licence {value:?} is not one nrw-etl knows; give {LICENCE_SPELLINGS}"
                        ),
                    )
                })?;
                info.licence_given = keep;
            }
            Some("author") => info.author = keep,
            Some("url") => info.url = keep,
            Some("date_taken") => info.date_taken = keep,
            _ => {
                info.extra.insert(column, value);
            }
        }
    }
    let name = name.ok_or_else(|| {
        bad(
            "name",
            "no image name (a column `name`, `image`, `image_name` or `filename`)".into(),
        )
    })?;
    Ok((name, info))
}

/// A JSON value as the text a CSV cell would hold.
fn json_text(v: &serde_json::Value) -> String {
    match v {
        serde_json::Value::String(s) => s.clone(),
        serde_json::Value::Null => String::new(),
        other => other.to_string(),
    }
}

/// A file's rows: (line, (column, value) pairs).
type Rows = Vec<(u64, Vec<(String, String)>)>;

/// The rows of a CSV file: (line, fields).
fn csv_rows(path: &Path, bytes: &[u8]) -> Result<Rows> {
    let mut reader = csv::ReaderBuilder::new().flexible(false).from_reader(bytes);
    let csv_err = |e: csv::Error| {
        let line = e.position().map_or(0, |p| p.line());
        DatasetError::Value {
            path: path.into(),
            record: format!("line {line}"),
            field: "(row)".into(),
            problem: e.to_string(),
        }
    };
    let header: Vec<String> = reader
        .headers()
        .map_err(csv_err)?
        .iter()
        .map(str::to_string)
        .collect();
    let mut rows = Vec::new();
    for record in reader.records() {
        let record = record.map_err(csv_err)?;
        let line = record.position().map_or(0, |p| p.line());
        rows.push((
            line,
            header
                .iter()
                .cloned()
                .zip(record.iter().map(str::to_string))
                .collect(),
        ));
    }
    Ok(rows)
}

/// The rows of a JSON Lines file (one object per line; blank lines skipped).
fn json_lines_rows(path: &Path, text: &str) -> Result<Rows> {
    let mut rows = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let n = i as u64 + 1;
        if line.trim().is_empty() {
            continue;
        }
        let value: serde_json::Value =
            serde_json::from_str(line).map_err(|e| DatasetError::Value {
                path: path.into(),
                record: format!("line {n}"),
                field: format!("(column {})", e.column()),
                problem: e.to_string(),
            })?;
        let serde_json::Value::Object(map) = value else {
            return Err(DatasetError::Value {
                path: path.into(),
                record: format!("line {n}"),
                field: "(row)".into(),
                problem: "not a JSON object".into(),
            });
        };
        rows.push((
            n,
            map.iter().map(|(k, v)| (k.clone(), json_text(v))).collect(),
        ));
    }
    Ok(rows)
}

/// Read a photo-info file (CSV with a header row, or JSON Lines: `.jsonl`, `.ndjson`, or a
/// first character `{`): image name → (line, what it says). A malformed row, an unknown
/// licence or a name given twice is an error naming the file, line and column.
pub fn read_photo_info(path: &Path) -> Result<BTreeMap<String, (u64, PhotoInfo)>> {
    let bytes = std::fs::read(path).map_err(|e| DatasetError::io(path, e))?;
    let text = std::str::from_utf8(&bytes).map_err(|e| DatasetError::Value {
        path: path.into(),
        record: "file".into(),
        field: "(encoding)".into(),
        problem: format!("not UTF-8: {e}"),
    })?;
    let ext = path.extension().and_then(|e| e.to_str()).unwrap_or("");
    let json = matches!(ext, "jsonl" | "ndjson" | "json") || text.trim_start().starts_with('{');
    let rows = if json {
        json_lines_rows(path, text)?
    } else {
        csv_rows(path, &bytes)?
    };
    let mut out: BTreeMap<String, (u64, PhotoInfo)> = BTreeMap::new();
    for (line, fields) in rows {
        let (name, info) = row_info(path, line, fields)?;
        if let Some((first, _)) = out.get(&name) {
            return Err(DatasetError::Value {
                path: path.into(),
                record: format!("line {line}"),
                field: "name".into(),
                problem: format!("{name:?} is given on line {first} already"),
            });
        }
        out.insert(name, (line, info));
    }
    Ok(out)
}

/// A photo's EXIF as [`Exif`], from the file's first bytes; a photo without EXIF (or with
/// one that does not parse) gives the empty record: EXIF is information, never a reason to
/// drop a photo.
pub fn read_exif(photo: &Path) -> Exif {
    let Ok(file) = std::fs::File::open(photo) else {
        return Exif::default();
    };
    let mut reader = std::io::BufReader::new(file);
    let Ok(exif) = exif::Reader::new().read_from_container(&mut reader) else {
        return Exif::default();
    };
    let text = |tag| {
        exif.get_field(tag, exif::In::PRIMARY)
            .map(|f| {
                f.display_value()
                    .to_string()
                    .trim_matches('"')
                    .trim()
                    .to_string()
            })
            .filter(|s| !s.is_empty())
    };
    Exif {
        date_taken: text(exif::Tag::DateTimeOriginal).or_else(|| text(exif::Tag::DateTime)),
        make: text(exif::Tag::Make),
        model: text(exif::Tag::Model),
        orientation: exif
            .get_field(exif::Tag::Orientation, exif::In::PRIMARY)
            .and_then(|f| f.value.get_uint(0))
            .and_then(|v| u16::try_from(v).ok()),
    }
}

/// Whether a record has anything a table should keep.
fn recorded(r: &PhotoRecord) -> bool {
    r.info != PhotoInfo::default() || r.exif != Exif::default()
}

fn utf8(values: impl Iterator<Item = Option<String>>) -> ArrayRef {
    Arc::new(StringArray::from_iter(values))
}

/// Arrow schema of `scene/photos.parquet` (documented in schemas/scene_photos.toml).
pub fn photos_schema() -> arrow_schema::SchemaRef {
    let text = |name: &str| Field::new(name, DataType::Utf8, true);
    Arc::new(Schema::new(vec![
        Field::new("image_id", DataType::UInt32, false),
        Field::new("name", DataType::Utf8, false),
        Field::new("licence", DataType::Utf8, false),
        text("licence_given"),
        text("author"),
        text("url"),
        text("date_taken"),
        text("extra_json"),
        text("exif_date_taken"),
        text("exif_make"),
        text("exif_model"),
        Field::new("exif_orientation", DataType::UInt16, true),
    ]))
}

/// Write [`PHOTOS_TABLE`] when any photo has a photo-info row or EXIF (nothing otherwise, so
/// a dataset without provenance keeps its bytes); its manifest entry.
pub fn write_photos_table(
    store: &Store,
    records: &[PhotoRecord],
) -> Result<Option<crate::manifest::FileEntry>> {
    if !records.iter().any(recorded) {
        return Ok(None);
    }
    let s = |f: fn(&PhotoRecord) -> Option<String>| utf8(records.iter().map(f));
    let schema = photos_schema();
    let columns: Vec<ArrayRef> = vec![
        Arc::new(UInt32Array::from_iter_values(
            records.iter().map(|r| r.image_id),
        )),
        s(|r| Some(r.name.clone())),
        s(|r| Some(r.info.licence.clone())),
        s(|r| r.info.licence_given.clone()),
        s(|r| r.info.author.clone()),
        s(|r| r.info.url.clone()),
        s(|r| r.info.date_taken.clone()),
        s(|r| {
            (!r.info.extra.is_empty())
                .then(|| serde_json::to_string(&r.info.extra).expect("strings"))
        }),
        s(|r| r.exif.date_taken.clone()),
        s(|r| r.exif.make.clone()),
        s(|r| r.exif.model.clone()),
        Arc::new(UInt16Array::from_iter(
            records.iter().map(|r| r.exif.orientation),
        )),
    ];
    let batch = RecordBatch::try_new(schema, columns).map_err(|source| DatasetError::Arrow {
        table: PHOTOS_TABLE.into(),
        source,
    })?;
    Ok(Some(crate::parquet_io::write_table(
        store,
        PHOTOS_TABLE,
        &batch,
    )?))
}

/// What an export and QA need of a photo: licence, author, URL, EXIF orientation.
#[derive(Debug, Clone, PartialEq)]
pub struct Attribution {
    pub licence: String,
    pub author: Option<String>,
    pub url: Option<String>,
    pub orientation: Option<u16>,
}

impl Default for Attribution {
    fn default() -> Self {
        Attribution {
            licence: UNKNOWN.into(),
            author: None,
            url: None,
            orientation: None,
        }
    }
}

/// Image id → attribution from [`PHOTOS_TABLE`]; empty when the dataset has none (every
/// photo's licence then reads as [`UNKNOWN`]).
pub fn read_attributions(store: &Store) -> Result<BTreeMap<u32, Attribution>> {
    use crate::parquet_io::column;
    let mut out = BTreeMap::new();
    if !store.exists(PHOTOS_TABLE)? {
        return Ok(out);
    }
    let path = store.name(PHOTOS_TABLE);
    let cols = ["image_id", "licence", "author", "url", "exif_orientation"];
    for b in crate::parquet_io::read_batches(store, PHOTOS_TABLE, Some(&cols))? {
        let ids = column::<UInt32Array>(&b, "image_id", &path)?;
        let licence = column::<StringArray>(&b, "licence", &path)?;
        let author = column::<StringArray>(&b, "author", &path)?;
        let url = column::<StringArray>(&b, "url", &path)?;
        let orientation = column::<UInt16Array>(&b, "exif_orientation", &path)?;
        let opt = |a: &StringArray, i: usize| (!a.is_null(i)).then(|| a.value(i).to_string());
        for i in 0..b.num_rows() {
            out.insert(
                ids.value(i),
                Attribution {
                    licence: licence.value(i).to_string(),
                    author: opt(author, i),
                    url: opt(url, i),
                    orientation: (!orientation.is_null(i)).then(|| orientation.value(i)),
                },
            );
        }
    }
    Ok(out)
}

/// Registered photos counted by licence, with the names of those without one and of those
/// whose EXIF orientation is not 1: what `inspect` and QA show.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Tally {
    pub licences: BTreeMap<String, usize>,
    pub without_licence: Vec<String>,
    pub rotated_by_exif: Vec<String>,
}

/// The [`Tally`] of `photos` (image id, name), a photo missing from `attributions` unknown.
pub fn tally<'a>(
    photos: impl Iterator<Item = (u32, &'a str)>,
    attributions: &BTreeMap<u32, Attribution>,
) -> Tally {
    let unknown = Attribution::default();
    let mut t = Tally::default();
    for (id, name) in photos {
        let a = attributions.get(&id).unwrap_or(&unknown);
        *t.licences.entry(a.licence.clone()).or_insert(0) += 1;
        if a.licence == UNKNOWN {
            t.without_licence.push(name.to_string());
        }
        if a.orientation.is_some_and(|o| o != 1) {
            t.rotated_by_exif.push(name.to_string());
        }
    }
    t
}

/// One CSV cell, quoted when it holds a comma, quote or line break (RFC 4180).
fn cell(s: &str) -> String {
    if s.contains([',', '"', '\n', '\r']) {
        format!("\"{}\"", s.replace('"', "\"\""))
    } else {
        s.to_string()
    }
}

/// `attribution.csv`'s bytes: a header and one row per photo (name, licence, author, URL),
/// in the order given.
pub fn attribution_csv<'a>(photos: impl Iterator<Item = (&'a str, &'a Attribution)>) -> Vec<u8> {
    let mut out = String::from("image,licence,author,url\n");
    for (name, a) in photos {
        out.push_str(&format!(
            "{},{},{},{}\n",
            cell(name),
            cell(&a.licence),
            cell(a.author.as_deref().unwrap_or("")),
            cell(a.url.as_deref().unwrap_or(""))
        ));
    }
    out.into_bytes()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_accepted_spelling_of_a_licence_is_one_spdx_id() {
        for (given, spdx) in [
            ("CC-BY-2.0", "CC-BY-2.0"),
            ("cc by-nc-sa 4.0", "CC-BY-NC-SA-4.0"),
            ("CC BY 2.0", "CC-BY-2.0"),
            (
                "http://creativecommons.org/licenses/by-nc/2.0/",
                "CC-BY-NC-2.0",
            ),
            (
                "https://creativecommons.org/publicdomain/zero/1.0/",
                "CC0-1.0",
            ),
            ("4", "CC-BY-2.0"),
            ("0", "LicenseRef-All-Rights-Reserved"),
            ("10", "LicenseRef-Public-Domain-Mark-1.0"),
            (
                "Attribution-NonCommercial-NoDerivs License",
                "CC-BY-NC-ND-2.0",
            ),
            ("CC0", "CC0-1.0"),
            ("", UNKNOWN),
            ("Unknown", UNKNOWN),
        ] {
            assert_eq!(normalise_licence(given).as_deref(), Some(spdx), "{given}");
        }
        for wrong in [
            "11",
            "CC-BY-5.0",
            "GPL",
            "https://creativecommons.org/licenses/xx/2.0/",
        ] {
            assert_eq!(normalise_licence(wrong), None, "{wrong}");
        }
    }

    #[test]
    fn attribution_cells_with_commas_and_quotes_are_quoted() {
        let a = Attribution {
            author: Some("Doe, \"JD\"".into()),
            ..Attribution::default()
        };
        let csv = String::from_utf8(attribution_csv([("a b.jpg", &a)].into_iter())).unwrap();
        assert_eq!(
            csv,
            "image,licence,author,url\na b.jpg,unknown,\"Doe, \"\"JD\"\"\",\n"
        );
    }
}
