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
use std::time::Duration;

use bytes::Bytes;
use futures_util::TryStreamExt;
use object_store::{ObjectStore, ObjectStoreExt};

use crate::error::{DatasetError, Result};

/// A dataset's location and the operations on its files (paths relative to the dataset).
#[derive(Clone)]
pub struct Store {
    inner: Arc<Inner>,
}

enum Inner {
    Local(PathBuf),
    Remote(Remote),
}

struct Remote {
    /// The URL as given, without a trailing slash (names files in messages).
    url: String,
    store: Arc<dyn ObjectStore>,
    prefix: object_store::path::Path,
    rt: &'static tokio::runtime::Runtime,
}

/// The one async runtime of the process, shared by every object-store location it opens
/// (made on the first open; a process that stays local never starts it).
fn runtime(url: &str) -> Result<&'static tokio::runtime::Runtime> {
    static RT: std::sync::OnceLock<tokio::runtime::Runtime> = std::sync::OnceLock::new();
    if let Some(rt) = RT.get() {
        return Ok(rt);
    }
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .map_err(|e| DatasetError::io(url, e))?;
    // Two threads racing here each build one; the loser's is dropped unused.
    Ok(RT.get_or_init(|| rt))
}

impl std::fmt::Debug for Store {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Store({})", self.root().display())
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

/// Whether a location names an object store (`scheme://…` other than `file://`).
pub fn is_url(location: &str) -> bool {
    location.split_once("://").is_some_and(|(s, _)| {
        !s.is_empty() && s != "file" && s.chars().all(|c| c.is_ascii_alphanumeric())
    })
}

/// Environment variables object_store's builders read (never printed).
fn provider_env() -> Vec<(String, String)> {
    std::env::vars()
        .filter(|(k, _)| {
            ["AWS_", "GOOGLE_", "AZURE_"]
                .iter()
                .any(|p| k.starts_with(p))
        })
        .map(|(k, v)| (k.to_ascii_lowercase(), v))
        .collect()
}

/// Retries of one request: a few, over at most half a minute, so an unreachable endpoint
/// fails in seconds rather than the providers' minutes.
fn retry() -> object_store::RetryConfig {
    object_store::RetryConfig {
        max_retries: 2,
        retry_timeout: Duration::from_secs(30),
        backoff: object_store::BackoffConfig::default(),
    }
}

fn client_options() -> object_store::ClientOptions {
    object_store::ClientOptions::new()
        .with_connect_timeout(Duration::from_secs(5))
        .with_timeout(Duration::from_secs(120))
}

fn build_remote(
    url: &str,
    extra: &[(String, String)],
) -> std::result::Result<(Arc<dyn ObjectStore>, object_store::path::Path), String> {
    let parsed = url::Url::parse(url).map_err(|e| e.to_string())?;
    let (scheme, path) =
        object_store::ObjectStoreScheme::parse(&parsed).map_err(|e| e.to_string())?;
    let prefix = object_store::path::Path::parse(path).map_err(|e| e.to_string())?;
    let mut env = provider_env();
    env.extend(extra.iter().cloned());
    macro_rules! with_env {
        ($b:expr) => {
            env.iter().fold($b, |b, (k, v)| match k.parse() {
                Ok(key) => b.with_config(key, v.clone()),
                Err(_) => b,
            })
        };
    }
    // One builder per provider, each with our client options and retries, then the
    // environment's settings, then the URL.
    macro_rules! build {
        ($builder:expr) => {
            Arc::new(
                with_env!($builder
                    .with_client_options(client_options())
                    .with_retry(retry()))
                .with_url(url)
                .build()
                .map_err(|e| e.to_string())?,
            )
        };
    }
    let store: Arc<dyn ObjectStore> = match scheme {
        object_store::ObjectStoreScheme::AmazonS3 => {
            build!(object_store::aws::AmazonS3Builder::new())
        }
        object_store::ObjectStoreScheme::GoogleCloudStorage => {
            build!(object_store::gcp::GoogleCloudStorageBuilder::new())
        }
        object_store::ObjectStoreScheme::MicrosoftAzure => {
            build!(object_store::azure::MicrosoftAzureBuilder::new())
        }
        other => {
            return Err(format!(
                "{other:?} URLs are not supported (s3://, gs://, az:// are)"
            ))
        }
    };
    Ok((store, prefix))
}

/// Part size of a multipart upload: above it a file travels in parts of this size.
pub const UPLOAD_PART: usize = 16 << 20;

/// Why an upload stopped: reading the local file, or the object store.
enum Upload {
    Read(std::io::Error),
    Store(object_store::Error),
}

/// `from` to `key` in parts of [`UPLOAD_PART`] bytes, at most two in flight; aborted (no
/// object left) on any error.
async fn upload_parts(
    r: &Remote,
    key: &object_store::path::Path,
    from: &Path,
) -> std::result::Result<(), Upload> {
    use std::io::Read;
    let mut file = std::fs::File::open(from).map_err(Upload::Read)?;
    let upload = r.store.put_multipart(key).await.map_err(Upload::Store)?;
    let mut w = object_store::WriteMultipart::new_with_chunk_size(upload, UPLOAD_PART);
    let mut buf = vec![0u8; UPLOAD_PART];
    loop {
        let n = match file.read(&mut buf) {
            Ok(n) => n,
            Err(e) => {
                let _ = w.abort().await;
                return Err(Upload::Read(e));
            }
        };
        if n == 0 {
            break;
        }
        if let Err(e) = w.wait_for_capacity(2).await {
            let _ = w.abort().await;
            return Err(Upload::Store(e));
        }
        w.write(&buf[..n]);
    }
    w.finish().await.map(|_| ()).map_err(Upload::Store)
}

/// An object-store error as a dataset error naming the object's URL (object_store's
/// messages carry no credentials).
fn remote_err(url: String, e: object_store::Error) -> DatasetError {
    let kind = match &e {
        object_store::Error::NotFound { .. } => std::io::ErrorKind::NotFound,
        object_store::Error::AlreadyExists { .. } => std::io::ErrorKind::AlreadyExists,
        _ => std::io::ErrorKind::Other,
    };
    let text = e.to_string();
    let message = match hint(&text) {
        Some(h) => format!("{h} ({text})"),
        None => text,
    };
    DatasetError::Io {
        path: url.into(),
        source: std::io::Error::new(kind, message),
    }
}

/// What a provider's error means for the user, from its code or the client's failure.
fn hint(text: &str) -> Option<&'static str> {
    let has = |s: &str| text.contains(s);
    if has("NoSuchBucket") {
        Some("the bucket does not exist")
    } else if has("InvalidAccessKeyId")
        || has("SignatureDoesNotMatch")
        || has("AccessDenied")
        || has("403 Forbidden")
    {
        Some("access denied: check the credentials (AWS_ACCESS_KEY_ID, AWS_SECRET_ACCESS_KEY or the provider's equivalents)")
    } else if has("error sending request") || has("Connection refused") {
        Some("cannot reach the endpoint (AWS_ENDPOINT_URL, or the provider's default)")
    } else {
        None
    }
}

