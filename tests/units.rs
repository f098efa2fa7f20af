//! Work units (`--unit I/N`) and `finalize`: any number of units, in any order, killed and
//! rerun or running at once, give the bytes of one process.

use super::*;

const COMMON: [&str; 3] = ["--rows-per-shard", "2", "--quiet"];

/// A unit (or the whole stage without `shard`) of ingest on the small scene.
fn ingest_unit(scene: &Path, out: &Path, shard: Option<&str>, extra: &[&str]) -> Output {
    let mut args: Vec<&str> = COMMON.to_vec();
    if let Some(s) = shard {
        args.extend(["--unit", s]);
    }
    args.extend(extra);
    ingest_small(scene, out, &args)
}

fn assert_ok(o: &Output) {
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
}

fn assert_same(whole: &Path, other: &Path, what: &str) {
    assert_same_files(&files(whole), &files(other), what);
}

/// The command of an ingest unit of the small scene (spawned by the caller).
fn unit_command(scene: &Path, out: &Path, shard: &str) -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_nrw-etl"));
    c.args([
        "ingest",
        scene.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ])
    .args(["--min-dim", "96", "--min-photo-side", "100"])
    .args(COMMON)
    .args(["--unit", shard]);
    c
}

/// Start a unit that pauses after each shard, kill it (SIGKILL) once its first shard is
/// recorded, and check it died mid-way.
fn kill_mid_way(scene: &Path, out: &Path, shard: &str) {
    let mut child = unit_command(scene, out, shard)
        .args(["--pause-after-group-ms", "400"])
        .spawn()
        .unwrap();
    let records = out.join(".units/ingest");
    let t0 = std::time::Instant::now();
    while !std::fs::read_dir(&records)
        .map(|d| {
            d.flatten()
                .any(|e| e.file_name().to_string_lossy().starts_with("group-"))
        })
        .unwrap_or(false)
    {
        assert!(
            t0.elapsed().as_secs() < 120,
            "the unit never recorded a group"
        );
        assert!(
            child.try_wait().unwrap().is_none(),
            "the unit ended before it was killed"
        );
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    child.kill().unwrap(); // SIGKILL on Unix
    child.wait().unwrap();
    let (i, n) = shard.split_once('/').unwrap();
    assert!(
        !records.join(format!("unit-{i}-of-{n}.json")).exists(),
        "the unit was killed before it finished"
    );
}

#[test]
fn n_units_in_any_order_one_killed_and_rerun_equal_one_process() {
    let tmp = tempfile::tempdir().unwrap();
    let scene = tmp.path().join("scene");
    small_scene(&scene, 13); // 7 groups of 2
    let whole = tmp.path().join("whole");
    assert_ok(&ingest_unit(&scene, &whole, None, &[]));
    for n in [1usize, 2, 3, 7] {
        let out = tmp.path().join(format!("units-{n}"));
        // Shuffled: odd units first (descending), then even ones.
        let mut order: Vec<usize> = (0..n).rev().filter(|i| i % 2 == 1).collect();
        order.extend((0..n).filter(|i| i % 2 == 0));
        let killed = order[0];
        kill_mid_way(&scene, &out, &format!("{killed}/{n}"));
        for i in order {
            let o = ingest_unit(&scene, &out, Some(&format!("{i}/{n}")), &["--json"]);
            assert_ok(&o);
            let s: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
            if i == killed {
                assert!(s["resumed_groups"].as_u64().unwrap() >= 1, "{s}");
            }
            assert!(
                !out.join("manifest.json").exists(),
                "a unit never writes the manifest"
            );
        }
        let o = nrw(&["finalize", out.to_str().unwrap()]);
        assert_ok(&o);
        assert_same(&whole, &out, &format!("{n} units"));
    }
}

#[test]
fn two_units_at_once_in_one_folder_lose_nothing_and_auto_reads_slurm() {
    let tmp = tempfile::tempdir().unwrap();
    let scene = tmp.path().join("scene");
    small_scene(&scene, 13);
    let whole = tmp.path().join("whole");
    assert_ok(&ingest_unit(&scene, &whole, None, &[]));
    let out = tmp.path().join("together");
    let spawn = |task: &str| {
        unit_command(&scene, &out, "auto")
            .env("SLURM_ARRAY_TASK_ID", task)
            .env("SLURM_ARRAY_TASK_MIN", "1")
            .env("SLURM_ARRAY_TASK_COUNT", "2")
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap()
    };
    let (a, b) = (spawn("1"), spawn("2"));
    for c in [a, b] {
        assert_ok(&c.wait_with_output().unwrap());
    }
    let mut records: Vec<String> = std::fs::read_dir(out.join(".units/ingest"))
        .unwrap()
        .flatten()
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with("unit-"))
        .collect();
    records.sort();
    assert_eq!(records, ["unit-0-of-2.json", "unit-1-of-2.json"]);
    assert_ok(&nrw(&["finalize", out.to_str().unwrap()]));
    assert_same(&whole, &out, "two units at once");
}

