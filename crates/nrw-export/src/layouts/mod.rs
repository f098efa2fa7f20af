//! One room per export layout: a file each, or a folder for a family of consumers
//! (`megadepth/`: D2-Net, LoFTR, RoMa, DUSt3R, IMC 2022; `paper/`: the paper's published
//! code, as PNG folders or TFRecords). Each implements [`crate::writer::LayoutWriter`].

pub mod files;
pub mod gsplat;
pub mod megadepth;
pub mod nerfbaselines;
pub mod nerfstudio;
pub mod nerfw;
pub mod paper;
