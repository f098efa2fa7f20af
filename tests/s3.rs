//! Datasets on object storage: every stage against a real S3-compatible server (moto, started
//! here on loopback) gives the bytes the same stages give on local disk; unreachable
//! endpoints, missing buckets and wrong credentials fail with the URL named and no secret
//! printed; a unit killed on S3 leaves nothing the manifest lists.

use super::*;

use std::io::{Read, Write};
use std::net::{TcpListener, TcpStream};

const SECRET: &str = "nrw-test-secret-do-not-print";

/// A moto S3 server on a free loopback port, stopped on drop.
pub(crate) struct Moto {
    child: std::process::Child,
    port: u16,
}

impl Drop for Moto {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

fn free_port() -> u16 {
    TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

/// Start moto_server (with `auth`, it checks access keys as AWS does); `None` (with a
/// message) when it is not installed, unless NRW_REQUIRE_S3=1 (CI) makes that a failure.
pub(crate) fn moto(auth: bool) -> Option<Moto> {
    let found = Command::new("moto_server")
        .arg("--help")
        .output()
        .is_ok_and(|o| o.status.success());
    if !found {
        assert!(
            std::env::var("NRW_REQUIRE_S3").is_err(),
            "moto_server is required (NRW_REQUIRE_S3 is set): pip install 'moto[server]'"
        );
        eprintln!(
            "skipped: moto_server not found (pip install 'moto[server]' to run the S3 tests)"
        );
        return None;
    }
    let port = free_port();
    let mut cmd = Command::new("moto_server");
    cmd.args(["-H", "127.0.0.1", "-p", &port.to_string()])
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null());
    if auth {
        cmd.env("INITIAL_NO_AUTH_ACTION_COUNT", "0");
    }
    let child = cmd.spawn().unwrap();
    let m = Moto { child, port };
    let t0 = std::time::Instant::now();
    while TcpStream::connect(("127.0.0.1", port)).is_err() {
        assert!(t0.elapsed().as_secs() < 60, "moto_server did not start");
        std::thread::sleep(std::time::Duration::from_millis(100));
    }
    Some(m)
}

impl Moto {
    fn endpoint(&self) -> String {
        format!("http://127.0.0.1:{}", self.port)
    }

    /// Create a bucket (moto accepts unsigned requests unless started with `auth`).
    pub(crate) fn bucket(&self, name: &str) {
        let mut s = TcpStream::connect(("127.0.0.1", self.port)).unwrap();
        write!(s, "PUT /{name} HTTP/1.1\r\nHost: 127.0.0.1:{}\r\nContent-Length: 0\r\nConnection: close\r\n\r\n", self.port).unwrap();
        let mut reply = String::new();
        s.read_to_string(&mut reply).unwrap();
        assert!(reply.starts_with("HTTP/1.1 200"), "{reply}");
    }

    /// The ETag of object `key` of `bucket` as boto3 (moto's own dependency, not our client)
    /// reads it: an upload of N parts has S3's multipart form `"HEX-N"`, one PUT plain `"HEX"`.
    pub(crate) fn etag(&self, bucket: &str, key: &str) -> String {
        let script = "import sys, boto3\n\
             s3 = boto3.client('s3', endpoint_url=sys.argv[1])\n\
             print(s3.head_object(Bucket=sys.argv[2], Key=sys.argv[3])['ETag'])";
        let o = Command::new("python3")
            .args(["-c", script, &self.endpoint(), bucket, key])
            .envs(self.env())
            .output()
            .expect("python3 runs");
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        String::from_utf8_lossy(&o.stdout).trim().to_string()
    }

    /// The variables a user sets for this endpoint.
    pub(crate) fn env(&self) -> Vec<(&'static str, String)> {
        vec![
            ("AWS_ACCESS_KEY_ID", "nrwtest".into()),
            ("AWS_SECRET_ACCESS_KEY", SECRET.into()),
            ("AWS_DEFAULT_REGION", "us-east-1".into()),
            ("AWS_ENDPOINT_URL", self.endpoint()),
            ("AWS_ALLOW_HTTP", "true".into()),
        ]
    }

