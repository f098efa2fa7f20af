//! Image names are data from whoever made the model (a download, a collaborator's bucket, a
//! script), never paths until checked here. One rule decides what a name may be: a relative
//! path of normal components — COLMAP's subfolders (`cam0/0001.jpg`) included — with no `..`
//! or `.`, no root or drive prefix, no backslash, no NUL or control character, no empty
//! component, within the length limits of common file systems. Readers refuse any other name
//! naming file, image and field; writers join every name-derived path through the same rule.

use std::path::{Path, PathBuf};

/// Longest name accepted, in bytes (Linux's PATH_MAX).
pub const MAX_NAME_BYTES: usize = 4096;
/// Longest folder or file component, in bytes (NAME_MAX of ext4, APFS, NTFS).
pub const MAX_COMPONENT_BYTES: usize = 255;

/// Why `name` cannot be a relative path inside its folder, or Ok.
pub fn check_name(name: &str) -> Result<(), String> {
    if name.is_empty() {
        return Err("is empty".into());
    }
    if name.len() > MAX_NAME_BYTES {
        return Err(format!(
            "is {} bytes long, more than {MAX_NAME_BYTES}",
            name.len()
        ));
    }
    if let Some((at, c)) = name.char_indices().find(|(_, c)| c.is_control()) {
        return Err(format!(
            "holds the control character U+{:04X} at byte {at}",
            c as u32
        ));
    }
    if name.contains('\\') {
        return Err(
            "holds a backslash: COLMAP separates folders with `/`, and on Windows `\\` would climb folders too"
                .into(),
        );
    }
    if name.starts_with('/') {
        return Err("is an absolute path: it would be read from outside the images folder".into());
    }
    let b = name.as_bytes();
    if b.len() >= 2 && b[0].is_ascii_alphabetic() && b[1] == b':' {
        return Err("starts with a drive prefix".into());
    }
    for c in name.split('/') {
        match c {
            "" => return Err("has an empty component (`//` or a trailing `/`)".into()),
            "." => return Err("has a `.` component".into()),
            ".." => {
                return Err("climbs out of its folder with `..`".into());
            }
            c if c.len() > MAX_COMPONENT_BYTES => {
                return Err(format!(
                    "has a component of {} bytes, more than {MAX_COMPONENT_BYTES}",
                    c.len()
                ))
            }
            _ => {}
        }
    }
    Ok(())
}

/// The form under which two names are one file on a file system that ignores letter case
/// and Unicode normalisation (macOS's APFS, Windows' NTFS): NFC, lower case, NFC again.
/// (Lower-casing stands in for each system's own case folding; it joins every pair they join
/// among real photo names.) Writers refuse a second file of an equal key in one export.
pub fn fold_key(name: &str) -> String {
    use unicode_normalization::UnicodeNormalization;
    name.nfc()
        .collect::<String>()
        .to_lowercase()
        .nfc()
        .collect()
}

/// A model reader's check of one image's name (see [`check_name`]); the error names the
/// file, the image and `field`. (Two images of one name are refused where the model is
/// assembled.)
pub(crate) fn check_model_name(
    path: &Path,
    rec: crate::error::Record,
    field: &str,
    name: &str,
) -> crate::error::Result<()> {
    use crate::error::ColmapError;
    check_name(name).map_err(|p| {
        ColmapError::invalid(
            path,
            rec,
            field,
            format!("{name:?} {p}: an image name must be a relative path inside the images folder"),
        )
    })?;
    Ok(())
}

/// `root/name` after [`check_name`]: the one way a name from input becomes a path.
pub fn join_checked(root: &Path, name: &str) -> Result<PathBuf, String> {
    check_name(name).map_err(|p| format!("{name:?} {p}"))?;
    Ok(root.join(name))
}

/// An images folder, resolved once: each photo's link check then costs one `canonicalize`
/// of the photo, not of the folder too (a model names up to millions of photos).
#[derive(Debug, Clone)]
pub struct PhotoDir {
    dir: PathBuf,
    /// The folder's real path; `None` when links out are allowed (or the folder is missing).
    root: Option<PathBuf>,
}

impl PhotoDir {
    /// The folder `dir`; with `follow_outside_links`, photos linking out of it are allowed.
    pub fn new(dir: &Path, follow_outside_links: bool) -> PhotoDir {
        PhotoDir {
            dir: dir.to_path_buf(),
            root: if follow_outside_links {
                None
            } else {
                dir.canonicalize().ok()
            },
        }
    }

    /// The folder as given.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// The photo `name` inside the folder. A photo that is a symbolic link (or inside a
    /// linked folder) resolving outside it is refused unless links out were allowed: a model
    /// cannot make the tool read files the user did not put in the images folder.
    pub fn photo(&self, name: &str) -> Result<PathBuf, String> {
        let path = join_checked(&self.dir, name)?;
        let Some(root) = &self.root else {
            return Ok(path);
        };
        let Ok(real) = path.canonicalize() else {
            return Ok(path); // missing: the caller reports it as missing
        };
        if !real.starts_with(root) {
            return Err(format!(
                "{name:?} resolves to {}, outside the images folder {}: a link out of the folder is refused (`follow_outside_links` allows it)",
                real.display(),
                root.display()
            ));
        }
        Ok(path)
    }
}

