//! Where the tests find ../shared (real scenes, VGG16 weights, PyTorch fixtures). A clone
//! without it skips the tests that need it and says so; CI sets NRW_REQUIRE_SHARED=1, under
//! which a missing ../shared fails them instead. NRW_SHARED_DIR points elsewhere (a way to
//! try a clone without ../shared: `NRW_SHARED_DIR=/nowhere cargo test --workspace`).
//! Shared by `#[path]` from each test file; each uses only some of these.
#![allow(dead_code)]

use std::path::{Path, PathBuf};

/// The shared folder: $NRW_SHARED_DIR, or ../shared beside the repository.
pub fn shared_dir() -> PathBuf {
    std::env::var_os("NRW_SHARED_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared"))
}

/// `shared_dir()/rel` when it exists; otherwise None after saying the test skips (or a
/// failure under NRW_REQUIRE_SHARED=1).
pub fn shared(rel: &str) -> Option<PathBuf> {
    let p = shared_dir().join(rel);
    if p.exists() {
        return Some(p);
    }
    assert!(
        std::env::var("NRW_REQUIRE_SHARED").map_or(true, |v| v != "1"),
        "NRW_REQUIRE_SHARED=1 but {} is missing",
        p.display()
    );
    eprintln!(
        "skipped: {} is not there (no ../shared in this clone; CI requires it)",
        p.display()
    );
    None
}

/// `shared_dir()/rel` whether or not it exists: for tests that only name a file.
pub fn shared_path(rel: &str) -> PathBuf {
    shared_dir().join(rel)
}
