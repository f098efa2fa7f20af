//! One view's payloads decoded into plain buffers (no Python object), so it runs with the GIL
//! released, and those buffers moved into NumPy arrays without a copy.

use nrw_dataset::ViewRow;
use numpy::ndarray::{Array2, Array3};
use numpy::IntoPyArray;
use pyo3::prelude::*;
use pyo3::types::PyDict;

/// A view with every payload decoded.
pub struct Decoded {
    image_id: u32,
    name: String,
    camera_id: u32,
    model: String,
    params: Vec<f64>,
    qvec: [f64; 4],
    tvec: [f64; 3],
    width: usize,
    height: usize,
    photo: Vec<u8>,
    color: Vec<u8>,
    depth: Vec<f32>,
    normals: Option<Vec<u8>>,
    semantics: Option<Vec<u8>>,
    labels: Option<Vec<u8>>,
    transient: Option<Vec<u8>>,
}

/// Decode every payload of a view (their CRCs were checked when the row was read).
pub fn decode(v: ViewRow) -> nrw_dataset::Result<Decoded> {
    Ok(Decoded {
        photo: v.photo()?.into_raw(),
        color: v.color()?.into_raw(),
        depth: v.depth()?.data,
        normals: v.normals()?.map(|n| n.into_raw()),
        semantics: v.semantics()?.map(|s| s.into_raw()),
        labels: v.labels()?.map(|l| l.into_raw()),
        transient: v.transient()?.map(|t| t.into_raw()),
        width: v.width as usize,
        height: v.height as usize,
        image_id: v.image_id,
        name: v.name,
        camera_id: v.camera_id,
        model: v.model,
        params: v.params,
        qvec: v.qvec,
        tvec: v.tvec,
    })
}

impl Decoded {
    /// The view as the dict `Dataset.views` yields (an `nrw._view.View`, where the old key
    /// `render` still reads `color`): arrays H × W × C (H × W for one channel).
    pub fn into_dict(self, py: Python<'_>) -> PyResult<Bound<'_, PyDict>> {
        let (h, w) = (self.height, self.width);
        let d = py
            .import("nrw._view")?
            .getattr("View")?
            .call0()?
            .cast_into::<PyDict>()?;
        let shape_err =
            |e: numpy::ndarray::ShapeError| crate::py_err(format!("{}: {e}", self.name));
        let hwc = |px: Vec<u8>, c: usize| Array3::from_shape_vec((h, w, c), px).map_err(shape_err);
        let hw = |px: Vec<u8>| Array2::from_shape_vec((h, w), px).map_err(shape_err);
        d.set_item("image_id", self.image_id)?;
        d.set_item("photo", hwc(self.photo, 3)?.into_pyarray(py))?;
        d.set_item("color", hwc(self.color, 4)?.into_pyarray(py))?;
        let depth = Array2::from_shape_vec((h, w), self.depth).map_err(shape_err)?;
        d.set_item("depth", depth.into_pyarray(py))?;
        if let Some(n) = self.normals {
            d.set_item("normals", hwc(n, 3)?.into_pyarray(py))?;
        }
        if let Some(s) = self.semantics {
            d.set_item("semantics", hwc(s, 3)?.into_pyarray(py))?;
        }
        if let Some(l) = self.labels {
            d.set_item("labels", hw(l)?.into_pyarray(py))?;
        }
        if let Some(t) = self.transient {
            d.set_item("transient", hw(t)?.into_pyarray(py))?;
        }
        d.set_item("camera_id", self.camera_id)?;
        d.set_item("model", self.model)?;
        d.set_item("params", self.params)?;
        d.set_item("qvec", self.qvec.to_vec())?;
        d.set_item("tvec", self.tvec.to_vec())?;
        d.set_item("name", self.name)?;
        Ok(d)
    }
}
