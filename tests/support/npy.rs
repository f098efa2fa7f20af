//! NumPy .npy files (format 1.0, little-endian, C order), for benchmarks that hand data to a
//! Python peer (Open3D, faiss, PyTorch) and read its answer. Shared by `#[path]` from each
//! benchmark; each uses only some of these.
#![allow(dead_code)]

/// Write `data` (rows × cols, row-major) to `path`.
pub fn write_npy_f32(path: &std::path::Path, data: &[f32], cols: usize) {
    write_npy_shape_f32(path, data, &[data.len() / cols.max(1), cols]);
}

/// Write `data` with any C-order `shape` to `path`.
pub fn write_npy_shape_f32(path: &std::path::Path, data: &[f32], shape: &[usize]) {
    assert_eq!(
        shape.iter().product::<usize>(),
        data.len(),
        "shape and data"
    );
    let dims: String = shape.iter().map(|d| format!("{d}, ")).collect();
    let mut header = format!("{{'descr': '<f4', 'fortran_order': False, 'shape': ({dims}), }}");
    while (10 + header.len() + 1) % 64 != 0 {
        header.push(' ');
    }
    header.push('\n');
    let mut out = b"\x93NUMPY\x01\x00".to_vec();
    out.extend_from_slice(&(header.len() as u16).to_le_bytes());
    out.extend_from_slice(header.as_bytes());
    for v in data {
        out.extend_from_slice(&v.to_le_bytes());
    }
    std::fs::write(path, out).unwrap();
}

/// The 8-byte payload values of a .npy file a peer wrote (the dtype is the caller's to know).
fn payload8(path: &std::path::Path) -> Vec<[u8; 8]> {
    let b = std::fs::read(path).unwrap();
    let hl = u16::from_le_bytes([b[8], b[9]]) as usize;
    b[10 + hl..]
        .chunks_exact(8)
        .map(|c| c.try_into().unwrap())
        .collect()
}

/// Read an int64 array, flattened.
pub fn read_npy_i64(path: &std::path::Path) -> Vec<i64> {
    payload8(path).into_iter().map(i64::from_le_bytes).collect()
}

/// Read a float64 array, flattened.
pub fn read_npy_f64(path: &std::path::Path) -> Vec<f64> {
    payload8(path).into_iter().map(f64::from_le_bytes).collect()
}
