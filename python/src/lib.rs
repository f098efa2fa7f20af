//! `nrw._nrw`, the compiled half of the `nrw` Python package: nrw-dataset's reader exposed to
//! Python. Payloads are decoded here with the GIL released into NumPy arrays, tables go to
//! pyarrow through the Arrow C data interface, and draws (epoch order, crop places, triplets)
//! are nrw_dataset::sampling's, so Python and the Rust trainer draw the same.

use pyo3::prelude::*;

/// The extension's allocator (see Cargo.toml): arrays handed to NumPy are freed through it too,
/// as rust-numpy drops their Vec on the Rust side.
#[global_allocator]
static ALLOCATOR: mimalloc::MiMalloc = mimalloc::MiMalloc;

mod dataset;
mod decode;
mod sampling;

pyo3::create_exception!(
    nrw,
    DatasetError,
    pyo3::exceptions::PyException,
    "A dataset that cannot be read: the message names the file, and the record and field where it applies."
);

/// This process's decoding threads. A forked child (a PyTorch DataLoader worker) inherits a
/// pool whose threads stayed in the parent, so it makes its own; the inherited one is left
/// alone (dropping it would signal threads that are not there). `RAYON_NUM_THREADS` sets the
/// size, as for rayon's global pool.
pub(crate) fn pool() -> PyResult<std::sync::Arc<rayon::ThreadPool>> {
    type PerProcess = Option<(u32, std::sync::Arc<rayon::ThreadPool>)>;
    static POOL: std::sync::Mutex<PerProcess> = std::sync::Mutex::new(None);
    let pid = std::process::id();
    let mut pool = POOL.lock().unwrap_or_else(|p| p.into_inner());
    match pool.take() {
        Some((owner, made)) if owner == pid => {
            *pool = Some((owner, made.clone()));
            return Ok(made);
        }
        Some(inherited) => std::mem::forget(inherited),
        None => {}
    }
    let made = std::sync::Arc::new(
        rayon::ThreadPoolBuilder::new()
            .build()
            .map_err(|e| py_err(format!("cannot start decoding threads: {e}")))?,
    );
    *pool = Some((pid, made.clone()));
    Ok(made)
}

/// The Rust error as a Python exception carrying its whole message.
pub(crate) fn py_err(e: impl std::fmt::Display) -> PyErr {
    DatasetError::new_err(e.to_string())
}

/// A reader error as Python sees it: a split or image id the dataset does not have is a
/// `KeyError` (by its variant, not by re-checking ids), anything else a `DatasetError`.
pub(crate) fn dataset_err(e: nrw_dataset::DatasetError) -> PyErr {
    match e {
        nrw_dataset::DatasetError::NoSplit { .. } | nrw_dataset::DatasetError::NotKept { .. } => {
            pyo3::exceptions::PyKeyError::new_err(e.to_string())
        }
        other => py_err(other),
    }
}

#[pymodule]
fn _nrw(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("DatasetError", m.py().get_type::<DatasetError>())?;
    m.add("SCHEMA_VERSION", nrw_dataset::SCHEMA_VERSION)?;
    m.add_class::<dataset::Dataset>()?;
    m.add_class::<dataset::ViewIter>()?;
    m.add_class::<sampling::TripletSampler>()?;
    m.add_function(wrap_pyfunction!(sampling::epoch_order, m)?)?;
    m.add_function(wrap_pyfunction!(sampling::crop_place, m)?)?;
    Ok(())
}
