//! NumPy's files, read and written without NumPy: the one crate every other reads and writes
//! them through. [`npz`] writes `.npy` and `.npz` (ZIP64 past 4 GiB), [`pickle`] writes the
//! pickles numpy loads (protocol 3 and 4), and [`read`] reads a pickled `.npy` (tensorflow-vgg's
//! `vgg16.npy`) by interpreting its opcodes into plain values, never calling anything.

pub mod npz;
pub mod pickle;
pub mod read;
