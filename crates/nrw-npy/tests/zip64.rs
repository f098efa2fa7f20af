//! The `.npz` writer's ZIP64 records, read by their consumers: Python's `zipfile` (CRC check,
//! sizes, offsets) and `np.load` (every array back), and Info-ZIP's `unzip -t` and `zipinfo`
//! where they are installed (zipinfo follows the ZIP64 locator, which zipfile does not read). A real archive past 4 GiB is too big for
//! a test, so the records are forced from a lower threshold: everything, and a mid-archive
//! threshold where later members overflow only their offset and one member its size.

#[path = "../../../tests/support/python.rs"]
mod python;

use std::io::Cursor;

use nrw_npy::npz::{Array, NpzWriter};

/// The ZIP64 end-of-central-directory record's signature.
const ZIP64_END: [u8; 4] = 0x0606_4b50u32.to_le_bytes();

/// An archive of three members (the last streamed in pieces) with ZIP64 records from `limit`.
fn archive(limit: Option<u64>) -> Vec<u8> {
    let mut z = NpzWriter::new(Cursor::new(Vec::new()));
    if let Some(limit) = limit {
        z = z.zip64_from(limit);
    }
    let m: Vec<f64> = (0..6).map(|i| i as f64 * 0.5 - 1.0).collect();
    z.member("m", &Array::f64(&[3, 2], &m).npy()).unwrap();
    z.member("names", &Array::unicode(&["a".into(), "béta".into()]).npy())
        .unwrap();
    let big = Array::i64(&(0..1000).collect::<Vec<i64>>()).npy();
    z.streamed("big", big.len() as u64, |put| {
        big.chunks(333).try_for_each(put)
    })
    .unwrap();
    z.finish().unwrap().into_inner()
}

/// Python's reading of the archive at `path`: zipfile's CRC check, each member's size and
/// header offset, and numpy's arrays, as JSON.
fn python_reads(path: &std::path::Path) -> serde_json::Value {
    let code = r#"
import json, sys, zipfile
import numpy as np
p = sys.argv[1]
z = zipfile.ZipFile(p)
d = np.load(p)
print(json.dumps({
    "bad": z.testzip(),
    "members": [[i.filename, i.file_size, i.header_offset] for i in z.infolist()],
    "m": d["m"].tolist(), "names": d["names"].tolist(), "big": d["big"].tolist(),
}))
"#;
    let out = std::process::Command::new("python3")
        .args(["-c", code])
        .arg(path)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).unwrap()
}

/// Info-ZIP's reading of the archive: `unzip -t` (every CRC) passes and `zipinfo -v` (which
/// follows the ZIP64 locator) reports no error; None where Info-ZIP is not installed.
fn info_zip_reads(path: &std::path::Path) -> Option<Result<(), String>> {
    let test = std::process::Command::new("unzip")
        .arg("-tq")
        .arg(path)
        .output()
        .ok()?;
    let info = std::process::Command::new("zipinfo")
        .arg("-v")
        .arg(path)
        .output()
        .ok()?;
    let said =
        String::from_utf8_lossy(&info.stdout).to_string() + &String::from_utf8_lossy(&info.stderr);
    if !test.status.success() {
        return Some(Err(String::from_utf8_lossy(&test.stdout).into()));
    }
    match said.lines().find(|l| l.contains("error")) {
        Some(line) => Some(Err(line.into())),
        None => Some(Ok(())),
    }
}

/// Where each local header starts, found by walking the archive's own headers.
fn local_offsets(bytes: &[u8]) -> Vec<u64> {
    let (mut at, mut offsets) = (0usize, Vec::new());
    while bytes[at..at + 4] == 0x0403_4b50u32.to_le_bytes() {
        offsets.push(at as u64);
        let u16_at = |i: usize| u16::from_le_bytes([bytes[at + i], bytes[at + i + 1]]) as usize;
        let size = u32::from_le_bytes(bytes[at + 18..at + 22].try_into().unwrap());
        let (name, extra) = (u16_at(26), u16_at(28));
        let len = if size == u32::MAX {
            let e = at + 30 + name + 4;
            u64::from_le_bytes(bytes[e..e + 8].try_into().unwrap()) as usize
        } else {
            size as usize
        };
        at += 30 + name + extra + len;
    }
    offsets
}

#[test]
fn python_and_info_zip_read_the_zip64_records() {
    if !python::python_has("import numpy, zipfile") {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let plain = archive(None);
    assert!(
        !plain.windows(4).any(|w| w == ZIP64_END),
        "no ZIP64 record below 4 GiB"
    );
    let mut want = None;
    for (label, limit) in [("plain", None), ("all", Some(0)), ("mid", Some(200))] {
        let bytes = archive(limit);
        if limit.is_some() {
            assert!(bytes.windows(4).any(|w| w == ZIP64_END), "{label}");
        }
        let path = tmp.path().join(format!("{label}.npz"));
        std::fs::write(&path, &bytes).unwrap();
        let got = python_reads(&path);
        assert_eq!(
            got["bad"],
            serde_json::Value::Null,
            "{label}: a CRC differs"
        );
        let offsets: Vec<u64> = got["members"]
            .as_array()
            .unwrap()
            .iter()
            .map(|m| m[2].as_u64().unwrap())
            .collect();
        assert_eq!(offsets, local_offsets(&bytes), "{label}: {got}");
        assert_eq!(got["big"][999], 999, "{label}");
        match info_zip_reads(&path) {
            Some(read) => assert_eq!(read, Ok(()), "{label}: Info-ZIP"),
            None => {
                assert!(
                    std::env::var("NRW_REQUIRE_INFO_ZIP").map_or(true, |v| v != "1"),
                    "NRW_REQUIRE_INFO_ZIP=1 but unzip or zipinfo is not installed"
                );
                eprintln!("Info-ZIP (unzip, zipinfo) not installed: its reading skipped");
            }
        }
        assert_eq!(got["names"], serde_json::json!(["a", "béta"]), "{label}");
        let arrays = (got["m"].clone(), got["names"].clone(), got["big"].clone());
        match &want {
            None => want = Some(arrays),
            Some(w) => assert_eq!(&arrays, w, "{label}: arrays differ from the plain archive"),
        }
    }
}
