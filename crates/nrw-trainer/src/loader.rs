//! The data pipeline: stream a split's views, decode a batch in parallel, take aligned random
//! crops of photo + render + depth (+ semantics), normalise, and hand out batches.
//!
//! Memory is bounded by construction: only one batch of views is decoded at a time (the
//! reader streams from the shards; nothing is cached), and `in_flight` counts decoded views so
//! a test can hold the loader to it.

use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Arc;

use nrw_dataset::reader::Dataset;
use rayon::prelude::*;

use crate::error::{Result, TrainError};

/// Settings of a loader.
#[derive(Debug, Clone)]
pub struct LoaderConfig {
    /// Square crop side in pixels (the paper: 256).
    pub crop: u32,
    pub batch: usize,
    pub seed: u64,
    /// Also return semantics (when the dataset has them).
    pub semantics: bool,
}

/// A batch of aligned crops, channels-first f32, ready for a network.
#[derive(Debug, Clone)]
pub struct Batch {
    pub ids: Vec<u32>,
    /// Where each crop was taken (x, y) in its view.
    pub offsets: Vec<(u32, u32)>,
    pub crop: usize,
    /// B × 3 × S × S, RGB in [−1, 1].
    pub photo: Vec<f32>,
    /// B × 3 × S × S, the colour render in [−1, 1] (−1 where empty).
    pub color: Vec<f32>,
    /// B × 1 × S × S, depth / the dataset's largest depth, in [0, 1]; 0 where empty.
    pub depth: Vec<f32>,
    /// B × 3 × S × S semantic colours in [−1, 1], when asked for and present.
    pub semantics: Option<Vec<f32>>,
}

impl Batch {
    /// Batch size.
    pub fn len(&self) -> usize {
        self.ids.len()
    }
    /// True for an empty batch.
    pub fn is_empty(&self) -> bool {
        self.ids.is_empty()
    }
}

/// One decoded, cropped, normalised view; counted while alive.
struct Item {
    id: u32,
    x: u32,
    y: u32,
    photo: Vec<f32>,
    color: Vec<f32>,
    depth: Vec<f32>,
    semantics: Option<Vec<f32>>,
    _guard: Guard,
}

struct Guard(Arc<AtomicUsize>);
impl Drop for Guard {
    fn drop(&mut self) {
        self.0.fetch_sub(1, Ordering::SeqCst);
    }
}

/// Streams batches of one split, epoch after epoch, in a seeded order.
pub struct Loader<'a> {
    ds: &'a Dataset,
    ids: Vec<u32>,
    cfg: LoaderConfig,
    depth_scale: f32,
    in_flight: Arc<AtomicUsize>,
    peak: Arc<AtomicUsize>,
}

fn to_chw(px: &[u8], channels: usize, keep: usize, s: usize) -> Vec<f32> {
    let mut out = vec![0f32; keep * s * s];
    for i in 0..s * s {
        for c in 0..keep {
            out[c * s * s + i] = px[i * channels + c] as f32 / 127.5 - 1.0;
        }
    }
    out
}

