//! `nrw.Dataset`: open a dataset folder or object-store URL, list its splits, stream views,
//! fetch views by id, and hand its tables to pyarrow.

use std::collections::HashMap;
use std::sync::Arc;

use arrow_pyarrow::IntoPyArrow;
use nrw_dataset::reader::{self, GroupRead};
use nrw_dataset::Store;
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};
use rayon::prelude::*;

use crate::decode::{decode, Decoded};
use crate::{dataset_err, py_err};

/// An nrw-etl dataset opened for reading: a folder or an s3://, gs:// or az:// URL, with the
/// CLI's credentials. Its views stream as dicts of NumPy arrays, its tables as pyarrow.
#[pyclass(module = "nrw._nrw", frozen)]
pub struct Dataset {
    /// The opened dataset and the process that opened it: a forked child (a DataLoader
    /// worker) reopens it, as object-store connections do not survive a fork.
    opened: std::sync::Mutex<(u32, Arc<reader::Dataset>)>,
    location: String,
    /// Provider settings given to the constructor, kept so a worker process can reopen.
    options: HashMap<String, String>,
}

/// What a pickled `Dataset` is made from again: location and provider settings.
type Reopen = (String, HashMap<String, String>);

/// Decode views on this process's decoding threads; the caller has released the GIL.
fn decode_all(
    pool: &rayon::ThreadPool,
    views: Vec<nrw_dataset::ViewRow>,
) -> nrw_dataset::Result<Vec<Decoded>> {
    pool.install(|| views.into_par_iter().map(decode).collect())
}

/// Open a dataset (without the GIL).
fn open(location: &str, options: &HashMap<String, String>) -> nrw_dataset::Result<reader::Dataset> {
    let pairs: Vec<(String, String)> = options.clone().into_iter().collect();
    reader::Dataset::open(Store::open_with(
        &nrw_dataset::Location::parse(location),
        &pairs,
    )?)
}

impl Dataset {
    /// The dataset as opened, for what needs no read (sizes, ids, splits).
    fn meta(&self) -> Arc<reader::Dataset> {
        self.opened
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .1
            .clone()
    }

    /// The dataset as opened in this process (reopened once in a forked child).
    pub(crate) fn current(&self, py: Python<'_>) -> PyResult<Arc<reader::Dataset>> {
        let pid = std::process::id();
        let lock = || self.opened.lock().unwrap_or_else(|p| p.into_inner());
        {
            let opened = lock();
            if opened.0 == pid {
                return Ok(opened.1.clone());
            }
        }
        // Opened without the lock held: a thread waiting for it holds the GIL.
        let again = py
            .detach(|| open(&self.location, &self.options))
            .map_err(py_err)?;
        let mut opened = lock();
        if opened.0 != pid {
            *opened = (pid, Arc::new(again));
        }
        Ok(opened.1.clone())
    }

    /// The image ids of `split`, or of every kept view when None.
    fn ids_of(&self, split: Option<&str>) -> PyResult<Vec<u32>> {
        match split {
            None => Ok(self.meta().all_ids()),
            Some(s) => self.meta().ids(s).map(<[u32]>::to_vec).map_err(dataset_err),
        }
    }
}

#[pymethods]
impl Dataset {
    /// Open a dataset: a folder or an s3://, gs:// or az:// URL; `options` are provider
    /// settings named as the environment variables in lower case (aws_endpoint_url, ...).
    #[new]
    #[pyo3(signature = (location, options = None))]
    fn new(
        py: Python<'_>,
        location: PathOrUrl,
        options: Option<HashMap<String, String>>,
    ) -> PyResult<Self> {
        let location = location.0;
        let options = options.unwrap_or_default();
        let inner = py.detach(|| open(&location, &options)).map_err(py_err)?;
        Ok(Dataset {
            opened: std::sync::Mutex::new((std::process::id(), Arc::new(inner))),
            location,
            options,
        })
    }