    /// Every object under `url`, by path relative to it.
    pub(crate) fn files(&self, url: &str) -> std::collections::BTreeMap<PathBuf, Vec<u8>> {
        let opts: Vec<(String, String)> = self
            .env()
            .into_iter()
            .map(|(k, v)| (k.to_ascii_lowercase(), v))
            .collect();
        let store = nrw_dataset::Store::open_with(&url.into(), &opts).unwrap();
        store
            .list("")
            .unwrap()
            .into_iter()
            .filter(|rel| !rel.ends_with("timings.json"))
            .map(|rel| {
                let bytes = store.read(&rel).unwrap().to_vec();
                (PathBuf::from(rel), bytes)
            })
            .collect()
    }

    /// `nrw-etl ARGS` with this endpoint's variables.
    fn nrw(&self, args: &[&str]) -> Output {
        Command::new(env!("CARGO_BIN_EXE_nrw-etl"))
            .args(args)
            .envs(self.env())
            .output()
            .expect("binary runs")
    }
}

fn assert_ok(o: &Output) -> String {
    let err = String::from_utf8_lossy(&o.stderr).into_owned();
    assert!(o.status.success(), "{err}");
    assert!(!err.contains(SECRET), "a secret was printed: {err}");
    String::from_utf8_lossy(&o.stdout).into_owned()
}

fn assert_fails(o: &Output) -> String {
    let err = String::from_utf8_lossy(&o.stderr).into_owned();
    assert_eq!(o.status.code(), Some(1), "a clean error exit: {err}");
    assert!(!err.contains(SECRET), "a secret was printed: {err}");
    err
}

/// ingest → split → style → triplets → qa → export of `scene` into `ds` (a folder or a URL).
fn every_stage(m: &Moto, scene: &Path, ds: &str, export: &Path, ingest_extra: &[&str]) {
    let mut ingest = vec![
        "ingest",
        scene.to_str().unwrap(),
        "--out",
        ds,
        "--quiet",
        "--rows-per-shard",
        "3",
    ];
    ingest.extend(ingest_extra);
    assert_ok(&m.nrw(&ingest));
    assert_ok(&m.nrw(&["split", ds, "--val", "2"]));
    assert_ok(&m.nrw(&[
        "style",
        ds,
        "--tier",
        "color-stats",
        "--quiet",
        "--photos-per-part",
        "4",
    ]));
    assert_ok(&m.nrw(&["triplets", ds, "--k", "3"]));
    assert_ok(&m.nrw(&["qa", ds]));
    assert_ok(&m.nrw(&[
        "export",
        ds,
        "--out",
        export.to_str().unwrap(),
        "--name",
        "scene",
        "--quiet",
        "--no-semantics",
        "--crop",
        "none",
    ]));
}

/// Files of a local dataset or export, without what names its location (the QA report and
/// the export summary record where they were made; timings differ by nature).
fn comparable(
    files: std::collections::BTreeMap<PathBuf, Vec<u8>>,
) -> std::collections::BTreeMap<PathBuf, Vec<u8>> {
    files
        .into_iter()
        .filter(|(k, _)| {
            !k.starts_with("qa") && !k.ends_with("export.json") && !k.ends_with("timings.json")
        })
        .collect()
}

fn same_bytes_on_s3_as_on_disk(scene: &Path, ingest_extra: &[&str], what: &str) {
    let Some(m) = moto(false) else {
        return;
    };
    m.bucket("nrw");
    let tmp = tempfile::tempdir().unwrap();
    let local = tmp.path().join("local");
    every_stage(
        &m,
        scene,
        local.to_str().unwrap(),
        &tmp.path().join("export-local"),
        ingest_extra,
    );
    let url = "s3://nrw/datasets/scene";
    every_stage(&m, scene, url, &tmp.path().join("export-s3"), ingest_extra);
    assert!(assert_ok(&m.nrw(&["verify", url, "--quiet"])).starts_with("verified"));
    let (a, b) = (comparable(files(&local)), comparable(m.files(url)));
    assert_same_files(&a, &b, &format!("{what} on disk and on S3"));
    let remote = m.files(url);
    assert!(
        remote.contains_key(Path::new("qa/report.html")),
        "the report is uploaded next to the dataset"
    );
    let (ea, eb) = (
        comparable(files(&tmp.path().join("export-local"))),
        comparable(files(&tmp.path().join("export-s3"))),
    );
    assert!(!ea.is_empty() && ea == eb, "{what}: the exports differ");
}

#[test]
fn every_export_layout_on_s3_holds_the_bytes_of_the_local_export_and_replaces_an_earlier_one_whole()
{
    let Some(m) = moto(false) else {
        return;
    };
    m.bucket("nrw");
    let tmp = tempfile::tempdir().unwrap();
    let (ds, _) = crate::untrusted::exportable_dataset(tmp.path());
    let export = |layout: &str, out: &str| {
        let a = crate::untrusted::export_args(&ds, layout, out);
        m.nrw(&a.iter().map(String::as_str).collect::<Vec<_>>())
    };
    for layout in crate::untrusted::LAYOUTS {
        let local = tmp.path().join("local").join(layout);
        let url = format!("s3://nrw/exports/{layout}");
        assert_ok(&export(layout, local.to_str().unwrap()));
        assert_ok(&export(layout, &url));
        let (a, b) = (files(&local), m.files(&url));
        assert!(a.len() >= 3, "{layout}: {:?}", a.keys());
        assert_same_files(&a, &b, &format!("the {layout} export on disk and on S3"));
    }
    // A second export into the same prefix replaces the first whole: no file of it is left.
    let official = "s3://nrw/exports/official";
    assert_ok(&export("tfrecord", official));
    assert_same_files(
        &files(&tmp.path().join("local/tfrecord")),
        &m.files(official),
        "a tfrecord export over an official one on S3",
    );
    // A prefix that holds other files is not an export to replace.
    let opts: Vec<(String, String)> = m
        .env()
        .into_iter()
        .map(|(k, v)| (k.to_ascii_lowercase(), v))
        .collect();
    let other = nrw_dataset::Store::open_with(&"s3://nrw/papers".into(), &opts).unwrap();
    other.write("draft.tex", b"keep me".to_vec()).unwrap();
    let e = assert_fails(&export("files", "s3://nrw/papers"));
    assert!(
        e.contains("s3://nrw/papers") && e.contains("not an nrw-etl export"),
        "{e}"
    );
    assert_eq!(m.files("s3://nrw/papers").len(), 1, "nothing was written");
    // QA of a local dataset into a URL writes its report there, through the store.
    let r = assert_ok(&m.nrw(&["qa", ds.to_str().unwrap(), "--out", "s3://nrw/reports/ds"]));
    let report = m.files("s3://nrw/reports/ds");
    assert!(
        report.contains_key(Path::new("report.html")) && report.contains_key(Path::new("qa.json")),
        "{r}: {:?}",
        report.keys()
    );
}

#[test]
fn a_file_larger_than_one_part_uploads_in_parts_and_reads_back_whole() {
    let Some(m) = moto(false) else {
        return;
    };
    m.bucket("nrw");
    let tmp = tempfile::tempdir().unwrap();
    let local = tmp.path().join("big.bin");
    // 2.5 parts of distinct bytes, so a part out of order or missing cannot go unseen.
    let n = nrw_dataset::store::UPLOAD_PART * 5 / 2;
    let bytes: Vec<u8> = (0..n as u32)
        .map(|i| (i.wrapping_mul(2_654_435_761) >> 24) as u8)
        .collect();
    std::fs::write(&local, &bytes).unwrap();
    let opts: Vec<(String, String)> = m
        .env()
        .into_iter()
        .map(|(k, v)| (k.to_ascii_lowercase(), v))
        .collect();
    let store = nrw_dataset::Store::open_with(&"s3://nrw/big".into(), &opts).unwrap();
    store.upload("a/big.bin", &local).unwrap();
    assert_eq!(store.read("a/big.bin").unwrap().as_ref(), bytes.as_slice());
    // It travelled as three parts, not one PUT (which would also read back whole).
    let etag = m.etag("nrw", "big/a/big.bin");
    assert!(etag.ends_with("-3\""), "ETag {etag}: not a 3-part upload");
    // A file under one part goes as one PUT.
    let small = tmp.path().join("small.bin");
    std::fs::write(&small, &bytes[..1000]).unwrap();
    store.upload("a/small.bin", &small).unwrap();
    let etag = m.etag("nrw", "big/a/small.bin");
    assert!(
        !etag.contains('-'),
        "ETag {etag}: a small file went in parts"
    );
    assert_eq!(store.list("").unwrap(), ["a/big.bin", "a/small.bin"]);
}

#[test]
fn every_stage_on_s3_gives_the_bytes_of_local_disk_on_the_demo_scene() {
    let tmp = tempfile::tempdir().unwrap();
    let scene = tmp.path().join("scene");
    small_scene(&scene, 9);
    same_bytes_on_s3_as_on_disk(
        &scene,
        &["--min-dim", "96", "--min-photo-side", "100"],
        "synthetic scene",
    );
}

#[test]
fn every_stage_on_s3_gives_the_bytes_of_local_disk_on_a_real_scene() {
    let Some(_) = shared::shared("data") else {
        return;
    };
    same_bytes_on_s3_as_on_disk(
        &data().join("sceaux_castle"),
        &["--min-dim", "200"],
        "sceaux_castle",
    );
}

#[test]
fn bad_endpoints_buckets_and_credentials_name_the_url_and_keep_secrets() {
    let Some(m) = moto(false) else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    let scene = tmp.path().join("scene");
    small_scene(&scene, 3);
    let s = scene.to_str().unwrap();
    let ingest = |m: &Moto, url: &str, env: &[(&str, String)]| {
        Command::new(env!("CARGO_BIN_EXE_nrw-etl"))
            .args([
                "ingest",
                s,
                "--out",
                url,
                "--quiet",
                "--min-dim",
                "96",
                "--min-photo-side",
                "100",
            ])
            .envs(m.env())
            .envs(env.iter().map(|(k, v)| (*k, v.clone())))
            .output()
            .unwrap()
    };
    // The bucket exists before the failed attempts, so that "nothing was written" can be
    // checked after them (a listing of a bucket made afterwards would be empty anyway).
    m.bucket("nrw");
    // Nothing listens there.
    let dead = format!("http://127.0.0.1:{}", free_port());
    let t0 = std::time::Instant::now();
    let err = assert_fails(&ingest(&m, "s3://nrw/ds", &[("AWS_ENDPOINT_URL", dead)]));
    assert!(
        err.contains("s3://nrw/ds") && err.contains("cannot reach the endpoint"),
        "{err}"
    );
    assert!(
        t0.elapsed().as_secs() < 90,
        "an unreachable endpoint fails in bounded time"
    );
    // The bucket does not exist.
    let err = assert_fails(&ingest(&m, "s3://no-such-bucket/ds", &[]));
    assert!(
        err.contains("s3://no-such-bucket/ds") && err.contains("the bucket does not exist"),
        "{err}"
    );
    // A server that checks credentials, given wrong ones.
    let Some(auth) = moto(true) else {
        return;
    };
    let err = assert_fails(&ingest(&auth, "s3://nrw/ds", &[]));
    assert!(
        err.contains("s3://nrw/ds") && err.contains("access denied"),
        "{err}"
    );
    // A scene that fails once the dataset is open (a photo missing): the store was reached
    // with working credentials, and still nothing may be written.
    let photo = std::fs::read_dir(scene.join("images"))
        .unwrap()
        .flatten()
        .next()
        .unwrap()
        .path();
    std::fs::remove_file(photo).unwrap();
    let err = assert_fails(&ingest(&m, "s3://nrw/ds", &[]));
    assert!(err.contains("registered photos are missing"), "{err}");
    // Nothing was written by any of them: the bucket made first is empty, and the missing
    // bucket was not created (a second attempt finds it missing still).
    assert!(
        m.files("s3://nrw").is_empty(),
        "{:?}",
        m.files("s3://nrw").keys()
    );
    let err = assert_fails(&ingest(&m, "s3://no-such-bucket/ds", &[]));
    assert!(err.contains("the bucket does not exist"), "{err}");
}

#[test]
fn a_unit_killed_on_s3_leaves_nothing_the_manifest_lists_and_resumes() {
    let Some(m) = moto(false) else {
        return;
    };
    m.bucket("nrw");
    let tmp = tempfile::tempdir().unwrap();
    let scene = tmp.path().join("scene");
    small_scene(&scene, 9);
    let s = scene.to_str().unwrap();
    let url = "s3://nrw/units";
    let base = [
        "--quiet",
        "--min-dim",
        "96",
        "--min-photo-side",
        "100",
        "--rows-per-shard",
        "2",
    ];
    let mut child = Command::new(env!("CARGO_BIN_EXE_nrw-etl"))
        .args([
            "ingest",
            s,
            "--out",
            url,
            "--unit",
            "0/2",
            "--pause-after-group-ms",
            "1500",
        ])
        .args(base)
        .envs(m.env())
        .spawn()
        .unwrap();
    let t0 = std::time::Instant::now();
    while !m
        .files(url)
        .keys()
        .any(|k| k.to_string_lossy().contains("group-"))
    {
        assert!(
            t0.elapsed().as_secs() < 120,
            "the unit never recorded a group"
        );
        std::thread::sleep(std::time::Duration::from_millis(50));
    }
    // Killed mid-run: still running when the signal goes, ended by it, not finished.
    assert!(
        child.try_wait().unwrap().is_none(),
        "the unit ended before it was killed"
    );
    child.kill().unwrap();
    let status = child.wait().unwrap();
    assert_eq!(
        std::os::unix::process::ExitStatusExt::signal(&status),
        Some(9),
        "{status}"
    );
    let after_kill = m.files(url);
    assert!(
        !after_kill.contains_key(Path::new("manifest.json")),
        "a unit never writes the manifest"
    );
    let err = assert_fails(&m.nrw(&["finalize", url]));
    assert!(err.contains("none has finished"), "{err}");
    for shard in ["0/2", "1/2"] {
        let mut a = vec!["ingest", s, "--out", url, "--unit", shard];
        a.extend(base);
        assert_ok(&m.nrw(&a));
    }
    assert_ok(&m.nrw(&["finalize", url]));
    let local = tmp.path().join("local");
    let mut a = vec!["ingest", s, "--out", local.to_str().unwrap()];
    a.extend(base);
    assert_ok(&m.nrw(&a));
    assert_eq!(
        comparable(files(&local)),
        comparable(m.files(url)),
        "units on S3 equal one local process"
    );
}

#[test]
fn densify_on_s3_as_units_and_finalize_gives_the_bytes_of_a_local_run_and_a_stopped_unit_resumes() {
    let Some(m) = moto(false) else {
        return;
    };
    m.bucket("nrw");
    let tmp = tempfile::tempdir().unwrap();
    let scene = super::densify::textured_scene(tmp.path(), 4);
    let s = scene.to_str().unwrap();
    let local = tmp.path().join("local");
    let url = "s3://nrw/scene/dense";
    let args = |out: &str, extra: &[&str]| -> Vec<String> {
        ["densify", s, "-q", "--max-image-size", "96", "--out", out]
            .iter()
            .chain(extra)
            .map(|a| a.to_string())
            .collect()
    };
    let run = |out: &str, extra: &[&str]| m.nrw(&super::strs(&args(out, extra)));
    assert_ok(&run(local.to_str().unwrap(), &[]));

    // A geometric unit before the photometric pass: refused, naming the map on the bucket.
    let err = assert_fails(&run(url, &["--unit", "0/2", "--pass", "geometric"]));
    assert!(
        err.contains("s3://nrw/scene/.dense.partial/stereo/")
            && err.contains("is missing: the photometric pass has not finished view"),
        "{err}"
    );
    // Unit 0/2 of the photometric pass stops after one view (as a kill would), then resumes
    // from the maps it shared: the machine's scratch folder is gone with the process.
    super::densify::a_stopped_unit_resumes(&|extra| run(url, extra), &|| {
        let shared = m.files("s3://nrw/scene/.dense.partial");
        assert!(
            shared.contains_key(Path::new("densify.json"))
                && shared.keys().filter(|k| k.starts_with("stereo")).count() == 2,
            "the stopped unit shared its record and one view's two maps: {:?}",
            shared.keys().collect::<Vec<_>>()
        );
        assert!(
            m.files(url).is_empty(),
            "nothing is published before finalize"
        );
    });
    assert_ok(&run(url, &["--unit", "1/2", "--pass", "photometric"]));
    for unit in ["1/2", "0/2"] {
        assert_ok(&run(url, &["--unit", unit, "--pass", "geometric"]));
    }
    let err = String::from_utf8_lossy(&run(url, &["--finalize", "--fusion-cache-mb", "0"]).stderr)
        .into_owned();
    assert!(err.contains("densified 4 of 4 views"), "{err}");
    super::assert_same_files(
        &super::files(&local),
        &m.files(url),
        "densify on S3 (2 units, a stopped one resumed, finalize) vs one local process",
    );
    assert!(
        m.files("s3://nrw/scene/.dense.partial").is_empty(),
        "finalize removes the staging prefix"
    );
    // A published workspace is kept unless --overwrite; with it, a whole run replaces it.
    let err = assert_fails(&run(url, &[]));
    assert!(err.contains(url) && err.contains("--overwrite"), "{err}");
    assert_ok(&run(url, &["--overwrite"]));
    super::assert_same_files(&super::files(&local), &m.files(url), "a whole run on S3");
    // A bucket root leaves the units no place beside it.
    let err = assert_fails(&run("s3://nrw", &[]));
    assert!(err.contains("inside the bucket"), "{err}");
}
