//! The layouts of one file set (or one record) per view — official, tfrecord, files — share
//! this pipeline: a reader thread streams each split's views, batches are encoded on all
//! cores, and a writer thread appends them in order, so reading, encoding and writing overlap.

use rayon::prelude::*;

use nrw_dataset::ViewRow;

use crate::error::{ExportError, Result};
use crate::staging::Staged;
use crate::writer::Job;
use crate::{ExportSummary, Skipped, SplitExport};

/// Encoded files of one view (path relative to the export, bytes), in the order they are
/// written; a record layout gives one entry whose path is unused.
pub type Encoded = Vec<(String, Vec<u8>)>;

/// How one layout turns a view into files.
pub trait ViewEncoder: Sync {
    /// Refuse a view the layout cannot write at all (checked before any size check).
    fn check_view(&self, _v: &ViewRow) -> Result<()> {
        Ok(())
    }

    /// Why `v` is left out (listed in `export.json`), or None to write it.
    fn skip(&self, _v: &ViewRow) -> Option<String> {
        None
    }

    /// The files of view `v`, the `stem`-th of `split` (zero-padded to sort in order).
    fn encode(&self, v: &ViewRow, split: &str, stem: &str) -> Result<Encoded>;

    /// The record files a split is appended to, in shard order (TFRecords); empty when each
    /// encoded entry is a file of its own.
    fn records(&self, _split: &str) -> Vec<String> {
        Vec::new()
    }
}

/// Views read, encoded in parallel and written in order this many at a time: small enough
/// that reading, encoding and writing overlap, large enough to keep every core busy.
const BATCH: usize = 8;

/// Zero-padded index width for `n` files: at least 4 (the published `%04d`), more when `n`
/// needs it, so names sort in index order at any size.
pub fn index_width(n: usize) -> usize {
    n.saturating_sub(1).to_string().len().max(4)
}

/// Write every split with views through `enc`; a split with none (or none left after
/// skipping) is listed in `summary.empty_splits`.
pub fn write_views(
    job: &Job,
    staged: &Staged,
    enc: &dyn ViewEncoder,
    summary: &mut ExportSummary,
) -> Result<()> {
    for (split, n) in &job.splits {
        if *n == 0 {
            summary.empty_splits.push(split.clone());
            continue;
        }
        let s = write_split(job, split, *n, staged, enc, &mut summary.skipped)?;
        if s.image_ids.is_empty() {
            summary.empty_splits.push(split.clone());
        } else {
            summary.splits.push(s);
        }
    }
    Ok(())
}

/// Where one split's encoded views go: files in the staging folder, or record files.
struct Sink<'a> {
    staged: &'a Staged,
    records: Vec<(String, std::io::BufWriter<std::fs::File>)>,
    /// Views of the split in all (shard choice: position · shards / views).
    views: usize,
    files: Vec<String>,
}

