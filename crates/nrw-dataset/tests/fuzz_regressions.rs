//! Every input a fuzz target ever crashed on (`fuzz/regressions/TARGET/`) run through the
//! target's own code (`nrw_dataset::fuzz_entry`): each must now be an error, never a panic or a
//! huge allocation. The committed seeds (`fuzz/seeds/TARGET/`) must still read. So every
//! `cargo test` runs the targets' code on what matters most.

use std::path::{Path, PathBuf};

use nrw_dataset::fuzz_entry;

fn inputs(kind: &str, target: &str) -> Vec<(PathBuf, Vec<u8>)> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../fuzz")
        .join(kind)
        .join(target);
    let mut out: Vec<(PathBuf, Vec<u8>)> = std::fs::read_dir(&dir)
        .map(|d| {
            d.map(|e| {
                let p = e.unwrap().path();
                let bytes = std::fs::read(&p).unwrap();
                (p, bytes)
            })
            .collect()
        })
        .unwrap_or_default();
    out.sort();
    out
}

/// An input that once asked for gigabytes must now be refused before the allocation (with
/// overcommit the allocation itself could succeed, so the error must say why).
fn refused(p: &Path, e: String) {
    let oom = p.file_name().unwrap().to_string_lossy().starts_with("oom-");
    let early = [
        "damaged Parquet footer",
        "damaged Parquet page",
        "limit",
        "but the view is",
    ];
    assert!(
        !oom || early.iter().any(|m| e.contains(m)),
        "{}: {e}",
        p.display()
    );
}

#[test]
fn every_input_a_fuzz_target_crashed_on_is_now_an_error() {
    let mut n = 0;
    for (p, b) in inputs("regressions", "shard") {
        refused(&p, fuzz_entry::shard(&b).unwrap_err().to_string());
        n += 1;
    }
    // A payload's header is read and checked against the view's size before any pixel
    // buffer exists, so any error here comes before the allocation.
    for (p, b) in inputs("regressions", "payload") {
        assert!(fuzz_entry::payload(&b).is_err(), "{}", p.display());
        n += 1;
    }
    for (p, b) in inputs("regressions", "descriptors") {
        refused(&p, fuzz_entry::descriptors(&b).unwrap_err().to_string());
        n += 1;
    }
    for (p, b) in inputs("regressions", "triplets") {
        refused(&p, fuzz_entry::triplets(&b).unwrap_err().to_string());
        n += 1;
    }
    assert!(
        n >= 8,
        "the regression inputs are in fuzz/regressions/ ({n} found)"
    );
}

#[test]
fn the_fuzz_seeds_read_whole() {
    for (p, b) in inputs("seeds", "shard") {
        assert_eq!(fuzz_entry::shard(&b).unwrap(), 2, "{}", p.display());
    }
    for (p, b) in inputs("seeds", "payload") {
        fuzz_entry::payload(&b).unwrap_or_else(|e| panic!("{}: {e}", p.display()));
    }
    for (p, b) in inputs("seeds", "descriptors") {
        assert!(fuzz_entry::descriptors(&b).unwrap() > 0, "{}", p.display());
    }
    for (p, b) in inputs("seeds", "triplets") {
        assert!(fuzz_entry::triplets(&b).unwrap() > 0, "{}", p.display());
    }
    for (_, b) in inputs("seeds", "manifest") {
        fuzz_entry::manifest(&b).unwrap();
    }
    for (p, b) in inputs("seeds", "photo") {
        assert!(fuzz_entry::photo(&b).unwrap() > 0, "{}", p.display());
    }
}
