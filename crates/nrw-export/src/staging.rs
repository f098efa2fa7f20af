//! Where an export is built and how it is published. Every export is written into a hidden
//! local folder first, every file claimed through the one checked join; then the folder is
//! moved into place whole (a local destination) or uploaded file by file with `export.json`
//! last (an object-store destination), so a reader never sees a half-written export or
//! files left from an earlier one.

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::Mutex;

use nrw_dataset::{Location, Store};

use crate::error::{ExportError, Result};

/// The JSON an export writes beside its files: what it holds and how to read it back. Its
/// presence marks a folder as an export this tool may replace.
pub const EXPORT_JSON: &str = "export.json";

/// Where a finished export goes.
enum Destination {
    /// A local folder: the staging folder is renamed to it.
    Folder(PathBuf),
    /// An object-store prefix: the staged files are uploaded under it; `earlier` lists what
    /// it held when the export began (listed once, to check and then to clean up).
    Remote { store: Store, earlier: Vec<String> },
}

/// The hidden folder an export is built in, and every file claimed in it so far: no two
/// files of one export may have names equal, or equal but for letter case or Unicode
/// normalisation ([`nrw_colmap::names::fold_key`]), since on macOS and Windows the second
/// would overwrite the first. Every file an export writes is claimed here.
pub struct Staged {
    dir: PathBuf,
    /// The export's destination, named in messages (the hidden folder means nothing to a user).
    out: Location,
    dest: Destination,
    claimed: Mutex<HashMap<String, String>>,
}

impl Staged {
    /// Check the destination `out` (a folder or an object-store URL) and make the hidden
    /// folder the export is built in.
    pub fn new(out: &Location) -> Result<Staged> {
        let (dir, dest) = match out {
            Location::Url(_) => {
                let store = Store::open(out)?;
                let earlier = store.list("")?;
                refuse_foreign(out, &earlier, |k| k == EXPORT_JSON)?;
                (
                    nrw_dataset::publish::scratch_folder("export-new")?,
                    Destination::Remote { store, earlier },
                )
            }
            Location::Local(folder) => {
                (local_staging(folder)?, Destination::Folder(folder.clone()))
            }
        };
        Ok(Staged {
            dir,
            out: out.clone(),
            dest,
            claimed: Default::default(),
        })
    }

    /// The hidden folder itself (for files of fixed names written by other code, such as a
    /// COLMAP model).
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// The destination as the user gave it.
    pub fn out(&self) -> &Location {
        &self.out
    }

    /// `dir/rel` through the checked join ([`join_under`]), claimed for one file.
    pub fn claim(&self, rel: &str) -> Result<PathBuf> {
        // Named by the export folder: the hidden staging folder means nothing to a user.
        let path = join_under(&self.dir, rel).map_err(|e| match e {
            ExportError::Value { problem, .. } => name_error(&self.out, problem),
            e => e,
        })?;
        let key = nrw_colmap::names::fold_key(rel);
        let mut claimed = self.claimed.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(first) = claimed.get(&key) {
            let how = if first == rel {
                "two views would write the same file"
            } else {
                "the names differ only in letter case or Unicode normalisation, so on macOS and Windows they are one file"
            };
            return Err(name_error(
                &self.out,
                format!("{rel:?} and {first:?}: {how}; rename one photo in the model (or leave one out) and export again"),
            ));
        }
        claimed.insert(key, rel.to_string());
        Ok(path)
    }

    /// Write `bytes` to a claimed `rel`, creating its folders.
    pub fn write(&self, rel: &str, bytes: &[u8]) -> Result<()> {
        write_file(&self.claim(rel)?, bytes)
    }

    /// Write a claimed `rel` through `write`, given a buffered file it may seek in (an `.npz`
    /// writer patches each member's CRC), creating its folders and syncing the file: for
    /// files streamed, never held whole in memory.
    pub fn write_seekable(
        &self,
        rel: &str,
        write: impl FnOnce(
            std::io::BufWriter<std::fs::File>,
        ) -> std::io::Result<std::io::BufWriter<std::fs::File>>,
    ) -> Result<()> {
        let path = self.claim(rel)?;
        if let Some(d) = path.parent() {
            std::fs::create_dir_all(d).map_err(|e| ExportError::io(d, e))?;
        }
        let file = std::fs::File::create(&path).map_err(|e| ExportError::io(&path, e))?;
        let file = write(std::io::BufWriter::with_capacity(1 << 20, file))
            .map_err(|e| ExportError::io(&path, e))?;
        let file = file
            .into_inner()
            .map_err(|e| ExportError::io(&path, e.into_error()))?;
        file.sync_all().map_err(|e| ExportError::io(&path, e))
    }

