//! The one check of image names (`nrw_colmap::names`): whatever bytes a model holds, a name
//! that passes joins to a path of normal components inside its folder, one per `/`-separated
//! part, and folding never panics.
#![no_main]
use std::path::{Component, Path};

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Ok(name) = std::str::from_utf8(data) else {
        return; // models are read as UTF-8 and refuse other bytes before this check
    };
    let root = Path::new("/scene/images");
    let _ = nrw_colmap::names::fold_key(name);
    let Ok(path) = nrw_colmap::names::join_checked(root, name) else {
        return;
    };
    let rel = path.strip_prefix(root).expect("inside the folder");
    assert!(
        rel.components().all(|c| matches!(c, Component::Normal(_))),
        "{name:?}"
    );
    assert_eq!(rel.components().count(), name.split('/').count(), "{name:?}");
    assert!(!name.chars().any(char::is_control) && !name.contains('\\'), "{name:?}");
});
