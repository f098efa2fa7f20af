//! The file formats the layouts write, each with no knowledge of any layout: HDF5, TFRecord
//! framing, image pyramids and inverse-depth PNGs (NumPy's files are nrw-npy's).

pub mod hdf5;
pub mod inverse_depth;
pub mod pyramid;
pub mod record;
