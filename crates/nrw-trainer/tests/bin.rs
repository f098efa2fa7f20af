//! The `nrw-train` binary fails clearly on bad input (training itself is tested end to end in
//! the `cli` test (tests/trainer.rs), where datasets are made).

use std::process::Command;

#[test]
fn nrw_train_names_a_missing_dataset_and_explains_itself() {
    let tmp = tempfile::tempdir().unwrap();
    let missing = tmp.path().join("nope");
    let o = Command::new(env!("CARGO_BIN_EXE_nrw-train"))
        .arg(&missing)
        .arg("--quiet")
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(1));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("nope") && err.contains("manifest.json"),
        "{err}"
    );
    let help = Command::new(env!("CARGO_BIN_EXE_nrw-train"))
        .arg("--help")
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&help.stdout);
    assert!(
        text.contains("--pos-k") && text.contains("triplet loss"),
        "{text}"
    );
}