    /// Pickled as its location and settings: a DataLoader worker process reopens it.
    fn __reduce__<'py>(slf: &Bound<'py, Self>) -> PyResult<(Bound<'py, PyAny>, Reopen)> {
        let me = slf.get();
        Ok((
            slf.get_type().into_any(),
            (me.location.clone(), me.options.clone()),
        ))
    }

    /// Number of kept views.
    fn __len__(&self) -> usize {
        self.meta().len()
    }

    fn __repr__(&self) -> String {
        let splits: Vec<String> = self
            .meta()
            .splits()
            .into_iter()
            .map(|(n, k)| format!("{n}={k}"))
            .collect();
        format!(
            "nrw.Dataset({:?}, views={}, {})",
            self.location,
            self.meta().len(),
            splits.join(", ")
        )
    }

    fn __contains__(&self, image_id: u32) -> bool {
        self.meta().contains(image_id)
    }

    /// Where the dataset is, as given.
    #[getter]
    fn location(&self) -> &str {
        &self.location
    }

    /// The dataset's schema version (only this package's SCHEMA_VERSION opens).
    #[getter]
    fn schema_version(&self) -> u32 {
        self.meta().manifest.schema_version
    }

    /// The scene's largest depth, which the Rust loader divides depth by; None if unrecorded.
    #[getter]
    fn depth_max(&self, py: Python<'_>) -> PyResult<Option<f64>> {
        let ds = self.current(py)?;
        py.detach(|| nrw_dataset::scene::read_depth_max(&ds.store))
            .map_err(py_err)
    }

    /// Split names with their sizes ({"all": n} before `nrw-etl split`).
    fn splits(&self) -> HashMap<String, usize> {
        self.meta().splits().into_iter().collect()
    }

    /// A split's image ids, sorted; every kept view's in file order when split is None.
    #[pyo3(signature = (split = None))]
    fn ids(&self, split: Option<&str>) -> PyResult<Vec<u32>> {
        self.ids_of(split)
    }

    /// Stream the views of a split, of `ids`, or of every kept view, in file order, as dicts
    /// of NumPy arrays (photo, render, depth, and normals, semantics, labels, transient when
    /// present); each payload's CRC-32 is checked first.
    #[pyo3(signature = (split = None, *, ids = None))]
    fn views(
        slf: &Bound<'_, Self>,
        split: Option<&str>,
        ids: Option<Vec<u32>>,
    ) -> PyResult<ViewIter> {
        let me = slf.get();
        let ids = match (split, ids) {
            (Some(_), Some(_)) => {
                return Err(PyValueError::new_err("give a split or ids, not both"))
            }
            (_, Some(ids)) => ids,
            (split, None) => me.ids_of(split)?,
        };
        let reads = me.meta().reads(&ids).map_err(dataset_err)?;
        Ok(ViewIter {
            dataset: slf.clone().unbind(),
            reads: std::sync::Mutex::new((reads.into_iter().rev().collect(), Vec::new())),
        })
    }

    /// One view by image id (KeyError when it is not a kept view).
    fn get<'py>(&self, py: Python<'py>, image_id: u32) -> PyResult<Bound<'py, PyDict>> {
        let ds = self.current(py)?;
        let view = py
            .detach(|| ds.get(image_id).and_then(decode))
            .map_err(dataset_err)?;
        view.into_dict(py)
    }

    /// Views in the order of `ids`, each row group read once, decoded in parallel.
    fn get_many<'py>(&self, py: Python<'py>, ids: Vec<u32>) -> PyResult<Bound<'py, PyList>> {
        let (ds, pool) = (self.current(py)?, crate::pool()?);
        let decoded = py
            .detach(|| -> nrw_dataset::Result<Vec<Decoded>> {
                let mut views: HashMap<u32, nrw_dataset::ViewRow> = HashMap::new();
                for read in ds.reads(&ids)? {
                    for v in ds.read(&read)? {
                        views.insert(v.image_id, v);
                    }
                }
                // A repeated id decodes again (its row was read once).
                let ordered: Vec<nrw_dataset::ViewRow> =
                    ids.iter().map(|id| views[id].clone()).collect();
                decode_all(&pool, ordered)
            })
            .map_err(dataset_err)?;
        let dicts = decoded
            .into_iter()
            .map(|d| d.into_dict(py))
            .collect::<PyResult<Vec<_>>>()?;
        PyList::new(py, dicts)
    }

    /// triplets.parquet as a pyarrow.Table (its manifest hash checked), None before
    /// `nrw-etl triplets`.
    fn triplets<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyAny>>> {
        let ds = self.current(py)?;
        let batches = py
            .detach(|| nrw_dataset::triplets::table(&ds.store))
            .map_err(py_err)?;
        batches
            .map(|b| to_pyarrow(py, b, nrw_dataset::triplets::triplets_schema()))
            .transpose()
    }

    /// The style descriptors the manifest lists as a pyarrow.Table (each row's CRC-32
    /// checked), None before `nrw-etl style`.
    fn descriptors<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyAny>>> {
        let ds = self.current(py)?;
        let batches = py
            .detach(|| nrw_dataset::descriptors::table(&ds.store))
            .map_err(py_err)?;
        if batches.is_empty() {
            return Ok(None);
        }
        to_pyarrow(py, batches, nrw_dataset::descriptors::descriptors_schema()).map(Some)
    }
}

