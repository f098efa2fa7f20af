//! Descriptors laid out chunk-major — for each run of [`KCHUNK`] dimensions, that run of every
//! row, contiguous — in memory or in a scratch file, so every whole-collection computation
//! reads them in passes and never holds N full descriptors: a K-chunk of all rows (what the
//! blocked GEMM multiplies) and a block of full rows (what the PCA multiplies) are both a
//! handful of contiguous reads.
//!
//! Exact distances of chosen pairs are summed chunk by chunk with the eight partial sums of
//! [`crate::distance2_f64`] carried from one chunk to the next (chunks are multiples of eight
//! values long), so they equal `distance2_f64` of the full rows to the bit.

use std::fs::File;
use std::os::unix::fs::FileExt;

use rayon::prelude::*;

use crate::KnnError;

/// Values per chunk: the dot products of the exact path are GEMMs over this many terms.
pub const KCHUNK: usize = 4096;

/// Bytes of scratch file read per call while a chunk streams through a sink.
const READ_PIECE: usize = 1 << 20;

/// A failure of a streamed computation: the descriptors' own problem, or the source's.
#[derive(Debug, thiserror::Error)]
pub enum StreamError<E: std::error::Error + 'static> {
    #[error(transparent)]
    Knn(#[from] KnnError),
    #[error(transparent)]
    Source(E),
    #[error("scratch file of the descriptors ({path}): {source}")]
    Scratch {
        path: String,
        #[source]
        source: std::io::Error,
    },
}

/// Where the chunk-major values live.
enum Backing {
    Memory(Vec<f32>),
    /// An unlinked temporary file (nothing is left behind if the process dies).
    File {
        file: File,
        path: String,
    },
}

/// N descriptors of one dimension, chunk-major, with their squared norms (f64, summed in row
/// order, as the in-memory path sums them).
pub struct Spilled {
    backing: Backing,
    n: usize,
    dim: usize,
    norm2: Vec<f64>,
}

/// Squared norm summed in f64 in value order.
fn norm2_of(r: &[f32]) -> f64 {
    r.iter().map(|v| (*v as f64) * (*v as f64)).sum()
}

/// The first value of `r` that is not finite, as the error naming row `row`.
pub(crate) fn not_finite(row: usize, r: &[f32]) -> Option<KnnError> {
    r.iter()
        .enumerate()
        .find(|(_, v)| !v.is_finite())
        .map(|(index, value)| KnnError::NotFinite {
            row,
            index,
            value: *value,
        })
}

/// Offset (in values) of row `i`'s run of the chunk starting at `k0` (`kc` long).
fn at(n: usize, k0: usize, kc: usize, i: usize) -> usize {
    n * k0 + i * kc
}

impl Spilled {
    /// Rows already in memory, copied once into chunk-major order (checked: one dimension,
    /// all finite).
    pub fn from_rows(rows: &[Vec<f32>]) -> Result<Spilled, KnnError> {
        let dim = crate::validate(rows)?;
        let n = rows.len();
        let mut values = vec![0f32; n * dim];
        for k0 in (0..dim).step_by(KCHUNK) {
            let kc = KCHUNK.min(dim - k0);
            values[n * k0..n * (k0 + kc)]
                .par_chunks_mut(kc)
                .zip(rows.par_iter())
                .for_each(|(d, r)| d.copy_from_slice(&r[k0..k0 + kc]));
        }
        Ok(Spilled {
            backing: Backing::Memory(values),
            n,
            dim,
            norm2: rows.par_iter().map(|r| norm2_of(r)).collect(),
        })
    }

