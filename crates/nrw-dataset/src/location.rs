//! Where a dataset, an export or a report lives, as the user named it: a local folder or an
//! object-store URL. A URL is never a `PathBuf` here, so no code can join, canonicalise or
//! open one as a local path by accident.

use std::fmt;
use std::path::{Path, PathBuf};

/// A local file or folder, or an object-store URL (`s3://`, `gs://`, `az://`).
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub enum Location {
    /// A file or folder on the local file system.
    Local(PathBuf),
    /// An object-store URL, without a trailing slash.
    Url(String),
}

/// Whether a location names an object store (`scheme://…` other than `file://`).
pub fn is_url(location: &str) -> bool {
    location.split_once("://").is_some_and(|(s, _)| {
        !s.is_empty() && s != "file" && s.chars().all(|c| c.is_ascii_alphanumeric())
    })
}

impl Location {
    /// A location as a user writes it: a URL names an object store, `file://…` and anything
    /// else a local path.
    pub fn parse(text: &str) -> Location {
        if is_url(text) {
            Location::Url(text.trim_end_matches('/').to_string())
        } else {
            Location::Local(PathBuf::from(text.strip_prefix("file://").unwrap_or(text)))
        }
    }

    /// The file or folder `rel` inside this one (`rel` is `/`-separated; callers check it).
    pub fn join(&self, rel: &str) -> Location {
        match self {
            Location::Local(d) => Location::Local(d.join(rel)),
            Location::Url(u) => Location::Url(format!("{u}/{rel}")),
        }
    }

    /// The local path, when the location is local.
    pub fn local(&self) -> Option<&Path> {
        match self {
            Location::Local(d) => Some(d),
            Location::Url(_) => None,
        }
    }

    /// Whether the location is on object storage.
    pub fn is_remote(&self) -> bool {
        matches!(self, Location::Url(_))
    }
}

impl fmt::Display for Location {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Location::Local(p) => write!(f, "{}", p.display()),
            Location::Url(u) => f.write_str(u),
        }
    }
}

/// Parses as [`Location::parse`] and never fails, so command-line arguments can be locations.
impl std::str::FromStr for Location {
    type Err = std::convert::Infallible;

    fn from_str(s: &str) -> Result<Location, Self::Err> {
        Ok(Location::parse(s))
    }
}

/// A path is local by its type.
impl From<PathBuf> for Location {
    fn from(p: PathBuf) -> Location {
        Location::Local(p)
    }
}

/// A path is local by its type.
impl From<&Path> for Location {
    fn from(p: &Path) -> Location {
        Location::Local(p.to_path_buf())
    }
}

/// A path is local by its type.
impl From<&PathBuf> for Location {
    fn from(p: &PathBuf) -> Location {
        Location::Local(p.clone())
    }
}

/// Text naming a location, as [`Location::parse`] reads it.
impl From<&str> for Location {
    fn from(s: &str) -> Location {
        Location::parse(s)
    }
}

/// Text naming a location, as [`Location::parse`] reads it.
impl From<String> for Location {
    fn from(s: String) -> Location {
        Location::parse(&s)
    }
}

/// A borrowed location, for functions that take `impl Into<Location>`.
impl From<&Location> for Location {
    fn from(l: &Location) -> Location {
        l.clone()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn urls_and_paths_parse_apart_and_join_their_own_way() {
        let u = Location::parse("s3://bucket/ds/");
        assert_eq!(u, Location::Url("s3://bucket/ds".into()));
        assert_eq!(
            u.join("views/a.parquet").to_string(),
            "s3://bucket/ds/views/a.parquet"
        );
        assert!(u.local().is_none() && u.is_remote());
        let f = Location::parse("file:///tmp/ds");
        assert_eq!(f, Location::Local(PathBuf::from("/tmp/ds")));
        assert_eq!(f.join("x").local(), Some(Path::new("/tmp/ds/x")));
        // A colon in a local name is not a scheme.
        assert!(!Location::parse("./a:b//c").is_remote());
        assert!(!Location::parse("weird name://x").is_remote());
    }
}
