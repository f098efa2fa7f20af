//! Where a dataset lives: a local folder or an object-store prefix (`s3://`, `gs://`, `az://`),
//! behind one small set of operations every read and write of a dataset goes through.
//!
//! Atomicity: locally a file is written under a temporary name and renamed; on object
//! storage an object PUT is atomic by itself (readers see the old object or the new one,
//! never half), and nothing is renamed. Either way the manifest is written last and readers
//! trust only what it lists. Credentials and endpoints come from the providers' standard
//! environment variables (for S3: `AWS_ACCESS_KEY_ID`, `AWS_SECRET_ACCESS_KEY`,
//! `AWS_DEFAULT_REGION`, `AWS_ENDPOINT_URL`, `AWS_ALLOW_HTTP`); they are never printed.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use bytes::Bytes;
use futures_util::TryStreamExt;
use object_store::{ObjectStore, ObjectStoreExt};

use crate::error::{DatasetError, Result};
use crate::location::Location;

mod chunks;
mod remote;

pub use crate::location::is_url;
pub use chunks::{Chunks, RemoteFile, RemoteRead};
pub use remote::UPLOAD_PART;
use remote::{build_remote, remote_err, runtime, upload_parts, Remote, Upload};

/// A dataset's location and the operations on its files (paths relative to the dataset).
#[derive(Clone)]
pub struct Store {
    inner: Arc<Inner>,
}

enum Inner {
    Local(PathBuf),
    Remote(Remote),
}

impl std::fmt::Debug for Store {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Store({})", self.root())
    }
}

impl From<&Path> for Store {
    fn from(p: &Path) -> Store {
        Store::local(p)
    }
}

impl From<PathBuf> for Store {
    fn from(p: PathBuf) -> Store {
        Store::local(p)
    }
}

impl From<&Store> for Store {
    fn from(s: &Store) -> Store {
        s.clone()
    }
}

impl From<&PathBuf> for Store {
    fn from(p: &PathBuf) -> Store {
        Store::local(p)
    }
}

impl Store {
    /// A dataset folder on the local file system.
    pub fn local(dir: impl Into<PathBuf>) -> Store {
        Store {
            inner: Arc::new(Inner::Local(dir.into())),
        }
    }

    /// A dataset at `location`: a local folder or an object-store prefix.
    pub fn open(location: &Location) -> Result<Store> {
        Store::open_with(location, &[])
    }

    /// [`Store::open`] with provider settings given here, over the environment's (keys as
    /// the variables' names in lower case, e.g. `aws_endpoint_url`).
    pub fn open_with(location: &Location, options: &[(String, String)]) -> Result<Store> {
        let url = match location {
            Location::Local(dir) => return Ok(Store::local(dir)),
            Location::Url(url) => url.clone(),
        };
        let (store, prefix) =
            build_remote(&url, options).map_err(|problem| DatasetError::Location {
                url: url.clone(),
                problem,
            })?;
        let rt = runtime(&url)?;
        Ok(Store {
            inner: Arc::new(Inner::Remote(Remote {
                url,
                store,
                prefix,
                rt,
            })),
        })
    }

    /// The folder `rel` of this store as a store of its own (same credentials, same
    /// connection): where a report or an export goes beside a dataset.
    pub fn sub(&self, rel: &str) -> Result<Store> {
        let rel = self.checked(rel, true)?;
        let inner = match &*self.inner {
            Inner::Local(d) => Inner::Local(d.join(rel)),
            Inner::Remote(r) => Inner::Remote(Remote {
                url: format!("{}/{rel}", r.url),
                store: r.store.clone(),
                prefix: Store::key(r, rel),
                rt: r.rt,
            }),
        };
        Ok(Store {
            inner: Arc::new(inner),
        })
    }

    /// Whether the dataset is on object storage.
    pub fn is_remote(&self) -> bool {
        matches!(*self.inner, Inner::Remote(_))
    }