impl Store {
    /// A dataset folder on the local file system.
    pub fn local(dir: impl Into<PathBuf>) -> Store {
        Store {
            inner: Arc::new(Inner::Local(dir.into())),
        }
    }

    /// A dataset at `location`: an `s3://`, `gs://` or `az://` URL, or a local path.
    pub fn open(location: &str) -> Result<Store> {
        Store::open_with(location, &[])
    }

    /// [`Store::open`] with provider settings given here, over the environment's (keys as
    /// the variables' names in lower case, e.g. `aws_endpoint_url`).
    pub fn open_with(location: &str, options: &[(String, String)]) -> Result<Store> {
        if !is_url(location) {
            return Ok(Store::local(
                location.strip_prefix("file://").unwrap_or(location),
            ));
        }
        let url = location.trim_end_matches('/').to_string();
        let (store, prefix) =
            build_remote(&url, options).map_err(|problem| DatasetError::Schema {
                path: url.clone().into(),
                problem: format!("cannot open this object-store location: {problem}"),
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

    /// [`Store::open`] of a path argument (a URL passes through a `PathBuf` unchanged).
    pub fn open_path(location: &Path) -> Result<Store> {
        Store::open(&location.to_string_lossy())
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

    /// The dataset's location, to show (a folder or a URL).
    pub fn root(&self) -> PathBuf {
        match &*self.inner {
            Inner::Local(d) => d.clone(),
            Inner::Remote(r) => PathBuf::from(&r.url),
        }
    }

    /// A file's full name, to show in messages (a path or a URL).
    pub fn name(&self, rel: &str) -> PathBuf {
        match &*self.inner {
            Inner::Local(d) => d.join(rel),
            Inner::Remote(r) => PathBuf::from(format!("{}/{rel}", r.url)),
        }
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
                    .map_err(|e| remote_err(self.name(rel).display().to_string(), e))
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
                    .map_err(|e| remote_err(self.name(rel).display().to_string(), e))
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
                let name = self.name(rel).display().to_string();
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
                    Err(e) => Err(remote_err(self.name(rel).display().to_string(), e)),
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
                        .map_err(|e| remote_err(self.name(dir_rel).display().to_string(), e))?;
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
                    Err(e) => Err(remote_err(self.name(rel).display().to_string(), e)),
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
                            .map_err(|e| remote_err(self.name(rel).display().to_string(), e))?
                            .size
                    }
                };
                Ok(Chunks::Remote(Arc::new(RemoteFile {
                    store: self.clone(),
                    key,
                    size,
                    window: std::sync::Mutex::new(None),
                })))
            }
        }
    }

