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

/// The Python with torch that `NRW_TORCH_PYTHON` names, if it imports `modules` (the
/// consumers' own code that needs torch); when not, say the test skips, or fail when
/// NRW_REQUIRE_TORCH=1 and `in_ci` (the consumers CI installs from PyPI).
pub fn torch_python(modules: &str, what: &str, in_ci: bool) -> Option<std::ffi::OsString> {
    let required = in_ci && std::env::var("NRW_REQUIRE_TORCH").is_ok_and(|v| v == "1");
    let py = std::env::var_os("NRW_TORCH_PYTHON");
    let imports = py.as_ref().is_some_and(|py| {
        std::process::Command::new(py)
            .args(["-c", &format!("import torch, {modules}")])
            .current_dir(std::env::temp_dir())
            .status()
            .is_ok_and(|s| s.success())
    });
    if !imports {
        assert!(
            !required,
            "NRW_REQUIRE_TORCH=1 but NRW_TORCH_PYTHON ({py:?}) does not import torch, {modules} ({what})"
        );
        eprintln!(
            "skipped: NRW_TORCH_PYTHON ({py:?}) is not a Python with torch and {modules} ({what}); \
             the transcribed checks stand in"
        );
        return None;
    }
    py
}
