//! How runs that build one thing agree: the settings record of a folder built by several runs
//! (work units, a resumed run) — the first run writes what it builds with, every later run
//! reads it and goes on only if its own settings are the same, or is refused naming each
//! setting that differs (densify's `densify.json`, segment's record) — and the fingerprint a
//! dataset's work units record (`crate::units`), which finalize merges only when the units
//! agree on it. A folder built in hiding is then published whole by [`crate::publish`].

use std::collections::BTreeMap;

use serde::de::DeserializeOwned;
use serde::Serialize;

use crate::error::{DatasetError, Result};
use crate::store::Store;

/// What a folder's record says about a run's settings.
#[derive(Debug)]
pub enum Agreement<T> {
    /// No record yet: this run is the first.
    Fresh,
    /// The record holds these settings.
    Same(T),
    /// The record holds other settings: `differ` names each, `key = recorded (this run: …)`.
    Differs { found: T, differ: Vec<String> },
}

/// Read the record `rel` of `store` and compare it with `want` by `settings` (the part of a
/// record every run must share).
pub fn agree<T, S>(
    store: &Store,
    rel: &str,
    want: &S,
    settings: impl Fn(&T) -> &S,
) -> Result<Agreement<T>>
where
    T: DeserializeOwned,
    S: Serialize + PartialEq,
{
    let Some(bytes) = store.read_opt(rel)? else {
        return Ok(Agreement::Fresh);
    };
    let found: T = serde_json::from_slice(&bytes).map_err(|e| DatasetError::Json {
        path: store.name(rel),
        source: e,
    })?;
    if settings(&found) == want {
        return Ok(Agreement::Same(found));
    }
    let differ = differences(settings(&found), want);
    Ok(Agreement::Differs { found, differ })
}

/// SHA-256 (hex) of the inputs and parameters: what makes two runs' outputs interchangeable.
/// Work units record it, and finalize merges only units that agree on it.
pub fn fingerprint(
    inputs: &[crate::FileEntry],
    parameters: &serde_json::Map<String, serde_json::Value>,
) -> String {
    let mut text = serde_json::to_string(inputs).expect("json");
    text.push_str(&serde_json::to_string(parameters).expect("json"));
    crate::manifest::sha256_hex(text.as_bytes())
}

/// Write a record (pretty JSON: a person reads it when a run is refused).
pub fn write_record<T: Serialize>(store: &Store, rel: &str, record: &T) -> Result<()> {
    store.write(rel, record_bytes(record))
}

/// A record's bytes, the same wherever it is written.
pub fn record_bytes<T: Serialize>(record: &T) -> Vec<u8> {
    serde_json::to_string_pretty(record)
        .expect("a record serialises")
        .into_bytes()
}

/// Each leaf where `have` and `want` differ, as `key = have (this run: want)`.
pub fn differences<S: Serialize>(have: &S, want: &S) -> Vec<String> {
    let flat = |s: &S| {
        let mut out = BTreeMap::new();
        flatten(
            "",
            &serde_json::to_value(s).expect("settings serialise"),
            &mut out,
        );
        out
    };
    let (have, want) = (flat(have), flat(want));
    let null = serde_json::Value::Null;
    want.iter()
        .filter(|(k, v)| have.get(*k) != Some(*v))
        .map(|(k, v)| format!("{k} = {} (this run: {v})", have.get(k).unwrap_or(&null)))
        .collect()
}

/// A JSON object's leaves by dotted key.
fn flatten(prefix: &str, v: &serde_json::Value, out: &mut BTreeMap<String, serde_json::Value>) {
    match v {
        serde_json::Value::Object(m) => {
            for (k, v) in m {
                let key = if prefix.is_empty() {
                    k.clone()
                } else {
                    format!("{prefix}.{k}")
                };
                flatten(&key, v, out);
            }
        }
        _ => {
            out.insert(prefix.to_string(), v.clone());
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Debug, PartialEq, serde::Serialize, serde::Deserialize)]
    struct Settings {
        radius: u32,
        inner: Inner,
    }

    #[derive(Debug, PartialEq, serde::Serialize, serde::Deserialize)]
    struct Inner {
        mode: String,
    }

    #[test]
    fn the_first_run_records_and_a_later_one_is_refused_naming_each_difference() {
        let tmp = tempfile::tempdir().unwrap();
        let store = Store::local(tmp.path());
        let first = Settings {
            radius: 5,
            inner: Inner { mode: "a".into() },
        };
        let id = itself;
        assert!(matches!(
            agree(&store, "r.json", &first, id).unwrap(),
            Agreement::Fresh
        ));
        write_record(&store, "r.json", &first).unwrap();
        assert!(matches!(
            agree(&store, "r.json", &first, id).unwrap(),
            Agreement::Same(_)
        ));
        let other = Settings {
            radius: 3,
            inner: Inner { mode: "b".into() },
        };
        match agree(&store, "r.json", &other, id).unwrap() {
            Agreement::Differs { differ, .. } => assert_eq!(
                differ,
                vec![
                    "inner.mode = \"a\" (this run: \"b\")".to_string(),
                    "radius = 5 (this run: 3)".to_string()
                ]
            ),
            a => panic!("{a:?}"),
        }
        std::fs::write(tmp.path().join("r.json"), b"{").unwrap();
        let e = agree(&store, "r.json", &other, id).unwrap_err();
        assert!(e.to_string().contains("r.json"), "{e}");
    }

    fn itself(s: &Settings) -> &Settings {
        s
    }
}
