//! COLMAP's dense-workspace files as COLMAP's own script reads and writes them: depth and
//! normal maps written by `nrw_colmap::dense` equal what `read_write_dense.py` reads, and
//! maps it writes read back to the same values (tests/oracles/colmap_dense.py follows the script).

use std::path::Path;

use nrw_colmap::dense::DenseMap;

use super::npy::write_npy_shape_f32;
use super::python_has;

/// A map whose every value names its pixel and channel, so any transposition shows.
fn numbered(width: usize, height: usize, channels: usize) -> DenseMap {
    let mut m = DenseMap::filled(width, height, channels, 0.0);
    for y in 0..height {
        for x in 0..width {
            for c in 0..channels {
                m.set(x, y, c, (10_000 * c + 100 * y + x) as f32 + 0.25);
            }
        }
    }
    m
}

/// The map as a NumPy `.npy` (float32, height × width [× channels], C order), as the
/// script's `read_array` returns it (one channel squeezed away).
fn npy(m: &DenseMap, path: &Path) {
    let shape: &[usize] = if m.channels == 1 {
        &[m.height, m.width]
    } else {
        &[m.height, m.width, m.channels]
    };
    write_npy_shape_f32(path, &m.data, shape);
}

/// COLMAP's scripts/python folder (NRW_COLMAP_SCRIPTS, set by .ci/run from Debian's colmap
/// source), or `None`: the transcription in tests/oracles/colmap_dense.py then stands in, said here,
/// and refused under NRW_REQUIRE_COLMAP=1.
fn colmap_scripts() -> Option<String> {
    let dir = std::env::var("NRW_COLMAP_SCRIPTS")
        .ok()
        .filter(|d| !d.is_empty());
    if dir.is_none() {
        assert!(
            std::env::var("NRW_REQUIRE_COLMAP").map_or(true, |v| v != "1"),
            "NRW_REQUIRE_COLMAP=1 but NRW_COLMAP_SCRIPTS (COLMAP's scripts/python) is not set"
        );
        eprintln!(
            "note: NRW_COLMAP_SCRIPTS is not set: tests/oracles/colmap_dense.py's transcription of \
             read_write_dense.py stands in for COLMAP's own"
        );
    }
    dir
}

/// Runs tests/oracles/colmap_dense.py; checks it ran COLMAP's own file when there is one.
fn script(scripts: &Option<String>, args: &[&Path]) -> std::process::Output {
    let out = std::process::Command::new("python3")
        .arg(Path::new(env!("CARGO_MANIFEST_DIR")).join("../../tests/oracles/colmap_dense.py"))
        .args(args)
        .output()
        .unwrap();
    let said = String::from_utf8_lossy(&out.stdout);
    if let Some(dir) = scripts {
        let want = Path::new(dir).join("read_write_dense.py");
        let want = std::fs::canonicalize(&want)
            .unwrap_or_else(|e| panic!("NRW_COLMAP_SCRIPTS: {}: {e}", want.display()));
        assert!(
            said.contains(&format!("reader: colmap {}", want.display())),
            "COLMAP's read_write_dense.py did not run: {said}"
        );
    }
    out
}

#[test]
fn depth_and_normal_maps_are_what_colmaps_script_reads_and_writes() {
    if !python_has("import numpy") {
        return;
    }
    let scripts = colmap_scripts();
    let tmp = tempfile::tempdir().unwrap();
    // A depth map and a normal map, not square, so width and height cannot be swapped.
    for (w, h, c) in [(5, 3, 1), (4, 7, 3)] {
        let m = numbered(w, h, c);
        let (bin, want) = (tmp.path().join("m.bin"), tmp.path().join("m.npy"));
        std::fs::write(&bin, m.to_bytes()).unwrap();
        npy(&m, &want);
        let read = script(&scripts, &[Path::new("read"), &bin, &want]);
        assert!(
            read.status.success(),
            "{w}×{h}×{c}: {}",
            String::from_utf8_lossy(&read.stderr)
        );
        let theirs = tmp.path().join("theirs.bin");
        let write = script(&scripts, &[Path::new("write"), &theirs, &want]);
        assert!(
            write.status.success(),
            "{}",
            String::from_utf8_lossy(&write.stderr)
        );
        let bytes = std::fs::read(&theirs).unwrap();
        assert_eq!(DenseMap::from_bytes(&bytes, &theirs).unwrap(), m);
        assert_eq!(
            bytes,
            m.to_bytes(),
            "{w}×{h}×{c}: the same bytes as COLMAP writes"
        );
    }
}
