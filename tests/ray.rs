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

/// Ingest settings for the small synthetic scenes (tiny photos and renders, two rows a shard).
const SMALL_INGEST: [&str; 6] = [
    "--min-dim",
    "96",
    "--min-photo-side",
    "100",
    "--rows-per-shard",
    "2",
];

/// Run the driver's test script into `out` (a folder or URL); returns its stdout.
fn driver(scene: &str, out: &str, args: &[&str], env: &[(&str, String)]) -> String {
    let fixed = [scene, out, env!("CARGO_BIN_EXE_nrw-etl")];
    python_script(
        "pipelines/ray/test_driver.py",
        &[&fixed[..], args].concat(),
        env,
    )
}

/// Run a Python script of the repository with Ray's usage reporting off; its stdout, after
/// asserting it succeeded.
fn python_script(script: &str, args: &[&str], env: &[(&str, String)]) -> String {
    let script = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../..")
        .join(script);
    let o = Command::new("python3")
        .arg(&script)
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
    let ingest = SMALL_INGEST;
    // One process.
    let one = tmp.path().join("one");
    one_process(s, &one, &ingest);
    // The driver on a two-node cluster, one node killed after the first shard.
    let ray = tmp.path().join("ray");
    let args = [&ingest[..], &["--pause-after-group-ms", "2000"]].concat();
    let stdout = driver(s, ray.to_str().unwrap(), &args, &[]);
    assert!(stdout.contains("node killed mid-run"), "{stdout}");
    // The task log showed a task cut off on the killed node, run again elsewhere, and no
    // failure of the binary behind a retry (pipelines/ray/test_driver.py check_task_log).
    assert!(stdout.contains("cut off on the killed node"), "{stdout}");
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
fn densify_as_ray_units_on_two_nodes_gives_the_workspace_of_one_process() {
    if !python_has("import ray") {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let scene = super::densify::textured_scene(tmp.path(), 4);
    let s = scene.to_str().unwrap();
    let one = tmp.path().join("one");
    let settings = ["--max-image-size", "96"];
    ok(&[
        &["densify", s, "-q", "--out", one.to_str().unwrap()][..],
        &settings,
    ]
    .concat());
    let fixed = [s, env!("CARGO_BIN_EXE_nrw-etl"), "3"];
    let stdout = python_script(
        "tests/oracles/ray_densify.py",
        &[&fixed[..], &settings].concat(),
        &[],
    );
    assert!(
        stdout.contains("densify, geometric pass: 3 units"),
        "{stdout}"
    );
    assert_same_files(
        &files(&one),
        &files(&scene.join("dense")),
        "one process vs densify's units on Ray",
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

#[test]
fn the_corpus_driver_called_from_another_driver_with_a_node_killed_indexes_every_scene() {
    // pip install -r pipelines/ray/requirements.txt (CI does).
    if !python_has("import ray") {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let ingest = SMALL_INGEST;
    let (a, b) = (
        tmp.path().join("scenes/alpha"),
        tmp.path().join("scenes/beta"),
    );
    small_scene(&a, 13);
    small_scene(&b, 9);
    // A broken scene: its camera has too few parameters.
    let broken = tmp.path().join("scenes/broken");
    std::fs::create_dir_all(broken.join("sparse/0")).unwrap();
    std::fs::write(
        broken.join("sparse/0/cameras.txt"),
        "1 PINHOLE 640 480 500\n",
    )
    .unwrap();
    std::fs::write(broken.join("sparse/0/images.txt"), "").unwrap();
    std::fs::write(broken.join("sparse/0/points3D.txt"), "").unwrap();
    let out = tmp.path().join("corpus");
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../tests/oracles/ray_corpus.py");
    let driver_py = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../pipelines/ray/driver.py");
    let args = [&ingest[..], &["--pause-after-group-ms", "2000"]].concat();
    let o = Command::new("python3")
        .arg(&script)
        .arg(&driver_py)
        .arg(&out)
        .arg(env!("CARGO_BIN_EXE_nrw-etl"))
        .args([&a, &broken, &b])
        .arg("--")
        .args(&args)
        .env("RAY_USAGE_STATS_ENABLED", "0")
        // Another driver in another folder: workers cannot import the driver module.
        .current_dir(tmp.path())
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&o.stdout).into_owned();
    assert!(
        o.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&o.stderr)
    );
    assert!(stdout.contains("node killed mid-run"), "{stdout}");
    assert!(stdout.contains("cut off on the killed node"), "{stdout}");
    for (scene, name) in [(&a, "alpha"), (&b, "beta")] {
        let one = tmp.path().join(format!("one-{name}"));
        one_process(scene.to_str().unwrap(), &one, &ingest);
        assert_same_files(
            &without_qa(files(&one)),
            &without_qa(files(&out.join(name))),
            &format!("one process vs the corpus driver, scene {name}"),
        );
    }
    let rows = nrw_dataset::corpus::read_corpus(&nrw_dataset::Store::from(out.as_path())).unwrap();
    let names: Vec<&str> = rows.iter().map(|r| r.name.as_str()).collect();
    assert_eq!(names, ["alpha", "broken", "beta"]);
    let status: Vec<&str> = rows.iter().map(|r| r.status.as_str()).collect();
    assert_eq!(status, ["ok", "failed", "ok"]);
    let err = rows[1].error.as_deref().unwrap();
    assert!(
        err.contains("cameras.txt"),
        "the error names the file: {err}"
    );
    assert_eq!(rows[1].kept, None);
    assert_eq!(rows[0].registered, Some(13));
    assert!(
        rows[0].kept.unwrap() > 0 && rows[2].report.as_deref().unwrap().ends_with("report.html")
    );
    if python_has("import pyarrow") {
        assert!(
            stdout.contains("pyarrow read 3 rows: ['ok', 'failed', 'ok']"),
            "{stdout}"
        );
    }
    if python_has("import duckdb") {
        assert!(stdout.contains("('broken', 'failed')"), "{stdout}");
    }
}
