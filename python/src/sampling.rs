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

/// Triplets drawn as the paper's published code draws them (see the stub file).
#[pyclass(module = "nrw._nrw")]
pub struct TripletSampler {
    inner: sampling::TripletSampler,
}

#[pymethods]
impl TripletSampler {
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

    fn reseed(&mut self, seed: u64) {
        self.inner.reseed(seed)
    }

    fn sample(&mut self, n: usize) -> Vec<(u32, u32, u32)> {
        self.inner.sample(n)
    }

    fn held_out(&self) -> Vec<(u32, u32, u32)> {
        self.inner.held_out_triplets()
    }

    #[getter]
    fn train_anchors(&self) -> usize {
        self.inner.train_anchors()
    }
}