    /// `n` rows from a source that calls its sink once per row with the row's index (each of
    /// `0..n` once, any order), written to an unlinked scratch file under the system's
    /// temporary folder: memory holds one row at a time. The dimension is the first row's.
    pub fn from_source<E: std::error::Error + 'static>(
        n: usize,
        source: impl FnOnce(&mut dyn FnMut(usize, &[f32])) -> Result<(), E>,
    ) -> Result<Spilled, StreamError<E>> {
        let path = std::env::temp_dir().join(format!(
            "nrw-knn-{}-{}.f32",
            std::process::id(),
            SCRATCH_SEQ.fetch_add(1, std::sync::atomic::Ordering::Relaxed)
        ));
        let scratch = |source| StreamError::Scratch {
            path: path.display().to_string(),
            source,
        };
        let file = std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .create_new(true)
            .open(&path)
            .map_err(scratch)?;
        std::fs::remove_file(&path).map_err(scratch)?;
        let mut dim: Option<usize> = None;
        let mut norm2 = vec![f64::NAN; n];
        let mut seen = vec![false; n];
        let mut first_err: Option<KnnError> = None;
        let mut io_err: Option<std::io::Error> = None;
        let mut bytes = Vec::new();
        source(&mut |i, r| {
            if first_err.is_some() || io_err.is_some() || i >= n || seen[i] {
                return;
            }
            seen[i] = true;
            let d = *dim.get_or_insert(r.len());
            if r.len() != d {
                first_err = Some(KnnError::Dimension {
                    row: i,
                    len: r.len(),
                    dim: d,
                });
                return;
            }
            if let Some(e) = not_finite(i, r) {
                first_err = Some(e);
                return;
            }
            norm2[i] = norm2_of(r);
            for k0 in (0..d).step_by(KCHUNK) {
                let kc = KCHUNK.min(d - k0);
                bytes.clear();
                r[k0..k0 + kc]
                    .iter()
                    .for_each(|v| bytes.extend_from_slice(&v.to_le_bytes()));
                if let Err(e) = file.write_all_at(&bytes, 4 * at(n, k0, kc, i) as u64) {
                    io_err = Some(e);
                    return;
                }
            }
        })
        .map_err(StreamError::Source)?;
        if let Some(e) = io_err {
            return Err(scratch(e));
        }
        if let Some(e) = first_err {
            return Err(e.into());
        }
        if let Some(missing) = seen.iter().position(|s| !s) {
            return Err(KnnError::Missing { row: missing }.into());
        }
        Ok(Spilled {
            backing: Backing::File {
                file,
                path: path.display().to_string(),
            },
            n,
            dim: dim.unwrap_or(0),
            norm2,
        })
    }

    /// Number of rows.
    pub fn len(&self) -> usize {
        self.n
    }

    /// Whether there are no rows.
    pub fn is_empty(&self) -> bool {
        self.n == 0
    }

    /// Values per row.
    pub fn dim(&self) -> usize {
        self.dim
    }

    /// Squared norms of the rows.
    pub(crate) fn norm2(&self) -> &[f64] {
        &self.norm2
    }

    /// Values `from..from + len` of the chunk-major layout, piece by piece into `sink`
    /// (offset within the request, values).
    fn read(&self, from: usize, len: usize, sink: &mut dyn FnMut(usize, &[f32])) {
        match &self.backing {
            Backing::Memory(v) => sink(0, &v[from..from + len]),
            Backing::File { file, path } => {
                let mut bytes = vec![0u8; READ_PIECE.min(4 * len)];
                let mut vals = Vec::with_capacity(bytes.len() / 4);
                let mut done = 0;
                while done < len {
                    let take = (len - done).min(bytes.len() / 4);
                    let b = &mut bytes[..4 * take];
                    // A scratch file this process wrote and holds open cannot shrink: a
                    // failed read is the machine's failure, not the data's.
                    file.read_exact_at(b, 4 * (from + done) as u64)
                        .unwrap_or_else(|e| panic!("reading the scratch file {path}: {e}"));
                    vals.clear();
                    vals.extend(
                        b.chunks_exact(4)
                            .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]])),
                    );
                    sink(done, &vals);
                    done += take;
                }
            }
        }
    }

    /// The chunk starting at dimension `k0` (`kc` values) of every row into `out` (n × kc,
    /// row-major), converted to `T`.
    pub(crate) fn chunk<T: From32>(&self, k0: usize, kc: usize, out: &mut [T]) {
        let out = &mut out[..self.n * kc];
        self.read(self.n * k0, self.n * kc, &mut |off, vals| {
            out[off..off + vals.len()]
                .iter_mut()
                .zip(vals)
                .for_each(|(d, v)| *d = T::from32(*v));
        });
    }

    /// Rows `rows` in full into `out` (rows.len() × dim, row-major), `x − shift` per value.
    pub(crate) fn rows_into(&self, rows: std::ops::Range<usize>, shift: &[f32], out: &mut [f32]) {
        let (dim, b) = (self.dim, rows.len());
        for k0 in (0..dim).step_by(KCHUNK) {
            let kc = KCHUNK.min(dim - k0);
            let from = at(self.n, k0, kc, rows.start);
            self.read(from, b * kc, &mut |off, vals| {
                for (t, v) in vals.iter().enumerate() {
                    let (r, c) = ((off + t) / kc, (off + t) % kc);
                    out[r * dim + k0 + c] = v - shift[k0 + c];
                }
            });
        }
    }

    /// Exact squared distances of `pairs` (row indices), each equal to `distance2_f64` of the
    /// two rows to the bit, in one pass over the chunks: 64 bytes of state per pair.
    pub fn pair_distances(&self, pairs: &[(u32, u32)]) -> Vec<f64> {
        let (n, dim) = (self.n, self.dim);
        let mut acc = vec![[0f64; 8]; pairs.len()];
        let mut tail = vec![0f64; pairs.len()];
        let mut buf = vec![0f32; n * KCHUNK.min(dim)];
        for k0 in (0..dim).step_by(KCHUNK) {
            let kc = KCHUNK.min(dim - k0);
            let last = k0 + kc == dim;
            self.chunk(k0, kc, &mut buf);
            let buf = &buf[..n * kc];
            acc.par_iter_mut()
                .zip(tail.par_iter_mut())
                .zip(pairs.par_iter())
                .for_each(|((a, t), &(i, j))| {
                    let (x, y) = (
                        &buf[i as usize * kc..(i as usize + 1) * kc],
                        &buf[j as usize * kc..(j as usize + 1) * kc],
                    );
                    let (cx, cy) = (x.chunks_exact(8), y.chunks_exact(8));
                    let (rx, ry) = (cx.remainder(), cy.remainder());
                    for (p, q) in cx.zip(cy) {
                        for l in 0..8 {
                            let d = p[l] as f64 - q[l] as f64;
                            a[l] += d * d;
                        }
                    }
                    // Only the last chunk can end off a multiple of eight; its remainder
                    // is the full row's, added after the partial sums as distance2_f64 does.
                    if last {
                        *t = a.iter().sum::<f64>();
                        for (p, q) in rx.iter().zip(ry) {
                            let d = *p as f64 - *q as f64;
                            *t += d * d;
                        }
                    }
                });
        }
        if dim == 0 {
            return vec![0.0; pairs.len()];
        }
        tail
    }

    /// Rows `anchors` of the full N × N squared-distance matrix (row-major, f64, each entry
    /// equal to `distance2_f64`): one pass over the chunks per call, 72 bytes per entry.
    pub fn distance_rows(&self, anchors: std::ops::Range<usize>) -> Vec<f64> {
        let n = self.n as u32;
        let pairs: Vec<(u32, u32)> = anchors
            .flat_map(|i| (0..n).map(move |j| (i as u32, j)))
            .collect();
        self.pair_distances(&pairs)
    }
}