    /// Write a claimed `rel` through a buffered writer, creating its folders.
    pub fn write_with(
        &self,
        rel: &str,
        body: &mut dyn FnMut(&mut dyn std::io::Write) -> Result<()>,
    ) -> Result<()> {
        let path = self.claim(rel)?;
        if let Some(d) = path.parent() {
            std::fs::create_dir_all(d).map_err(|e| ExportError::io(d, e))?;
        }
        let f = std::fs::File::create(&path).map_err(|e| ExportError::io(&path, e))?;
        let mut w = std::io::BufWriter::new(f);
        body(&mut w)?;
        std::io::Write::flush(&mut w).map_err(|e| ExportError::io(&path, e))
    }

    /// Make the finished export visible at its destination, replacing an earlier one whole.
    pub fn publish(self) -> Result<()> {
        let published = match &self.dest {
            Destination::Folder(folder) => {
                nrw_dataset::publish::rename_into_place(&self.dir, folder).map_err(Into::into)
            }
            Destination::Remote { store, earlier } => {
                nrw_dataset::publish::upload_folder(&self.dir, store, earlier, EXPORT_JSON)
                    .map_err(Into::into)
            }
        };
        if published.is_ok() && self.dir.exists() {
            let _ = std::fs::remove_dir_all(&self.dir);
        }
        published
    }

    /// Remove what was staged (the export failed).
    pub fn abandon(self) {
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}

/// Refuse a non-empty destination that is not an earlier export (`has_marker` tells whether a
/// listed name is its `export.json`).
fn refuse_foreign(
    out: &Location,
    names: &[String],
    has_marker: impl Fn(&str) -> bool,
) -> Result<()> {
    if names.is_empty() || names.iter().any(|n| has_marker(n)) {
        return Ok(());
    }
    Err(ExportError::refused(
        out,
        format!("holds files that are not an nrw-etl export (no {EXPORT_JSON}); export into an empty or new folder, or into an earlier export to replace it"),
    ))
}

/// The hidden folder beside a local destination (same file system, so publishing is a rename),
/// after removing leftovers of interrupted exports into it.
fn local_staging(out: &Path) -> Result<PathBuf> {
    if out.is_file() {
        return Err(ExportError::refused(
            out,
            "is a file; give a folder to export into",
        ));
    }
    if out.is_dir() {
        let names: Vec<String> = std::fs::read_dir(out)
            .map_err(|e| ExportError::io(out, e))?
            .flatten()
            .map(|e| e.file_name().to_string_lossy().into_owned())
            .collect();
        refuse_foreign(&out.into(), &names, |n| {
            n == EXPORT_JSON && out.join(n).is_file()
        })?;
    }
    let parent = match out.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    };
    std::fs::create_dir_all(&parent).map_err(|e| ExportError::io(&parent, e))?;
    let base = out
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "export".into());
    if let Ok(entries) = std::fs::read_dir(&parent) {
        for e in entries.flatten() {
            let n = e.file_name().to_string_lossy().into_owned();
            if n.starts_with(&format!(".{base}.export-")) {
                let _ = std::fs::remove_dir_all(e.path());
            }
        }
    }
    let staged = parent.join(format!(".{base}.export-new-{}", std::process::id()));
    std::fs::create_dir_all(&staged).map_err(|e| ExportError::io(&staged, e))?;
    Ok(staged)
}

/// An output file name refused, naming the export folder.
fn name_error(out: &Location, problem: String) -> ExportError {
    ExportError::Value {
        path: out.into(),
        record: "output file".into(),
        field: "name".into(),
        problem,
    }
}

/// `root/rel`, refusing a `rel` that is not a relative path of normal components
/// ([`nrw_colmap::names::check_name`]): every file an export writes is joined this way (by
/// [`Staged::claim`]), so no name from a dataset (or an export's `--name`) can put a file
/// outside the export folder.
pub fn join_under(root: &Path, rel: &str) -> Result<PathBuf> {
    nrw_colmap::names::join_checked(root, rel).map_err(|problem| name_error(&root.into(), problem))
}

/// Write a file, creating its folders.
fn write_file(path: &Path, bytes: &[u8]) -> Result<()> {
    if let Some(d) = path.parent() {
        std::fs::create_dir_all(d).map_err(|e| ExportError::io(d, e))?;
    }
    std::fs::write(path, bytes).map_err(|e| ExportError::io(path, e))
}
