//! Publishing a folder built in hiding: the one way every stage that writes a folder whole
//! (export, densify) makes it visible. Locally the finished folder replaces the destination
//! by renames; on object storage its files are uploaded with a marker file last, so a reader
//! that trusts the marker never takes a half-written folder for a whole one.

use std::path::{Path, PathBuf};

use crate::error::{DatasetError, Result};
use crate::store::Store;

/// Move the finished folder `staged` to `out`, replacing an earlier folder there whole: the
/// earlier one is renamed aside first and removed after, so `out` is at every moment either
/// the earlier folder or the new one.
pub fn rename_into_place(staged: &Path, out: &Path) -> Result<()> {
    let old = aside(staged);
    crate::atomic::before_commit(&out.into());
    if out.exists() {
        std::fs::rename(out, &old).map_err(|e| DatasetError::io(out, e))?;
    }
    std::fs::rename(staged, out).map_err(|e| DatasetError::io(out, e))?;
    if old.exists() {
        std::fs::remove_dir_all(&old).map_err(|e| DatasetError::io(&old, e))?;
    }
    Ok(())
}

/// Whether the destination of a folder published whole already holds files (locally) or
/// objects (on object storage): what a stage's claim on its output tests before it would
/// replace them, the same test wherever the destination is.
pub fn occupied(out: &Store) -> Result<bool> {
    Ok(!out.list("")?.is_empty())
}

/// The hidden name a folder called `name` is built under beside its destination (a sibling
/// folder locally, a sibling prefix on object storage), so the units of one run find it.
pub fn staging_name(name: &str) -> String {
    format!(".{name}.partial")
}

/// A fresh hidden folder in the temporary directory, named by `tag`, the process and the
/// clock, where a folder bound for object storage is built before it is uploaded.
pub fn scratch_folder(tag: &str) -> Result<PathBuf> {
    let nanos = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.subsec_nanos());
    let dir = std::env::temp_dir().join(format!(".nrw-{tag}-{}-{nanos}", std::process::id()));
    std::fs::create_dir_all(&dir).map_err(|e| DatasetError::io(&dir, e))?;
    Ok(dir)
}

/// The name an earlier folder takes while `staged` replaces it (beside `staged`, so on its
/// file system).
fn aside(staged: &Path) -> PathBuf {
    let name = staged
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let renamed = if name.contains(".export-new-") {
        name.replace(".export-new-", ".export-old-")
    } else {
        format!("{name}.old")
    };
    staged.with_file_name(renamed)
}

/// Upload the files of the local folder `staged` under `store`: the earlier `marker` is
/// removed first (so a half-replaced folder is not taken for a whole one), every other file
/// next, `marker` last, then the files of `earlier` (what the destination held before) that
/// the new folder does not have.
pub fn upload_folder(staged: &Path, store: &Store, earlier: &[String], marker: &str) -> Result<()> {
    let files = Store::local(staged).list("")?;
    crate::atomic::before_commit(&store.root());
    store.delete(marker)?;
    for rel in files.iter().filter(|r| *r != marker) {
        store.upload(rel, &staged.join(rel))?;
    }
    store.upload(marker, &staged.join(marker))?;
    for rel in earlier.iter().filter(|r| !files.contains(r)) {
        store.delete(rel)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_folder_replaces_an_earlier_one_whole_and_uploads_with_its_marker_last() {
        let tmp = tempfile::tempdir().unwrap();
        let (staged, out) = (tmp.path().join(".out.partial"), tmp.path().join("out"));
        std::fs::create_dir_all(staged.join("sub")).unwrap();
        std::fs::write(staged.join("sub/a"), b"new").unwrap();
        std::fs::write(staged.join("done"), b"marker").unwrap();
        std::fs::create_dir_all(&out).unwrap();
        std::fs::write(out.join("stale"), b"old").unwrap();
        let copy = tmp.path().join("copy");
        std::fs::create_dir_all(&copy).unwrap();
        std::fs::write(copy.join("stale"), b"old").unwrap();
        let earlier = Store::local(&copy).list("").unwrap();
        assert!(occupied(&Store::local(&copy)).unwrap());
        assert!(!occupied(&Store::local(tmp.path().join("nothing"))).unwrap());
        upload_folder(&staged, &Store::local(&copy), &earlier, "done").unwrap();
        assert_eq!(
            Store::local(&copy).list("").unwrap(),
            vec!["done".to_string(), "sub/a".to_string()]
        );
        rename_into_place(&staged, &out).unwrap();
        assert_eq!(std::fs::read(out.join("sub/a")).unwrap(), b"new");
        assert!(!out.join("stale").exists() && !staged.exists());
        assert!(!tmp.path().join(".out.partial.old").exists());
    }
}