/// Batches as one pyarrow.Table, their buffers shared through the C data interface.
fn to_pyarrow(
    py: Python<'_>,
    batches: Vec<arrow_array::RecordBatch>,
    empty_schema: arrow_schema::SchemaRef,
) -> PyResult<Bound<'_, PyAny>> {
    let schema = batches.first().map(|b| b.schema()).unwrap_or(empty_schema);
    arrow_pyarrow::Table::try_new(batches, schema)
        .map_err(py_err)?
        .into_pyarrow(py)
}

/// A folder given as str or os.PathLike, or a URL.
struct PathOrUrl(String);

impl<'a, 'py> FromPyObject<'a, 'py> for PathOrUrl {
    type Error = PyErr;
    fn extract(ob: Borrowed<'a, 'py, PyAny>) -> PyResult<Self> {
        let fspath = ob.py().import("os")?.getattr("fspath")?;
        Ok(PathOrUrl(fspath.call1((ob,))?.extract()?))
    }
}

/// Views streamed a row group at a time: each group is read and decoded with the GIL
/// released, so memory stays at one row group's views.
#[pyclass(module = "nrw._nrw", frozen)]
pub struct ViewIter {
    dataset: Py<Dataset>,
    /// Reads still to do (last first) and decoded views not yet handed out (last first).
    reads: std::sync::Mutex<(Vec<GroupRead>, Vec<Decoded>)>,
}

#[pymethods]
impl ViewIter {
    /// The iterator itself.
    fn __iter__(slf: PyRef<'_, Self>) -> PyRef<'_, Self> {
        slf
    }

    /// Views still to come: those decoded and not handed out, and those of the reads left.
    fn __len__(&self) -> usize {
        let state = self.reads.lock().unwrap_or_else(|p| p.into_inner());
        state.1.len() + state.0.iter().map(GroupRead::len).sum::<usize>()
    }

    /// The next view, decoded (a row group at a time, without the GIL).
    fn __next__<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyDict>>> {
        let (ds, pool) = (self.dataset.get().current(py)?, crate::pool()?);
        let next = py
            .detach(|| -> nrw_dataset::Result<Option<Decoded>> {
                let mut state = self.reads.lock().unwrap_or_else(|p| p.into_inner());
                if state.1.is_empty() {
                    let Some(read) = state.0.pop() else {
                        return Ok(None);
                    };
                    let mut decoded = decode_all(&pool, ds.read(&read)?)?;
                    decoded.reverse();
                    state.1 = decoded;
                }
                Ok(state.1.pop())
            })
            .map_err(py_err)?;
        next.map(|d| d.into_dict(py)).transpose()
    }
}

impl Dataset {
    /// Where the dataset is, as given.
    pub(crate) fn location_str(&self) -> &str {
        &self.location
    }
}
