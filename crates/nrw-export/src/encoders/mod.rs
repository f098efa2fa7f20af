//! The file formats the layouts write, each with no knowledge of any layout: HDF5, NumPy
//! `.npz` and pickles, TFRecord framing, image pyramids and inverse-depth PNGs.

pub mod hdf5;
pub mod inverse_depth;
pub mod npz;
pub mod pickle;
pub mod pyramid;
pub mod record;
