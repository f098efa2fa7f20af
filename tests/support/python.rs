//! Python oracles for tests (dev tooling only, never a runtime dependency): whether they
//! import here, with a skip that says so, refused under NRW_REQUIRE_PY_ORACLES=1 (CI).
//! Shared by `#[path]` from each test file that calls Python.
#![allow(dead_code)]

/// Whether `python3 -c deps` succeeds; when not, say the test skips (or fail under
/// NRW_REQUIRE_PY_ORACLES=1).
pub fn python_has(deps: &str) -> bool {
    python_runs(deps, "NRW_REQUIRE_PY_ORACLES", "python oracles")
}

/// Whether `python3 -c code` succeeds (run from the temporary folder, so a source folder
/// beside the tests cannot stand in for an installed package); when not, say that `what`
/// is missing and the test skips, or fail when the variable `require` is 1.
pub fn python_runs(code: &str, require: &str, what: &str) -> bool {
    let have = std::process::Command::new("python3")
        .args(["-c", code])
        .current_dir(std::env::temp_dir())
        .status()
        .is_ok_and(|s| s.success());
    if !have {
        assert!(
            std::env::var(require).map_or(true, |v| v != "1"),
            "{require}=1 but `python3 -c '{code}'` fails ({what})"
        );
        eprintln!("{what} ({code}) not installed: skipped (CI requires them)");
    }
    have
}
