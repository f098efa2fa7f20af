//! What reading a `.npy` gives: float32 arrays, or why not. Its own file so the pickle
//! interpreter and the framing both use it without importing each other.

/// A float32 array read from the file: its shape and its values.
#[derive(Debug, Clone, PartialEq)]
pub struct F32Array {
    pub shape: Vec<usize>,
    pub data: Vec<f32>,
}

/// Why a `.npy` weights file could not be read (the caller adds the path).
pub type NpyError = String;
