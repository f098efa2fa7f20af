//! The Ray driver (pipelines/ray) on Ray's multi-node harness: four work units per stage
//! over two 1-CPU nodes, one node killed mid-run, give the bytes of one process; and on a
//! real scene with the dataset on S3 (moto), the bytes of one local process.

use super::*;

/// ingest → split → style (color-stats) → triplets in one process, as the driver's tests run it.
fn one_process(scene: &str, dir: &Path, ingest: &[&str]) {
    let d = dir.to_str().unwrap();
    ok(&[&["ingest", scene, "--out", d, "--quiet"][..], ingest].concat());
    ok(&["split", d, "--val", "2"]);
    ok(&["style", d, "--tier", "color-stats", "--quiet"]);
    ok(&["triplets", d, "--k", "3"]);
}

/// Run the driver's test script into `out` (a folder or URL); returns its stdout.
fn driver(scene: &str, out: &str, args: &[&str], env: &[(&str, String)]) -> String {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../pipelines/ray/test_driver.py");
    let o = Command::new("python3")
        .arg(&script)
        .args([scene, out, env!("CARGO_BIN_EXE_nrw-etl")])
        .args(args)
        .envs(env.iter().map(|(k, v)| (*k, v.clone())))
        .env("RAY_USAGE_STATS_ENABLED", "0")
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&o.stdout).into_owned();
    assert!(
        o.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&o.stderr)
    );
    stdout
}

/// A dataset's files without its QA report (it names where it was written).
fn without_qa(
    f: std::collections::BTreeMap<PathBuf, Vec<u8>>,
) -> std::collections::BTreeMap<PathBuf, Vec<u8>> {
    f.into_iter()
        .filter(|(k, _)| !k.starts_with("qa"))
        .collect()
}

#[test]
fn the_ray_driver_with_a_node_killed_gives_the_bytes_of_one_process() {
    // pip install -r pipelines/ray/requirements.txt (CI does).
    if !python_has("import ray") {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let scene = tmp.path().join("scene");
    small_scene(&scene, 13);
    let s = scene.to_str().unwrap();
    let ingest = [
        "--min-dim",
        "96",
        "--min-photo-side",
        "100",
        "--rows-per-shard",
        "2",
    ];
    // One process.
    let one = tmp.path().join("one");
    one_process(s, &one, &ingest);
    // The driver on a two-node cluster, one node killed after the first shard.
    let ray = tmp.path().join("ray");
    let args = [&ingest[..], &["--pause-after-shard-ms", "800"]].concat();
    let stdout = driver(s, ray.to_str().unwrap(), &args, &[]);
    assert!(stdout.contains("node killed mid-run"), "{stdout}");
    assert!(
        stdout.contains("report:"),
        "the driver says where the result is: {stdout}"
    );
    assert_same_files(
        &without_qa(files(&one)),
        &without_qa(files(&ray)),
        "one process vs the Ray driver",
    );
}

#[test]
fn the_ray_driver_on_a_real_scene_with_the_dataset_on_s3_gives_the_bytes_of_one_local_process() {
    let Some(_) = shared::shared("data") else {
        return;
    };
    if !python_has("import ray") {
        return;
    }
    let Some(m) = super::s3::moto(false) else {
        return;
    };
    m.bucket("nrw");
    let tmp = tempfile::tempdir().unwrap();
    let scene = data().join("sceaux_castle");
    let s = scene.to_str().unwrap();
    let ingest = ["--min-dim", "200", "--rows-per-shard", "3"];
    let one = tmp.path().join("one");
    one_process(s, &one, &ingest);
    let url = "s3://nrw/sceaux";
    let stdout = driver(s, url, &ingest, &m.env());
    assert!(stdout.contains(&format!("dataset: {url}")), "{stdout}");
    assert_same_files(
        &without_qa(files(&one)),
        &without_qa(m.files(url)),
        "one local process vs Ray on S3",
    );
}