impl<'a> Loader<'a> {
    /// A loader over `split` ("train", "val", or "all" before splitting).
    pub fn new(ds: &'a Dataset, split: &str, cfg: LoaderConfig) -> Result<Loader<'a>> {
        let ids = ds.ids(split)?.to_vec();
        if ids.is_empty() {
            return Err(TrainError::EmptySplit {
                dataset: ds.dir.clone(),
                split: split.into(),
            });
        }
        for (setting, value) in [("batch", cfg.batch), ("crop", cfg.crop as usize)] {
            if value == 0 {
                return Err(TrainError::Setting {
                    setting,
                    problem: "must be positive".into(),
                });
            }
        }
        let depth_scale = nrw_dataset::scene::read_depth_max(&ds.store)?
            .filter(|d| *d > 0.0)
            .unwrap_or(1.0) as f32;
        Ok(Loader {
            ds,
            ids,
            cfg,
            depth_scale,
            in_flight: Arc::new(AtomicUsize::new(0)),
            peak: Arc::new(AtomicUsize::new(0)),
        })
    }

    /// The split's image ids.
    pub fn ids(&self) -> &[u32] {
        &self.ids
    }

    /// Most decoded views alive at once so far (bounded by the batch size).
    pub fn peak_in_flight(&self) -> usize {
        self.peak.load(Ordering::SeqCst)
    }

    /// The order of an epoch: a permutation of the split drawn from (seed, epoch).
    pub fn epoch_order(&self, epoch: u64) -> Vec<u32> {
        nrw_dataset::sampling::epoch_order(&self.ids, self.cfg.seed, epoch)
    }

    /// Decode and crop the given views in parallel into one batch; crop places come from
    /// (seed, epoch, position in the epoch), so a batch is the same whatever the thread count.
    pub fn batch_of(&self, ids: &[u32], epoch: u64, first: usize) -> Result<Batch> {
        let s = self.cfg.crop as usize;
        let items: Vec<Item> = ids
            .par_iter()
            .enumerate()
            .map(|(k, &id)| self.item(id, epoch, first + k))
            .collect::<Result<_>>()?;
        let mut b = Batch {
            ids: Vec::with_capacity(items.len()),
            offsets: Vec::with_capacity(items.len()),
            crop: s,
            photo: Vec::with_capacity(items.len() * 3 * s * s),
            color: Vec::with_capacity(items.len() * 3 * s * s),
            depth: Vec::with_capacity(items.len() * s * s),
            semantics: self.cfg.semantics.then(Vec::new),
        };
        for it in items {
            b.ids.push(it.id);
            b.offsets.push((it.x, it.y));
            b.photo.extend_from_slice(&it.photo);
            b.color.extend_from_slice(&it.color);
            b.depth.extend_from_slice(&it.depth);
            match (&mut b.semantics, it.semantics) {
                (Some(all), Some(sem)) => all.extend_from_slice(&sem),
                (Some(_), None) => b.semantics = None,
                _ => {}
            }
        }
        Ok(b)
    }

    fn item(&self, id: u32, epoch: u64, position: usize) -> Result<Item> {
        let n = self.in_flight.fetch_add(1, Ordering::SeqCst) + 1;
        self.peak.fetch_max(n, Ordering::SeqCst);
        let guard = Guard(self.in_flight.clone());
        let view = self.ds.get(id)?;
        let seed = self.cfg.seed;
        let mut pick = |mx: u32, my: u32| {
            nrw_dataset::sampling::crop_place(seed, epoch, position as u64, mx, my)
        };
        let c = view.random_crop(self.cfg.crop, &mut pick)?;
        let s = self.cfg.crop as usize;
        let photo = to_chw(c.photo.as_raw(), 3, 3, s);
        let mut color = to_chw(c.color.as_raw(), 4, 3, s);
        for i in 0..s * s {
            if c.color.as_raw()[i * 4 + 3] == 0 {
                for ch in 0..3 {
                    color[ch * s * s + i] = -1.0;
                }
            }
        }
        let depth = c
            .depth
            .iter()
            .map(|d| {
                if d.is_finite() && *d > 0.0 {
                    (d / self.depth_scale).min(1.0)
                } else {
                    0.0
                }
            })
            .collect();
        let semantics = if self.cfg.semantics {
            c.semantics.as_ref().map(|m| to_chw(m.as_raw(), 3, 3, s))
        } else {
            None
        };
        Ok(Item {
            id,
            x: c.x,
            y: c.y,
            photo,
            color,
            depth,
            semantics,
            _guard: guard,
        })
    }

    /// Every batch of one epoch, in order (the last one may be short).
    pub fn epoch(&self, epoch: u64) -> impl Iterator<Item = Result<Batch>> + '_ {
        let order = self.epoch_order(epoch);
        let bs = self.cfg.batch;
        (0..order.len().div_ceil(bs)).map(move |k| {
            let ids = &order[k * bs..((k + 1) * bs).min(order.len())];
            self.batch_of(ids, epoch, k * bs)
        })
    }
}
