//! The draws of nrw_dataset::sampling, so Python draws what the Rust trainer draws.

use nrw_dataset::sampling;
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

use crate::dataset::Dataset;
use crate::py_err;

/// The order of an epoch: a permutation of `ids` drawn from (seed, epoch).
#[pyfunction]
pub fn epoch_order(ids: Vec<u32>, seed: u64, epoch: u64) -> Vec<u32> {
    sampling::epoch_order(&ids, seed, epoch)
}

/// The crop place (x, y) of the view at `position` of `epoch`, uniform in 0..=max_x, 0..=max_y.
#[pyfunction]
pub fn crop_place(seed: u64, epoch: u64, position: u64, max_x: u32, max_y: u32) -> (u32, u32) {
    sampling::crop_place(seed, epoch, position, max_x, max_y)
}

/// (anchor, positive, negative) image ids drawn as the paper's code draws them: the positive
/// among an anchor's pos_k nearest in style, the negative among its neg_k furthest; the same
/// seed draws what the Rust trainer draws.
#[pyclass(module = "nrw._nrw")]
pub struct TripletSampler {
    inner: sampling::TripletSampler,
}

#[pymethods]
impl TripletSampler {
    /// Read the dataset's triplet table and keep `pos_k` nearest and `neg_k` furthest per
    /// anchor, every `hold_out_every`-th photo held out.
    #[new]
    #[pyo3(signature = (dataset, pos_k = 5, neg_k = 13, hold_out_every = 5, seed = 0))]
    fn new(
        py: Python<'_>,
        dataset: &Dataset,
        pos_k: usize,
        neg_k: usize,
        hold_out_every: u32,
        seed: u64,
    ) -> PyResult<Self> {
        let ds = dataset.current(py)?;
        let rows = py
            .detach(|| nrw_dataset::triplets::read_triplets(&ds.store))
            .map_err(py_err)?
            .ok_or_else(|| {
                py_err(format!(
                    "{}: no triplets.parquet; run `nrw-etl style` and `nrw-etl triplets` first",
                    dataset.location_str()
                ))
            })?;
        let inner = sampling::TripletSampler::new(&rows, pos_k, neg_k, hold_out_every, seed)
            .map_err(|e| PyValueError::new_err(e.to_string()))?;
        Ok(TripletSampler { inner })
    }

    /// Restart the draws from `seed`, as if the sampler had just been made with it.
    fn reseed(&mut self, seed: u64) {
        self.inner.reseed(seed)
    }

    /// `n` training triplets (anchor, positive, negative), drawn with replacement.
    fn sample(&mut self, n: usize) -> Vec<(u32, u32, u32)> {
        self.inner.sample(n)
    }

    /// Every combination of the held-out anchors, for evaluation.
    fn held_out(&self) -> Vec<(u32, u32, u32)> {
        self.inner.held_out_triplets()
    }

    /// Anchors that training draws from.
    #[getter]
    fn train_anchors(&self) -> usize {
        self.inner.train_anchors()
    }
}