    /// The local folder, when the dataset is local.
    pub fn local_dir(&self) -> Option<&Path> {
        match &*self.inner {
            Inner::Local(d) => Some(d),
            Inner::Remote(_) => None,
        }
    }

    /// The dataset's location (a folder or a URL).
    pub fn root(&self) -> Location {
        match &*self.inner {
            Inner::Local(d) => Location::Local(d.clone()),
            Inner::Remote(r) => Location::Url(r.url.clone()),
        }
    }

    /// Where the file `rel` is (a path or a URL), to name it in messages.
    pub fn name(&self, rel: &str) -> Location {
        self.root().join(rel)
    }

    /// `rel` after the one name check ([`nrw_colmap::names::check_name`]): every file the
    /// store reads, writes or deletes, locally or as an object key, stays inside the dataset,
    /// whatever a table or a caller names. `""` (the dataset itself) passes where a folder is
    /// meant.
    fn checked<'a>(&self, rel: &'a str, folder: bool) -> Result<&'a str> {
        let rel = if folder {
            rel.trim_end_matches('/')
        } else {
            rel
        };
        if folder && rel.is_empty() {
            return Ok(rel);
        }
        nrw_colmap::names::check_name(rel).map_err(|problem| DatasetError::Value {
            path: self.root(),
            record: "file".into(),
            field: "name".into(),
            problem: format!("{rel:?} {problem}"),
        })?;
        Ok(rel)
    }

    fn key(r: &Remote, rel: &str) -> object_store::path::Path {
        let mut k = r.prefix.clone();
        for part in rel.split('/').filter(|p| !p.is_empty()) {
            k = k.join(part);
        }
        k
    }

    /// A file's bytes.
    pub fn read(&self, rel: &str) -> Result<Bytes> {
        let rel = self.checked(rel, false)?;
        match &*self.inner {
            Inner::Local(d) => {
                let p = d.join(rel);
                std::fs::read(&p)
                    .map(Bytes::from)
                    .map_err(|e| DatasetError::io(p, e))
            }
            Inner::Remote(r) => {
                let key = Store::key(r, rel);
                r.rt.block_on(async { r.store.get(&key).await?.bytes().await })
                    .map_err(|e| remote_err(self.name(rel).to_string(), e))
            }
        }
    }

    /// A file's bytes, or `None` when it does not exist.
    pub fn read_opt(&self, rel: &str) -> Result<Option<Bytes>> {
        match self.read(rel) {
            Ok(b) => Ok(Some(b)),
            Err(DatasetError::Io { source, .. })
                if source.kind() == std::io::ErrorKind::NotFound =>
            {
                Ok(None)
            }
            Err(e) => Err(e),
        }
    }

    /// Write a file whole and atomically (a temporary name and a rename locally, one PUT
    /// on object storage).
    pub fn write(&self, rel: &str, bytes: Vec<u8>) -> Result<()> {
        let rel = self.checked(rel, false)?;
        match &*self.inner {
            Inner::Local(d) => crate::atomic::write_bytes_atomic(&d.join(rel), &bytes),
            Inner::Remote(r) => {
                let key = Store::key(r, rel);
                r.rt.block_on(r.store.put(&key, bytes.into()))
                    .map(|_| ())
                    .map_err(|e| remote_err(self.name(rel).to_string(), e))
            }
        }
    }

    /// Copy the local file `from` to `rel` whole: a rename-safe copy locally, one PUT on object
    /// storage, or a multipart upload of parts of [`UPLOAD_PART`] bytes for a larger file (so a
    /// file of any size travels in bounded memory).
    pub fn upload(&self, rel: &str, from: &Path) -> Result<()> {
        let rel = self.checked(rel, false)?;
        let size = std::fs::metadata(from)
            .map_err(|e| DatasetError::io(from, e))?
            .len();
        match &*self.inner {
            Inner::Local(d) => crate::atomic::copy_atomic(from, &d.join(rel)),
            Inner::Remote(_) if size <= UPLOAD_PART as u64 => {
                let bytes = std::fs::read(from).map_err(|e| DatasetError::io(from, e))?;
                self.write(rel, bytes)
            }
            Inner::Remote(r) => {
                let key = Store::key(r, rel);
                let name = self.name(rel).to_string();
                r.rt.block_on(upload_parts(r, &key, from))
                    .map_err(|e| match e {
                        Upload::Read(e) => DatasetError::io(from, e),
                        Upload::Store(e) => remote_err(name, e),
                    })
            }
        }
    }

    /// Whether a file exists.
    pub fn exists(&self, rel: &str) -> Result<bool> {
        let rel = self.checked(rel, false)?;
        match &*self.inner {
            Inner::Local(d) => Ok(d.join(rel).is_file()),
            Inner::Remote(r) => {
                let key = Store::key(r, rel);
                match r.rt.block_on(r.store.head(&key)) {
                    Ok(_) => Ok(true),
                    Err(object_store::Error::NotFound { .. }) => Ok(false),
                    Err(e) => Err(remote_err(self.name(rel).to_string(), e)),
                }
            }
        }
    }

    /// Files under a folder of the dataset (recursively), as dataset-relative paths, sorted;
    /// empty when the folder does not exist.
    pub fn list(&self, dir_rel: &str) -> Result<Vec<String>> {
        let dir_rel = self.checked(dir_rel, true)?;
        let mut out = match &*self.inner {
            Inner::Local(d) => {
                let mut out = Vec::new();
                let mut stack = vec![dir_rel.trim_end_matches('/').to_string()];
                while let Some(rel) = stack.pop() {
                    let Ok(entries) = std::fs::read_dir(d.join(&rel)) else {
                        continue;
                    };
                    for e in entries.flatten() {
                        let name = e.file_name().to_string_lossy().into_owned();
                        let child = if rel.is_empty() {
                            name
                        } else {
                            format!("{rel}/{name}")
                        };
                        if e.file_type().is_ok_and(|t| t.is_dir()) {
                            stack.push(child);
                        } else {
                            out.push(child);
                        }
                    }
                }
                out
            }
            Inner::Remote(r) => {
                let key = Store::key(r, dir_rel);
                let metas: Vec<object_store::ObjectMeta> =
                    r.rt.block_on(r.store.list(Some(&key)).try_collect())
                        .map_err(|e| remote_err(self.name(dir_rel).to_string(), e))?;
                let base = r.prefix.as_ref().len();
                metas
                    .into_iter()
                    .map(|m| {
                        let full = m.location.as_ref();
                        full[base..].trim_start_matches('/').to_string()
                    })
                    .collect()
            }
        };
        out.sort();
        Ok(out)
    }

    /// Remove a file (a missing one is not an error).
    pub fn delete(&self, rel: &str) -> Result<()> {
        let rel = self.checked(rel, false)?;
        match &*self.inner {
            Inner::Local(d) => match std::fs::remove_file(d.join(rel)) {
                Err(e) if e.kind() != std::io::ErrorKind::NotFound => {
                    Err(DatasetError::io(d.join(rel), e))
                }
                _ => Ok(()),
            },
            Inner::Remote(r) => {
                let key = Store::key(r, rel);
                match r.rt.block_on(r.store.delete(&key)) {
                    Ok(()) | Err(object_store::Error::NotFound { .. }) => Ok(()),
                    Err(e) => Err(remote_err(self.name(rel).to_string(), e)),
                }
            }
        }
    }

    /// Remove every file under a folder of the dataset (and, locally, the folder).
    pub fn delete_dir(&self, dir_rel: &str) -> Result<()> {
        let dir_rel = self.checked(dir_rel, true)?;
        if let Inner::Local(d) = &*self.inner {
            let p = d.join(dir_rel);
            return match std::fs::remove_dir_all(&p) {
                Err(e) if e.kind() != std::io::ErrorKind::NotFound => Err(DatasetError::io(p, e)),
                _ => Ok(()),
            };
        }
        for rel in self.list(dir_rel)? {
            self.delete(&rel)?;
        }
        Ok(())
    }

    /// Random access to a file for the Parquet reader: the file itself locally, ranged GETs
    /// on object storage (only the footer and the column chunks asked for travel).
    pub fn chunks(&self, rel: &str) -> Result<Chunks> {
        self.chunks_sized(rel, None)
    }

    /// [`Store::chunks`] of a file whose size is known (from the manifest): no HEAD request.
    pub fn chunks_sized(&self, rel: &str, size: Option<u64>) -> Result<Chunks> {
        let rel = self.checked(rel, false)?;
        match &*self.inner {
            Inner::Local(d) => {
                let p = d.join(rel);
                let f = std::fs::File::open(&p).map_err(|e| DatasetError::io(&p, e))?;
                Ok(Chunks::File(f))
            }
            Inner::Remote(r) => {
                let key = Store::key(r, rel);
                let size = match size {
                    Some(s) => s,
                    None => {
                        r.rt.block_on(r.store.head(&key))
                            .map_err(|e| remote_err(self.name(rel).to_string(), e))?
                            .size
                    }
                };
                Ok(Chunks::Remote(Arc::new(RemoteFile {
                    remote: r.clone(),
                    key,
                    size,
                    window: std::sync::Mutex::new(None),
                })))
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn urls_and_paths_are_told_apart() {
        assert!(is_url("s3://bucket/ds"));
        assert!(is_url("gs://b/x"));
        assert!(!is_url("/tmp/ds"));
        assert!(!is_url("file:///tmp/ds"));
        assert!(!is_url("relative/dir"));
        let s = Store::open(&Location::parse("file:///tmp/x")).unwrap();
        assert_eq!(s.local_dir(), Some(Path::new("/tmp/x")));
    }

    #[test]
    fn no_name_leaves_the_dataset_locally_or_as_an_object_key() {
        let d = tempfile::tempdir().unwrap();
        let inner = d.path().join("ds");
        let remote = Store::open(&Location::parse("s3://bucket/ds")).unwrap();
        for s in [Store::local(&inner), remote] {
            for bad in [
                "../x.json",
                "/etc/passwd",
                "a/../../x",
                "a\\..\\x",
                "a\0b",
                "",
            ] {
                let named = |e: DatasetError| {
                    let m = e.to_string();
                    assert!(
                        m.contains("field `name`") && m.contains("ds"),
                        "{bad:?}: {m}"
                    );
                };
                named(s.write(bad, b"x".to_vec()).unwrap_err());
                named(s.read(bad).unwrap_err());
                named(s.exists(bad).unwrap_err());
                named(s.delete(bad).unwrap_err());
                named(s.chunks(bad).err().unwrap());
                if !bad.is_empty() {
                    named(s.list(bad).unwrap_err());
                    named(s.delete_dir(bad).unwrap_err());
                }
            }
        }
        assert_eq!(
            std::fs::read_dir(d.path()).unwrap().count(),
            0,
            "nothing written"
        );
    }

    #[test]
    fn local_store_writes_lists_and_deletes() {
        let d = tempfile::tempdir().unwrap();
        let s = Store::local(d.path());
        s.write("a/b/c.json", b"1".to_vec()).unwrap();
        s.write("a/d.json", b"22".to_vec()).unwrap();
        assert_eq!(s.list("a").unwrap(), ["a/b/c.json", "a/d.json"]);
        assert_eq!(s.list("").unwrap(), ["a/b/c.json", "a/d.json"]);
        assert_eq!(s.read("a/d.json").unwrap().as_ref(), b"22");
        assert!(s.read_opt("nope").unwrap().is_none());
        assert!(s.exists("a/b/c.json").unwrap());
        s.delete("a/d.json").unwrap();
        s.delete("a/d.json").unwrap();
        s.delete_dir("a").unwrap();
        assert!(s.list("a").unwrap().is_empty());
    }
}
