//! The layouts an export writes, by the names the CLI, pipeline files and `export.json` share.

use serde::Serialize;

/// Which files an export writes. One enum for the CLI (`--layout`), pipeline files
/// (`[export] layout`) and `export.json`, under the same lowercase names.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Layout {
    /// `train/` and `val/` with `NNNN_{reference,color,depth,seg_rgb}.png`, as the published
    /// code's `dataset_utils.AlignedRenderedDataset` and `pretrain_appearance` read them.
    Official,
    /// `<name>_<split>.tfrecord`: what `dataset_utils._generate_tfrecord_dataset` writes and
    /// `data._parser_rendered_dataset` parses.
    Tfrecord,
    /// `SPLIT/NAME/{photo.png, color.png, depth.exr, normal.png, semantics.png, labels.png,
    /// transient.png, meta.json}` for ordinary viewers.
    Files,
    /// NeRF-W's Phototourism layout (`NAME.tsv`, `dense/images`, `dense/sparse`), as nerf_pl
    /// and Ha-NeRF read it: see [`crate::nerfw`]. Needs the scene's points.
    Nerfw,
    /// nerfstudio's `transforms.json` with images, depth, masks and the sparse points: see
    /// [`crate::nerfstudio`]. Needs the scene's points.
    Nerfstudio,
    /// The COLMAP folder the 3DGS family reads (graphdeco, gsplat, OpenSplat, nerfbaselines):
    /// see [`crate::gsplat`]. Needs the scene's points.
    Gsplat,
    /// MegaDepth's folders and D2-Net's `scene_info` `.npz`, as matcher trainers read them: see
    /// [`crate::megadepth`]. Needs the scene's model (its tracks).
    Megadepth,
    /// The Phototourism folder nerfbaselines reads (WildGaussians and other in-the-wild
    /// methods): see [`crate::nerfbaselines`]. Needs the scene's points.
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

    /// The layout's name on the command line, in pipeline files and in `export.json`.
    pub const fn name(self) -> &'static str {
        match self {
            Layout::Official => "official",
            Layout::Tfrecord => "tfrecord",
            Layout::Files => "files",
            Layout::Nerfw => "nerfw",
            Layout::Nerfstudio => "nerfstudio",
            Layout::Gsplat => "gsplat",
            Layout::Megadepth => "megadepth",
            Layout::Nerfbaselines => "nerfbaselines",
        }
    }

    /// What the layout holds, in one line (the CLI's help for each value).
    pub fn summary(self) -> &'static str {
        match self {
            Layout::Official => "train/ and val/ with NNNN_reference.png, NNNN_color.png (RGBA), NNNN_depth.png (levels 0-255), NNNN_seg_rgb.png (the published colour coding), dist_NAME.pckl with official descriptors",
            Layout::Tfrecord => "NAME_train.tfrecord / NAME_val.tfrecord (or NAME-0000i-of-0000N_SPLIT.tfrecord with `export.tfrecord_files` N): the Examples the published data.py parses",
            Layout::Files => "SPLIT/NAME/{photo.png, color.png, depth.exr, normal.png, semantics.png, labels.png, transient.png, meta.json}",
            Layout::Nerfw => "NeRF-W's Phototourism layout for nerf_pl / Ha-NeRF loaders: NAME.tsv (filename, id, split, dataset), dense/images/, dense/sparse/ (one PINHOLE camera per image, the scene's points); needs a dataset ingested with `ingest.undistort` (or pinhole cameras)",
            Layout::Nerfstudio => "nerfstudio's transforms.json (each frame's exact camera model, OpenGL camera-to-world poses with nerfstudio's applied_transform, depth/*.npy, masks/*.png from the transient mask, train/val/test_filenames) with images/ and sparse_pc.ply; refuses camera models nerfstudio cannot represent exactly (FOV, FULL_OPENCV, thin-prism fisheyes)",
            Layout::Gsplat => "the COLMAP folder 3DGS trainers read (graphdeco, gsplat, OpenSplat, nerfbaselines): images/ and images_2|4|8/ (box-filtered whole blocks, intrinsics / N exactly), masks/ (255 = use; NAME.png and COLMAP's NAME.png.png) and masks_N/, sky/, depths/ and depths_N/ (graphdeco's 16-bit inverse depth) with sparse/0/depth_params.json, sparse/0 (one PINHOLE camera per image, the scene's points), train_list.txt / test_list.txt; needs PINHOLE cameras (`ingest.undistort`)",
            Layout::Nerfbaselines => "the Phototourism folder nerfbaselines reads (WildGaussians and other in-the-wild methods): images/, sparse/ (one PINHOLE camera per image, the scene's points), masks/ (255 = use), nerfw_split.csv, train_list.txt / test_list.txt and nb-info.json (loader colmap, id phototourism, NeRF-W evaluation); needs PINHOLE cameras (`ingest.undistort`)",
            Layout::Megadepth => "MegaDepth's layout for matcher trainers: Undistorted_SfM/NAME/{images/, sparse-txt/ (PINHOLE, the views' SfM observations)}, phoenix/S6/zl548/MegaDepth_v1/NAME/dense0/depths/*.h5 (key `depth`, float32, 0 = none) and scene_info/NAME.npz as D2-Net's preprocess_scene.py writes it (paths, K, poses, overlap, scale ratios, angles), LoFTR's index/, RoMa's prep_scene_info/, DUSt3R's dust3r/ and IMC 2022's imc2022/train/NAME/{calibration,pair_covisibility}.csv; needs PINHOLE cameras (`ingest.undistort`)",
        }
    }

    /// Whether the layout carries the scene's 3D points ([`crate::Inputs::points`]).
    pub fn needs_points(self) -> bool {
        matches!(
            self,
            Layout::Nerfw
                | Layout::Nerfstudio
                | Layout::Gsplat
                | Layout::Megadepth
                | Layout::Nerfbaselines
        )
    }

    /// Whether the layout writes depth priors, which prefer densify's MVS depth to the
    /// render's z-buffer.
    pub fn writes_depth_priors(self) -> bool {
        matches!(
            self,
            Layout::Nerfstudio | Layout::Gsplat | Layout::Megadepth
        )
    }

    /// Whether the layout is one the paper's published code reads (official, tfrecord).
    pub fn paper(self) -> bool {
        matches!(self, Layout::Official | Layout::Tfrecord)
    }

    /// The crop when none is asked: the published 512 for the paper's layouts, none (views
    /// kept whole) for the others.
    pub fn default_crop(self) -> Option<u32> {
        self.paper().then_some(crate::published::PUBLISHED_CROP)
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