#[test]
fn finalize_names_missing_units_and_other_parameters_and_is_idempotent() {
    let tmp = tempfile::tempdir().unwrap();
    let scene = tmp.path().join("scene");
    small_scene(&scene, 9);
    let whole = tmp.path().join("whole");
    assert_ok(&ingest_unit(&scene, &whole, None, &[]));
    let out = tmp.path().join("units");
    let ds = out.to_str().unwrap();

    let err = fails(&["finalize", ds]);
    assert!(err.contains("no unit has run here"), "{err}");
    for i in [0, 2] {
        assert_ok(&ingest_unit(&scene, &out, Some(&format!("{i}/3")), &[]));
    }
    let err = fails(&["finalize", ds]);
    assert!(err.contains("ingest unit 1/3 has not run"), "{err}");
    assert!(
        !out.join("manifest.json").exists(),
        "a refused finalize writes nothing"
    );

    assert_ok(&ingest_unit(&scene, &out, Some("1/3"), &["--radius", "2"]));
    let err = fails(&["finalize", ds]);
    assert!(
        err.contains("unit 1/3 ran with other parameters than units 0/3, 2/3")
            && err.contains("radius = 2.0 vs radius = 1.0"),
        "{err}"
    );
    let err = fails(&["finalize", ds]);
    assert!(
        err.contains("radius = 2.0"),
        "refusing twice changes nothing: {err}"
    );

    // The odd unit rerun with the others' settings replaces its own record and shards.
    assert_ok(&ingest_unit(&scene, &out, Some("1/3"), &[]));
    // A unit of another count (its groups are done already, so it only records itself).
    assert_ok(&ingest_unit(&scene, &out, Some("0/2"), &[]));
    let stray = out.join(".units/ingest/unit-0-of-2.json");
    let err = fails(&["finalize", ds]);
    assert!(
        err.contains("different unit counts") && err.contains("unit 0/2"),
        "{err}"
    );
    std::fs::remove_file(&stray).unwrap();

    let o = nrw(&["finalize", ds, "--json"]);
    assert_ok(&o);
    let s: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(s["ingest"]["units"], 3, "{s}");
    assert!(
        !out.join(".units").exists(),
        "finalize removes the records it merged"
    );
    assert_same(&whole, &out, "3 units, one rerun with the right radius");
    let before = files(&out);
    let o = nrw(&["finalize", ds]);
    assert_ok(&o);
    assert!(String::from_utf8_lossy(&o.stderr).contains("nothing to finalize"));
    assert!(before == files(&out), "a second finalize changes nothing");
}

#[test]
fn style_in_units_plus_finalize_equals_style_in_one_run() {
    let tmp = tempfile::tempdir().unwrap();
    let scene = tmp.path().join("scene");
    small_scene(&scene, 13);
    let one = tmp.path().join("one");
    assert_ok(&ingest_unit(&scene, &one, None, &[]));
    let split = |d: &Path| ok(&["split", d.to_str().unwrap(), "--val", "2"]);
    split(&one);
    let units = tmp.path().join("units");
    let copy = |from: &Path, to: &Path| {
        for (rel, bytes) in files(from) {
            let p = to.join(rel);
            std::fs::create_dir_all(p.parent().unwrap()).unwrap();
            std::fs::write(p, bytes).unwrap();
        }
    };
    copy(&one, &units);
    let style = |d: &Path, shard: Option<&str>| {
        let mut a = vec![
            "style",
            d.to_str().unwrap(),
            "--tier",
            "color-stats",
            "--photos-per-part",
            "3",
            "--quiet",
        ];
        if let Some(s) = shard {
            a.extend(["--unit", s]);
        }
        ok(&a);
    };
    style(&one, None);
    for i in [2, 0, 1] {
        style(&units, Some(&format!("{i}/3")));
    }
    assert_ok(&nrw(&["finalize", units.to_str().unwrap()]));
    assert_same(&one, &units, "style in 3 units");
    let m: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(one.join("manifest.json")).unwrap()).unwrap();
    let parts = m["tables"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|t| t["path"].as_str().unwrap().starts_with("descriptors/part-"))
        .count();
    assert!(
        parts >= 3,
        "descriptor parts are listed in the manifest ({parts})"
    );
}

#[test]
fn the_same_unit_twice_at_once_as_a_retry_racing_its_original_corrupts_nothing() {
    let tmp = tempfile::tempdir().unwrap();
    let scene = tmp.path().join("scene");
    small_scene(&scene, 13);
    let whole = tmp.path().join("whole");
    assert_ok(&ingest_unit(&scene, &whole, None, &[]));
    let out = tmp.path().join("raced");
    let spawn = |shard: &str| {
        unit_command(&scene, &out, shard)
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap()
    };
    let racers = [spawn("0/2"), spawn("0/2"), spawn("1/2"), spawn("1/2")];
    for c in racers {
        assert_ok(&c.wait_with_output().unwrap());
    }
    assert_ok(&nrw(&["finalize", out.to_str().unwrap()]));
    assert_same(&whole, &out, "units raced by their own retries");
}

#[test]
fn finalize_refuses_a_model_changed_since_the_units_read_it() {
    let tmp = tempfile::tempdir().unwrap();
    let scene = tmp.path().join("scene");
    small_scene(&scene, 4);
    let out = tmp.path().join("ds");
    assert_ok(&ingest_unit(&scene, &out, Some("0/1"), &[]));
    // One point's error changed and the model written again: other bytes, another SHA-256.
    let sparse = scene.join("sparse/0");
    let mut rec = nrw_colmap::read_model(&sparse, Some(nrw_colmap::Format::Binary)).unwrap();
    rec.points.values_mut().next().unwrap().error += 1.0;
    nrw_colmap::write_model(&rec, &sparse, nrw_colmap::Format::Binary).unwrap();
    let err = fails(&["finalize", out.to_str().unwrap()]);
    assert!(
        err.contains("points3D.bin changed since the ingest units read it"),
        "{err}"
    );
    assert!(
        !out.join("manifest.json").exists(),
        "a refused finalize writes no manifest"
    );
}
