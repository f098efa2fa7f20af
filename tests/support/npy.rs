//! A row-major f32 matrix as a NumPy .npy file (format 1.0), for benchmarks that hand data
//! to a Python peer (Open3D, faiss). Shared by `#[path]` from each benchmark.

/// Write `data` (rows × cols, row-major) to `path`.
pub fn write_npy_f32(path: &std::path::Path, data: &[f32], cols: usize) {
    let rows = data.len() / cols.max(1);
    let mut header =
        format!("{{'descr': '<f4', 'fortran_order': False, 'shape': ({rows}, {cols}), }}");
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