/// The photo `name` inside `dir` ([`PhotoDir::photo`]), for a caller with one photo to find.
pub fn photo_path(dir: &Path, name: &str, follow_outside_links: bool) -> Result<PathBuf, String> {
    PhotoDir::new(dir, follow_outside_links).photo(name)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The fuzz target's property (fuzz/fuzz_targets/names.rs), checked exhaustively over
    /// every name of up to five symbols from an alphabet of the characters that matter.
    #[test]
    fn every_short_name_that_passes_stays_inside_as_normal_components() {
        use std::path::Component;
        let alphabet = ['a', '.', '/', '\\', '\0', ':', 'C', '\u{301}'];
        let root = Path::new("/scene/images");
        let mut names = vec![String::new()];
        let (mut passed, mut refused) = (0, 0);
        for _ in 0..5 {
            names = names
                .iter()
                .flat_map(|n| alphabet.iter().map(move |c| format!("{n}{c}")))
                .collect();
            for name in &names {
                let _ = fold_key(name);
                let Ok(path) = join_checked(root, name) else {
                    refused += 1;
                    continue;
                };
                passed += 1;
                let rel = path.strip_prefix(root).unwrap();
                assert!(
                    rel.components().all(|c| matches!(c, Component::Normal(_))),
                    "{name:?}"
                );
                assert_eq!(
                    rel.components().count(),
                    name.split('/').count(),
                    "{name:?}"
                );
            }
        }
        // Both sides are exercised: ".." and "a/.." refused, "a..", "C:" prefixes refused,
        // "a/a" and "..a" kept.
        assert!(passed > 1_000 && refused > 10_000, "{passed} {refused}");
    }

    #[test]
    fn names_equal_but_for_case_or_normalisation_fold_to_one_key() {
        let nfc = "caf\u{e9}/IMG_1.JPG";
        let nfd = "cafe\u{301}/img_1.jpg";
        assert_ne!(nfc, nfd);
        assert_eq!(fold_key(nfc), fold_key(nfd));
        assert_eq!(
            fold_key("\u{C5}ngstr\u{F6}m.jpg"),
            fold_key("A\u{30A}ngstro\u{308}m.JPG")
        );
        assert_ne!(fold_key("cafe/img_1.jpg"), fold_key(nfd));
        assert_ne!(fold_key("a.jpg"), fold_key("a.png"));
    }

    #[test]
    fn only_relative_names_of_normal_components_pass() {
        for ok in [
            "0001.jpg",
            "cam0/0001.jpg",
            "a b/c d.JPG",
            "ünïcödé/写真.jpg",
            "..jpg",
            "a..b",
        ] {
            assert_eq!(check_name(ok), Ok(()), "{ok}");
        }
        let long = "a".repeat(256);
        let deep = vec!["abc"; 1100].join("/");
        for (bad, why) in [
            ("", "empty"),
            ("../x.jpg", "`..`"),
            ("a/../../x.jpg", "`..`"),
            ("..", "`..`"),
            ("/etc/passwd", "absolute"),
            ("C:photo.jpg", "drive"),
            ("a\\..\\x.jpg", "backslash"),
            ("a\0b.jpg", "U+0000"),
            ("a\nb.jpg", "U+000A"),
            ("a//b.jpg", "empty component"),
            ("a/", "empty component"),
            ("./a.jpg", "`.` component"),
            (long.as_str(), "256 bytes"),
            (deep.as_str(), "more than 4096"),
        ] {
            let e = check_name(bad).unwrap_err();
            assert!(e.contains(why), "{bad:?}: {e}");
        }
    }

    #[test]
    fn a_link_out_of_the_folder_is_refused_unless_allowed() {
        let tmp = tempfile::tempdir().unwrap();
        let images = tmp.path().join("images");
        std::fs::create_dir_all(images.join("sub")).unwrap();
        std::fs::write(tmp.path().join("secret.jpg"), b"x").unwrap();
        std::fs::write(images.join("sub/in.jpg"), b"x").unwrap();
        std::os::unix::fs::symlink(tmp.path().join("secret.jpg"), images.join("out.jpg")).unwrap();
        std::os::unix::fs::symlink(images.join("sub/in.jpg"), images.join("in.jpg")).unwrap();
        assert!(photo_path(&images, "sub/in.jpg", false).is_ok());
        assert!(
            photo_path(&images, "in.jpg", false).is_ok(),
            "a link inside stays allowed"
        );
        let e = photo_path(&images, "out.jpg", false).unwrap_err();
        assert!(
            e.contains("outside the images folder") && e.contains("secret.jpg"),
            "{e}"
        );
        assert!(photo_path(&images, "out.jpg", true).is_ok());
        assert!(
            photo_path(&images, "../secret.jpg", true).is_err(),
            "never a climbing name"
        );
        assert!(
            photo_path(&images, "missing.jpg", false).is_ok(),
            "missing is the caller's"
        );
    }
}
