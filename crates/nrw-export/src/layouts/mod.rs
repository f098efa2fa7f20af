//! One room per export layout: a file each, or a folder for a family of consumers
//! (`megadepth/`: D2-Net, LoFTR, RoMa, DUSt3R, IMC 2022; `paper/`: the paper's published
//! code, as PNG folders or TFRecords). Each implements [`crate::writer::LayoutWriter`]; this
//! file gives each `Layout` (crate::layout: the names the CLI, pipeline files and
//! `export.json` share) its writer. Adding a layout is its file, its `mod` line and writer
//! here, and its variant in layout.rs.

pub mod files;
pub mod gsplat;
pub mod megadepth;
pub mod nerfbaselines;
pub mod nerfstudio;
pub mod nerfw;
pub mod paper;

use crate::layout::Layout;
use paper::{official, tfrecord};

/// The format that writes `layout`.
pub(crate) fn writer_of(layout: Layout) -> &'static dyn crate::writer::LayoutWriter {
    match layout {
        Layout::Official => &official::Official,
        Layout::Tfrecord => &tfrecord::Tfrecord,
        Layout::Files => &files::Files,
        Layout::Nerfw => &nerfw::NERFW,
        Layout::Nerfstudio => &nerfstudio::NERFSTUDIO,
        Layout::Gsplat => &gsplat::Gsplat,
        Layout::Megadepth => &megadepth::Megadepth,
        Layout::Nerfbaselines => &nerfbaselines::NERFBASELINES,
    }
}
