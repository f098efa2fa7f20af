//! How a consumer draws from a dataset, shared by every reader (the Rust trainer's loader,
//! the Python package) so they draw the same: the seeded epoch order, the seeded crop place
//! of each position in an epoch, and triplets as the paper's published code samples them
//! (for an anchor, a positive drawn uniformly among its `pos_k` nearest photos in style and a
//! negative among its `neg_k` furthest; defaults 5 and 13).

use std::collections::HashSet;

use crate::triplets::TripletRow;
use rand::seq::SliceRandom;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// A sampling setting out of range, or a table that leaves nothing to draw.
#[derive(Debug, thiserror::Error)]
pub enum SamplingError {
    /// A setting out of its range, named as the config field (`pos_k`); a binary names its
    /// own flag for it.
    #[error("{setting}: {problem}")]
    Setting {
        setting: &'static str,
        problem: String,
    },
    /// Holding photos out left no triplet to train on.
    #[error("no training triplets: {anchors} anchors, {held_out} held out")]
    NoTriplets { anchors: usize, held_out: usize },
}

type Result<T> = std::result::Result<T, SamplingError>;

/// Mixes the epoch into a seed (the golden ratio's 64-bit odd constant).
const EPOCH_MIX: u64 = 0x9E37_79B9_7F4A_7C15;
/// Mixes the position in an epoch into a crop seed.
const POSITION_MIX: u64 = 0xD1B5_4A32_D192_ED03;

/// The order of an epoch: a permutation of `ids` drawn from (seed, epoch).
pub fn epoch_order(ids: &[u32], seed: u64, epoch: u64) -> Vec<u32> {
    let mut ids = ids.to_vec();
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ epoch.wrapping_mul(EPOCH_MIX));
    ids.shuffle(&mut rng);
    ids
}

/// Where the crop of the view at `position` of `epoch` goes: (x, y) drawn uniformly in
/// 0..=max_x and 0..=max_y from (seed, epoch, position), so a crop does not depend on which
/// thread, worker or process takes it.
pub fn crop_place(seed: u64, epoch: u64, position: u64, max_x: u32, max_y: u32) -> (u32, u32) {
    let mut rng = ChaCha8Rng::seed_from_u64(
        seed ^ epoch.wrapping_mul(EPOCH_MIX) ^ position.wrapping_mul(POSITION_MIX),
    );
    (rng.random_range(0..=max_x), rng.random_range(0..=max_y))
}

/// (anchor, positive, negative) image ids.
pub type Triplet = (u32, u32, u32);

/// Draws triplets from the triplet table, keeping a held-out set of photos apart.
pub struct TripletSampler {
    train: Vec<(u32, Vec<u32>, Vec<u32>)>,
    held_out: Vec<(u32, Vec<u32>, Vec<u32>)>,
    rng: ChaCha8Rng,
}

/// Whether a photo is held out for evaluation: every `every`-th by a hash of its id, so the
/// choice does not depend on table order.
pub fn is_held_out(id: u32, every: u32) -> bool {
    every > 0 && (id.wrapping_mul(2_654_435_761) >> 7).is_multiple_of(every)
}

impl TripletSampler {
    /// `hold_out_every` = 5 keeps about a fifth of the photos out of training: they are never
    /// anchor, positive or negative of a training triplet, and serve as evaluation anchors.
    pub fn new(
        rows: &[TripletRow],
        pos_k: usize,
        neg_k: usize,
        hold_out_every: u32,
        seed: u64,
    ) -> Result<TripletSampler> {
        let k_near = rows.iter().map(|r| r.nearest_ids.len()).min().unwrap_or(0);
        let k_far = rows.iter().map(|r| r.furthest_ids.len()).min().unwrap_or(0);
        for (setting, k, held, which) in [
            ("pos_k", pos_k, k_near, "nearest"),
            ("neg_k", neg_k, k_far, "furthest"),
        ] {
            if k == 0 || k > held {
                return Err(SamplingError::Setting {
                    setting,
                    problem: format!(
                        "{k}: the triplet table holds {held} {which} per anchor, and it must be between 1 and that; rerun the triplets stage with a larger `triplets.k` or lower it"
                    ),
                });
            }
        }
        let held: HashSet<u32> = rows
            .iter()
            .map(|r| r.anchor_id)
            .filter(|id| is_held_out(*id, hold_out_every))
            .collect();
        let mut train = Vec::new();
        let mut held_out = Vec::new();
        for r in rows {
            let near = r.nearest_ids[..pos_k].to_vec();
            let far = r.furthest_ids[..neg_k].to_vec();
            if held.contains(&r.anchor_id) {
                held_out.push((r.anchor_id, near, far));
            } else {
                let keep = |v: Vec<u32>| -> Vec<u32> {
                    v.into_iter().filter(|i| !held.contains(i)).collect()
                };
                let (near, far) = (keep(near), keep(far));
                if !near.is_empty() && !far.is_empty() {
                    train.push((r.anchor_id, near, far));
                }
            }
        }
        if train.is_empty() {
            return Err(SamplingError::NoTriplets {
                anchors: rows.len(),
                held_out: held.len(),
            });
        }
        Ok(TripletSampler {
            train,
            held_out,
            rng: ChaCha8Rng::seed_from_u64(seed),
        })
    }

    /// Restart the draws from `seed`, as if the sampler had just been made with it.
    pub fn reseed(&mut self, seed: u64) {
        self.rng = ChaCha8Rng::seed_from_u64(seed);
    }

    /// `n` training triplets drawn with replacement.
    pub fn sample(&mut self, n: usize) -> Vec<Triplet> {
        (0..n)
            .map(|_| {
                let (a, near, far) = &self.train[self.rng.random_range(0..self.train.len())];
                let p = near[self.rng.random_range(0..near.len())];
                let q = far[self.rng.random_range(0..far.len())];
                (*a, p, q)
            })
            .collect()
    }

    /// Every (anchor, positive, negative) combination of the held-out anchors.
    pub fn held_out_triplets(&self) -> Vec<Triplet> {
        let mut out = Vec::new();
        for (a, near, far) in &self.held_out {
            for p in near {
                for q in far {
                    out.push((*a, *p, *q));
                }
            }
        }
        out
    }

    /// Anchors used for training.
    pub fn train_anchors(&self) -> usize {
        self.train.len()
    }
}
