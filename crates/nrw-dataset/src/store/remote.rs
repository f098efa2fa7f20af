//! Object storage behind `Store`: the providers' settings from the environment, retries,
//! the process's one async runtime, multipart uploads, and errors that name the URL and
//! never a secret.

use std::path::Path;
use std::sync::Arc;
use std::time::Duration;

use object_store::{ObjectStore, ObjectStoreExt};

use crate::error::{DatasetError, Result};

/// An object-store location a `Store` reads and writes.
#[derive(Clone)]
pub(super) struct Remote {
    /// The URL as given, without a trailing slash (names files in messages).
    pub(super) url: String,
    pub(super) store: Arc<dyn ObjectStore>,
    pub(super) prefix: object_store::path::Path,
    pub(super) rt: &'static tokio::runtime::Runtime,
}

impl Remote {
    /// Bytes `range` of the object `key`, an I/O error naming the location otherwise.
    pub(super) fn get_range(
        &self,
        key: &object_store::path::Path,
        range: std::ops::Range<u64>,
    ) -> std::io::Result<bytes::Bytes> {
        self.rt
            .block_on(self.store.get_range(key, range))
            .map_err(|e| std::io::Error::other(format!("{}: {e}", self.url)))
    }
}

/// The one async runtime of the process, shared by every object-store location it opens
/// (made on the first open; a process that stays local never starts it). A forked child
/// (a PyTorch DataLoader worker) finds its parent's runtime without threads, so it makes its
/// own; each lives as long as its process, as a static would.
pub(super) fn runtime(url: &str) -> Result<&'static tokio::runtime::Runtime> {
    type PerProcess = Option<(u32, &'static tokio::runtime::Runtime)>;
    static RT: std::sync::Mutex<PerProcess> = std::sync::Mutex::new(None);
    let pid = std::process::id();
    let mut rt = RT.lock().unwrap_or_else(|p| p.into_inner());
    if let Some((owner, made)) = *rt {
        if owner == pid {
            return Ok(made);
        }
    }
    let made = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .map_err(|e| DatasetError::io(url, e))?;
    let made: &'static tokio::runtime::Runtime = Box::leak(Box::new(made));
    *rt = Some((pid, made));
    Ok(made)
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

pub(super) fn build_remote(
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
pub(super) enum Upload {
    Read(std::io::Error),
    Store(object_store::Error),
}

/// `from` to `key` in parts of [`UPLOAD_PART`] bytes, at most two in flight; aborted (no
/// object left) on any error.
pub(super) async fn upload_parts(
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
pub(super) fn remote_err(url: String, e: object_store::Error) -> DatasetError {
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