    fn get_range(
        &self,
        key: &object_store::path::Path,
        range: std::ops::Range<u64>,
    ) -> std::io::Result<Bytes> {
        match &*self.inner {
            Inner::Remote(r) => {
                r.rt.block_on(r.store.get_range(key, range))
                    .map_err(|e| std::io::Error::other(format!("{}: {e}", r.url)))
            }
            Inner::Local(_) => unreachable!("ranges are read from remote stores only"),
        }
    }
}

/// A file opened for random access (see [`Store::chunks`]).
pub enum Chunks {
    File(std::fs::File),
    Remote(Arc<RemoteFile>),
}

/// An object read by ranges through a read-ahead window: the Parquet reader asks for page
/// headers and column chunks in many small reads, and one GET per window serves them.
pub struct RemoteFile {
    store: Store,
    key: object_store::path::Path,
    size: u64,
    window: std::sync::Mutex<Option<(u64, Bytes)>>,
}

/// Bytes fetched ahead of a read (a row group's column chunks are contiguous).
const READ_AHEAD: u64 = 8 << 20;
/// Bytes fetched at the end of a file when any of them is read (the Parquet footer).
const TAIL: u64 = 64 << 10;

impl RemoteFile {
    /// `len` bytes from `start` (fewer at the end), from the window or one GET that refills it.
    fn bytes(&self, start: u64, len: u64) -> std::io::Result<Bytes> {
        let end = (start + len).min(self.size);
        if start >= end {
            return Ok(Bytes::new());
        }
        let mut window = self.window.lock().expect("window lock");
        if let Some((at, b)) = window.as_ref() {
            if *at <= start && end <= *at + b.len() as u64 {
                return Ok(b.slice((start - at) as usize..(end - at) as usize));
            }
        }
        let (from, to) = if end + TAIL >= self.size {
            (start.min(self.size.saturating_sub(TAIL)), self.size)
        } else {
            (start, (start + len.max(READ_AHEAD)).min(self.size))
        };
        let b = self.store.get_range(&self.key, from..to)?;
        *window = Some((from, b.clone()));
        Ok(b.slice((start - from) as usize..(end - from) as usize))
    }
}

/// A reader from an offset of a remote file, fetching through its window as it goes.
pub struct RemoteRead {
    file: Arc<RemoteFile>,
    pos: u64,
}

impl std::io::Read for RemoteRead {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let b = self.file.bytes(self.pos, buf.len() as u64)?;
        buf[..b.len()].copy_from_slice(&b);
        self.pos += b.len() as u64;
        Ok(b.len())
    }
}

impl parquet::file::reader::Length for Chunks {
    fn len(&self) -> u64 {
        match self {
            Chunks::File(f) => parquet::file::reader::Length::len(f),
            Chunks::Remote(r) => r.size,
        }
    }
}

impl parquet::file::reader::ChunkReader for Chunks {
    type T = Box<dyn std::io::Read + Send>;

    fn get_read(&self, start: u64) -> parquet::errors::Result<Self::T> {
        match self {
            Chunks::File(f) => Ok(Box::new(f.get_read(start)?)),
            Chunks::Remote(r) => Ok(Box::new(RemoteRead {
                file: r.clone(),
                pos: start,
            })),
        }
    }

    fn get_bytes(&self, start: u64, length: usize) -> parquet::errors::Result<Bytes> {
        match self {
            Chunks::File(f) => f.get_bytes(start, length),
            Chunks::Remote(r) => {
                let b = r
                    .bytes(start, length as u64)
                    .map_err(|e| parquet::errors::ParquetError::External(Box::new(e)))?;
                if b.len() < length {
                    return Err(parquet::errors::ParquetError::EOF(format!(
                        "{}: {length} bytes at {start} run past the end ({} bytes)",
                        r.store.root().display(),
                        r.size
                    )));
                }
                Ok(b)
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
        let s = Store::open("file:///tmp/x").unwrap();
        assert_eq!(s.local_dir(), Some(Path::new("/tmp/x")));
    }

    #[test]
    fn no_name_leaves_the_dataset_locally_or_as_an_object_key() {
        let d = tempfile::tempdir().unwrap();
        let inner = d.path().join("ds");
        let remote = Store::open("s3://bucket/ds").unwrap();
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
