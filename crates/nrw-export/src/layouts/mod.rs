//! One room per export layout: a file each, or a folder for a family of consumers
//! (`megadepth/`: D2-Net, LoFTR, RoMa, DUSt3R, IMC 2022; `paper/`: the paper's published
//! code, as PNG folders or TFRecords). Each file declares what its layout is ([`About`]: its
//! name, help and needs) and implements [`crate::writer::LayoutWriter`]; this file lists them.
//! Adding a layout is its file and four lines here: the `mod`, the variant, its place in
//! [`Layout::ALL`] and its arm in [`Layout::parts`].

pub mod files;
pub mod gsplat;
pub mod megadepth;
pub mod nerfbaselines;
pub mod nerfstudio;
pub mod nerfw;
pub mod paper;

use crate::writer::{About, LayoutWriter};
use paper::{official, tfrecord};

/// Which files an export writes: one value for the CLI (`--layout`), pipeline files
/// (`[export] layout`) and `export.json`, each under its [`About::name`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Layout {
    Official,
    Tfrecord,
    Files,
    Nerfw,
    Nerfstudio,
    Gsplat,
    Megadepth,
    Nerfbaselines,
}

impl Layout {
    /// Every layout, in the order help lists them.
    pub const ALL: [Layout; 8] = [
        Layout::Official,
        Layout::Tfrecord,
        Layout::Files,
        Layout::Nerfw,
        Layout::Nerfstudio,
        Layout::Gsplat,
        Layout::Megadepth,
        Layout::Nerfbaselines,
    ];

    /// What the layout is, and the format that writes it.
    pub(crate) const fn parts(self) -> (&'static About, &'static dyn LayoutWriter) {
        match self {
            Layout::Official => (&official::ABOUT, &official::Official),
            Layout::Tfrecord => (&tfrecord::ABOUT, &tfrecord::Tfrecord),
            Layout::Files => (&files::ABOUT, &files::Files),
            Layout::Nerfw => (&nerfw::ABOUT, &nerfw::NERFW),
            Layout::Nerfstudio => (&nerfstudio::ABOUT, &nerfstudio::NERFSTUDIO),
            Layout::Gsplat => (&gsplat::ABOUT, &gsplat::Gsplat),
            Layout::Megadepth => (&megadepth::ABOUT, &megadepth::Megadepth),
            Layout::Nerfbaselines => (&nerfbaselines::ABOUT, &nerfbaselines::NERFBASELINES),
        }
    }

    /// What the layout is: its name, help and needs (points, depth priors, default crop), as
    /// its file declares them.
    pub const fn about(self) -> &'static About {
        self.parts().0
    }

    /// The layout's name on the command line, in pipeline files and in `export.json`.
    pub const fn name(self) -> &'static str {
        self.about().name
    }

    /// What the layout holds, in one line (the CLI's help for each value).
    pub fn summary(self) -> &'static str {
        self.about().summary
    }
}

impl std::fmt::Display for Layout {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for Layout {
    type Err = String;

    /// A layout by its name; the error lists the names.
    fn from_str(s: &str) -> std::result::Result<Layout, String> {
        Layout::ALL
            .into_iter()
            .find(|l| l.name() == s)
            .ok_or_else(|| {
                let names: Vec<&str> = Layout::ALL.iter().map(|l| l.name()).collect();
                format!("{s:?} is not a layout: {}", names.join(", "))
            })
    }
}

impl serde::Serialize for Layout {
    /// The layout's name, as `export.json` and pipeline files spell it.
    fn serialize<S: serde::Serializer>(&self, s: S) -> std::result::Result<S::Ok, S::Error> {
        s.serialize_str(self.name())
    }
}

impl<'de> serde::Deserialize<'de> for Layout {
    /// A layout by its name; an unknown one is an error listing the names.
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> std::result::Result<Layout, D::Error> {
        let name = String::deserialize(d)?;
        name.parse().map_err(serde::de::Error::custom)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_layout_has_its_own_name_and_is_found_by_it() {
        let mut names: Vec<&str> = Layout::ALL.iter().map(|l| l.name()).collect();
        for l in Layout::ALL {
            assert_eq!(l.name().parse::<Layout>(), Ok(l));
            assert_eq!(
                serde_json::to_string(&l).unwrap(),
                format!("\"{}\"", l.name())
            );
            assert_eq!(
                serde_json::from_str::<Layout>(&format!("\"{l}\"")).unwrap(),
                l
            );
        }
        names.sort();
        names.dedup();
        assert_eq!(names.len(), Layout::ALL.len(), "two layouts share a name");
        let err = serde_json::from_str::<Layout>("\"colmap\"").unwrap_err();
        assert!(
            err.to_string()
                .contains("\"colmap\" is not a layout: official, tfrecord"),
            "{err}"
        );
    }
}
