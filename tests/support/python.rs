//! Python oracles for tests (dev tooling only, never a runtime dependency): whether they
//! import here, with a skip that says so, refused under NRW_REQUIRE_PY_ORACLES=1 (CI).
//! Shared by `#[path]` from each test file that calls Python.
#![allow(dead_code)]

/// Whether `python3 -c deps` succeeds; when not, say the test skips (or fail under
/// NRW_REQUIRE_PY_ORACLES=1).
pub fn python_has(deps: &str) -> bool {
    let have = std::process::Command::new("python3")
        .args(["-c", deps])
        .status()
        .is_ok_and(|s| s.success());
    if !have {
        assert!(
            std::env::var("NRW_REQUIRE_PY_ORACLES").map_or(true, |v| v != "1"),
            "NRW_REQUIRE_PY_ORACLES=1 but `python3 -c '{deps}'` fails"
        );
        eprintln!("python oracles ({deps}) not installed: skipped (CI requires them)");
    }
    have
}
