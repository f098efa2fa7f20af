//! Every input a fuzz target ever crashed on (`fuzz/regressions/TARGET/`) run through the same
//! code as that target: each must now be an error, never a panic or a huge allocation. The
//! committed seeds (`fuzz/seeds/TARGET/`) must still read. This also keeps the targets' code
//! paths compiled and exercised by `cargo test`.

use std::path::{Path, PathBuf};

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

/// What the `shard` target does; Err when anything refuses the bytes.
fn shard(data: &[u8]) -> nrw_dataset::Result<usize> {
    let path = Path::new("fuzz.parquet");
    let bytes = bytes::Bytes::copy_from_slice(data);
    nrw_dataset::views::check_shard(path, bytes.clone())?;
    let views = nrw_dataset::reader::views_in(bytes, path)?;
    for v in &views {
        v.photo()?;
        v.color()?;
        v.depth()?;
        v.semantics()?;
        v.transient()?;
        v.labels()?;
    }
    Ok(views.len())
}

/// What the `payload` target does for a depth payload (the one that crashed).
fn depth(data: &[u8]) -> nrw_dataset::Result<()> {
    nrw_dataset::depth::decode_exr(data.get(1..).unwrap_or_default(), Path::new("fuzz.exr"))?;
    Ok(())
}

fn descriptors(data: &[u8]) -> nrw_dataset::Result<usize> {
    let path = Path::new("part.parquet");
    let bytes = bytes::Bytes::copy_from_slice(data);
    nrw_dataset::descriptors::check_part(path, bytes.clone())?;
    Ok(nrw_dataset::descriptors::part_in(bytes, path)?.1.len())
}

fn triplets(data: &[u8]) -> nrw_dataset::Result<usize> {
    let path = Path::new("triplets.parquet");
    Ok(nrw_dataset::triplets::triplets_in(bytes::Bytes::copy_from_slice(data), path)?.len())
}

#[test]
fn every_input_a_fuzz_target_crashed_on_is_now_an_error() {
    let mut n = 0;
    // An input that once asked for gigabytes must now be refused before the allocation
    // (with overcommit the allocation itself could succeed, so the error must say why).
    let refused_early = |p: &Path, e: String| {
        let oom = p.file_name().unwrap().to_string_lossy().starts_with("oom-");
        assert!(
            !oom || e.contains("damaged Parquet footer") || e.contains("limit"),
            "{}: {e}",
            p.display()
        );
    };
    for (p, b) in inputs("regressions", "shard") {
        refused_early(&p, shard(&b).unwrap_err().to_string());
        n += 1;
    }
    for (p, b) in inputs("regressions", "payload") {
        refused_early(&p, depth(&b).unwrap_err().to_string());
        n += 1;
    }
    for (p, b) in inputs("regressions", "descriptors") {
        assert!(descriptors(&b).is_err(), "{}", p.display());
        n += 1;
    }
    for (p, b) in inputs("regressions", "triplets") {
        assert!(triplets(&b).is_err(), "{}", p.display());
        n += 1;
    }
    assert!(
        n >= 4,
        "the regression inputs are in fuzz/regressions/ ({n} found)"
    );
}

#[test]
fn the_fuzz_seeds_read_whole() {
    for (p, b) in inputs("seeds", "shard") {
        assert_eq!(shard(&b).unwrap(), 2, "{}", p.display());
    }
    for (p, b) in inputs("seeds", "descriptors") {
        assert!(descriptors(&b).unwrap() > 0, "{}", p.display());
    }
    for (p, b) in inputs("seeds", "triplets") {
        assert!(triplets(&b).unwrap() > 0, "{}", p.display());
    }
    for (p, b) in inputs("seeds", "manifest") {
        // The seed is of this schema version: it parses.
        nrw_dataset::Manifest::parse(&b, p.clone()).unwrap();
    }
    for (p, b) in inputs("seeds", "photo") {
        let img = nrw_dataset::codec::decode_photo(&b, 1 << 24).unwrap();
        assert!(img.width() > 0, "{}", p.display());
    }
}