impl<'a> Sink<'a> {
    /// A sink for `views` views; `records` names the split's record files, if any.
    fn open(staged: &'a Staged, records: Vec<String>, views: usize) -> Result<Sink<'a>> {
        let mut sink = Sink {
            staged,
            records: Vec::new(),
            views,
            files: Vec::new(),
        };
        for rel in records {
            let p = staged.claim(&rel)?;
            let f = std::fs::File::create(&p).map_err(|e| ExportError::io(&p, e))?;
            sink.records
                .push((rel, std::io::BufWriter::with_capacity(1 << 20, f)));
        }
        Ok(sink)
    }

    fn put(&mut self, pos: usize, files: Encoded) -> Result<()> {
        use std::io::Write;
        for (rel, bytes) in files {
            if self.records.is_empty() {
                self.staged.write(&rel, &bytes)?;
                self.files.push(rel);
            } else {
                let shard = pos * self.records.len() / self.views;
                let (rel, w) = &mut self.records[shard];
                w.write_all(&bytes)
                    .map_err(|e| ExportError::io(self.staged.dir().join(&*rel), e))?;
            }
        }
        Ok(())
    }

    /// Flush and sync the record files; the files written, relative to the export.
    fn finish(self) -> Result<Vec<String>> {
        let mut files = self.files;
        for (rel, w) in self.records {
            let path = self.staged.dir().join(&rel);
            let f = w
                .into_inner()
                .map_err(|e| ExportError::io(&path, e.into_error()))?;
            f.sync_all().map_err(|e| ExportError::io(&path, e))?;
            files.push(rel);
        }
        Ok(files)
    }
}

/// Encoded views of one batch: (position in the split, files).
type EncodedBatch = Vec<(usize, Encoded)>;

/// One split: its `n` views streamed, encoded and written in order.
fn write_split(
    job: &Job,
    split: &str,
    n: usize,
    staged: &Staged,
    enc: &dyn ViewEncoder,
    skipped: &mut Vec<Skipped>,
) -> Result<SplitExport> {
    let width = index_width(n);
    let mut out = SplitExport::new(split);
    let mut sink = Sink::open(staged, enc.records(split), n)?;
    let tick = job.tick;
    out.files = std::thread::scope(|scope| -> Result<Vec<String>> {
        let (tx, rx) = std::sync::mpsc::sync_channel::<EncodedBatch>(2);
        let writer = scope.spawn(move || -> Result<Vec<String>> {
            for batch in rx {
                for (pos, files) in batch {
                    sink.put(pos, files)?;
                }
            }
            sink.finish()
        });
        let rrx = read_batches(scope, job, split);
        let produced = (|| -> Result<()> {
            let mut seen = 0usize; // views of the split read so far
            for batch in rrx {
                let batch = batch?;
                if batch.is_empty() {
                    return Ok(());
                }
                let mut jobs: Vec<(usize, usize, &ViewRow)> = Vec::new(); // (index, position, view)
                for v in &batch {
                    enc.check_view(v)?;
                    match enc.skip(v) {
                        None => {
                            jobs.push((out.image_ids.len(), seen, v));
                            out.image_ids.push(v.image_id);
                            out.names.push(v.name.clone());
                        }
                        Some(reason) => {
                            skipped.push(Skipped {
                                split: split.into(),
                                image_id: v.image_id,
                                name: v.name.clone(),
                                width: v.width,
                                height: v.height,
                                reason,
                            });
                            tick();
                        }
                    }
                    seen += 1;
                }
                let encoded: EncodedBatch = jobs
                    .par_iter()
                    .map(|&(k, pos, v)| {
                        let e = enc.encode(v, split, &format!("{k:0width$}"))?;
                        tick();
                        Ok((pos, e))
                    })
                    .collect::<Result<_>>()?;
                if tx.send(encoded).is_err() {
                    return Ok(()); // the writer stopped on an error, which join returns
                }
            }
            Ok(())
        })();
        drop(tx);
        let written = writer.join().expect("writer thread does not panic");
        produced?;
        written
    })?;
    Ok(out)
}

/// A reader thread streaming `split`'s views in batches of [`BATCH`] (shard reads and
/// payload copies); an empty batch or an error ends the stream.
fn read_batches<'scope>(
    scope: &'scope std::thread::Scope<'scope, '_>,
    job: &'scope Job,
    split: &'scope str,
) -> std::sync::mpsc::Receiver<Result<Vec<ViewRow>>> {
    let (rtx, rrx) = std::sync::mpsc::sync_channel::<Result<Vec<ViewRow>>>(2);
    let ds = job.ds;
    scope.spawn(move || {
        let mut iter = match ds.iter_split(split) {
            Ok(it) => it,
            Err(e) => {
                let _ = rtx.send(Err(e.into()));
                return;
            }
        };
        loop {
            let batch: Result<Vec<ViewRow>> = iter
                .by_ref()
                .take(BATCH)
                .map(|r| r.map_err(ExportError::from))
                .collect();
            let last = batch.as_ref().map_or(true, |b| b.is_empty());
            if rtx.send(batch).is_err() || last {
                return;
            }
        }
    });
    rrx
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn index_names_sort_in_index_order_at_any_size() {
        assert_eq!(index_width(1), 4);
        assert_eq!(index_width(10_000), 4);
        assert_eq!(index_width(10_001), 5);
        assert_eq!(index_width(1_000_001), 7);
        for n in [9_999usize, 10_000, 10_001, 123_457] {
            let w = index_width(n);
            let names: Vec<String> = [0, 9, 999, 9_999, n - 1]
                .iter()
                .filter(|&&k| k < n)
                .map(|k| format!("{k:0w$}_color.png"))
                .collect();
            let mut sorted = names.clone();
            sorted.sort();
            assert_eq!(names, sorted, "n = {n}");
        }
    }
}
