//! `corpus.parquet`: one row per scene of a many-scene run (the Ray driver's `--scenes`):
//! where its dataset and report are, its counts and verdicts, or why it failed. A plain
//! Parquet table, so pyarrow, DuckDB or polars read it without this tool.

use std::sync::Arc;

use arrow_array::{Array, ArrayRef, RecordBatch, StringArray, UInt64Array};
use arrow_schema::{DataType, Field, Schema, SchemaRef};

use crate::error::{DatasetError, Result};
use crate::manifest::FileEntry;
use crate::parquet_io::{column, read_batches};
use crate::store::Store;

/// The index's file name under the corpus prefix.
pub const CORPUS_FILE: &str = "corpus.parquet";

/// Status of a scene that became a dataset.
pub const STATUS_OK: &str = "ok";
/// Status of a scene whose pipeline failed (the error says why).
pub const STATUS_FAILED: &str = "failed";

/// One scene of a corpus.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct CorpusRow {
    /// The scene folder as given.
    pub scene: String,
    /// The dataset's name under the corpus prefix.
    pub name: String,
    /// Where the dataset is (folder or URL).
    pub dataset: String,
    /// Where its QA report is; None when the scene failed.
    pub report: Option<String>,
    /// [`STATUS_OK`] or [`STATUS_FAILED`].
    pub status: String,
    /// Why the scene failed, as the failing command said it.
    pub error: Option<String>,
    pub registered: Option<u64>,
    pub kept: Option<u64>,
    pub dropped: Option<u64>,
    pub train: Option<u64>,
    pub val: Option<u64>,
    pub descriptors: Option<u64>,
    /// Dropped photos by verdict, as a JSON object (`{"too_sparse": 3}`).
    pub drops: Option<String>,
    /// QA warnings of the dataset.
    pub warnings: Option<u64>,
}

/// The count columns, in schema order.
const COUNTS: [&str; 7] = [
    "registered",
    "kept",
    "dropped",
    "train",
    "val",
    "descriptors",
    "warnings",
];

fn counts(r: &CorpusRow) -> [Option<u64>; 7] {
    [
        r.registered,
        r.kept,
        r.dropped,
        r.train,
        r.val,
        r.descriptors,
        r.warnings,
    ]
}

/// Arrow schema of `corpus.parquet` (documented in schemas/corpus.toml).
pub fn corpus_schema() -> SchemaRef {
    let text = |n: &str, null: bool| Field::new(n, DataType::Utf8, null);
    let mut fields = vec![
        text("scene", false),
        text("name", false),
        text("dataset", false),
        text("report", true),
        text("status", false),
        text("error", true),
    ];
    fields.extend(COUNTS.map(|c| Field::new(c, DataType::UInt64, true)));
    fields.push(text("drops", true));
    Arc::new(Schema::new(fields))
}

/// Write the index as `CORPUS_FILE` under `out`, atomically.
pub fn write_corpus(out: &Store, rows: &[CorpusRow]) -> Result<FileEntry> {
    let text = |f: fn(&CorpusRow) -> Option<&str>| -> ArrayRef {
        Arc::new(rows.iter().map(f).collect::<StringArray>())
    };
    let mut cols: Vec<ArrayRef> = vec![
        text(|r| Some(&r.scene)),
        text(|r| Some(&r.name)),
        text(|r| Some(&r.dataset)),
        text(|r| r.report.as_deref()),
        text(|r| Some(&r.status)),
        text(|r| r.error.as_deref()),
    ];
    for i in 0..COUNTS.len() {
        cols.push(Arc::new(
            rows.iter().map(|r| counts(r)[i]).collect::<UInt64Array>(),
        ));
    }
    cols.push(text(|r| r.drops.as_deref()));
    let batch = RecordBatch::try_new(corpus_schema(), cols).map_err(|e| DatasetError::Arrow {
        table: CORPUS_FILE.into(),
        source: e,
    })?;
    crate::parquet_io::write_table(out, CORPUS_FILE, &batch)
}

/// Read the index back.
pub fn read_corpus(out: &Store) -> Result<Vec<CorpusRow>> {
    let path = &out.name(CORPUS_FILE);
    let mut rows = Vec::new();
    for b in read_batches(out, CORPUS_FILE, None)? {
        let text = |c: &str| column::<StringArray>(&b, c, path);
        let (scene, name, dataset, report, status, error, drops) = (
            text("scene")?,
            text("name")?,
            text("dataset")?,
            text("report")?,
            text("status")?,
            text("error")?,
            text("drops")?,
        );
        let nums: Vec<&UInt64Array> = COUNTS
            .iter()
            .map(|c| column::<UInt64Array>(&b, c, path))
            .collect::<Result<_>>()?;
        let opt = |a: &StringArray, i: usize| a.is_valid(i).then(|| a.value(i).to_string());
        for i in 0..b.num_rows() {
            let n = |k: usize| nums[k].is_valid(i).then(|| nums[k].value(i));
            rows.push(CorpusRow {
                scene: scene.value(i).into(),
                name: name.value(i).into(),
                dataset: dataset.value(i).into(),
                report: opt(report, i),
                status: status.value(i).into(),
                error: opt(error, i),
                registered: n(0),
                kept: n(1),
                dropped: n(2),
                train: n(3),
                val: n(4),
                descriptors: n(5),
                warnings: n(6),
                drops: opt(drops, i),
            });
        }
    }
    Ok(rows)
}