/// Exact distances of a set of pairs, measured in one pass and looked up by pair.
pub(crate) struct PairDistances {
    pairs: Vec<(u32, u32)>,
    d: Vec<f64>,
}

impl PairDistances {
    /// Measure every pair (i, j) of `pairs` (any order, repeats and mirror images allowed).
    pub(crate) fn measure(s: &Spilled, pairs: impl IntoIterator<Item = (usize, usize)>) -> Self {
        let mut pairs: Vec<(u32, u32)> = pairs
            .into_iter()
            .map(|(i, j)| (i.min(j) as u32, i.max(j) as u32))
            .collect();
        pairs.sort_unstable();
        pairs.dedup();
        let d = s.pair_distances(&pairs);
        PairDistances { pairs, d }
    }

    /// The distance of i and j (either order); they must have been measured.
    pub(crate) fn get(&self, i: usize, j: usize) -> f64 {
        let key = (i.min(j) as u32, i.max(j) as u32);
        self.d[self
            .pairs
            .binary_search(&key)
            .expect("every asked pair was measured")]
    }
}

/// Scratch files made by this process so far (their names must differ).
static SCRATCH_SEQ: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);

/// An element type a chunk converts to (f32 or f64; both hold an f32 exactly).
pub(crate) trait From32: Copy + Send + Sync {
    fn from32(v: f32) -> Self;
}

impl From32 for f32 {
    fn from32(v: f32) -> Self {
        v
    }
}

impl From32 for f64 {
    fn from32(v: f32) -> Self {
        v as f64
    }
}
