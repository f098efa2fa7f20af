//! Which payload check each dataset file gets (what `verify` runs on every file).

use crate::error::Result;
use crate::payload::PayloadMismatch;

/// The payload check of any dataset file: shards and descriptor parts have checksummed
/// payloads; other files have none (their manifest SHA-256 covers them).
pub fn check_payloads(
    rel: &str,
    path: &crate::Location,
    data: bytes::Bytes,
) -> Result<Vec<PayloadMismatch>> {
    if crate::views::is_shard(rel) {
        crate::views::check_shard(path, data)
    } else if crate::descriptors::is_part(rel) {
        crate::descriptors::check_part(path, data)
    } else {
        Ok(Vec::new())
    }
}
