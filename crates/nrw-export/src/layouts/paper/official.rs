//! The official layout: `train/` and `val/` of `NNNN_{reference,color,depth,seg_rgb}.png` as
//! the published `dataset_utils.AlignedRenderedDataset` and `pretrain_appearance` read them,
//! and `dist_NAME.pckl`.

use nrw_dataset::split::TRAIN;
use nrw_dataset::ViewRow;

use crate::error::Result;
use crate::paper::Paper;
use crate::staging::Staged;
use crate::stream::{write_views, Encoded, ViewEncoder};
use crate::writer::{About, Job, LayoutWriter};
use crate::ExportSummary;

pub use crate::published::{
    crop_start, official_colors, official_seg_rgb, DepthMapping, DepthScale, OFFICIAL_COLORS_CSV,
    PUBLISHED_CROP,
};

/// The `official` layout, as the CLI, pipeline files and `export.json` name it.
pub const ABOUT: About = About {
    name: "official",
    summary: "train/ and val/ with NNNN_reference.png, NNNN_color.png (RGBA), NNNN_depth.png (levels 0-255), NNNN_seg_rgb.png (the published colour coding), dist_NAME.pckl with official descriptors",
    needs_points: false,
    writes_depth_priors: false,
    default_crop: Some(crate::published::PUBLISHED_CROP),
};

/// The official layout: `train/` and `val/` of `NNNN_{reference,color,depth,seg_rgb}.png`,
/// and `dist_NAME.pckl` when the dataset has official style descriptors.
pub struct Official;

impl LayoutWriter for Official {
    fn check(&self, job: &Job) -> Result<()> {
        crate::paper::check(job)
    }

    fn write(&self, job: &Job, staged: &Staged, summary: &mut ExportSummary) -> Result<()> {
        let paper = Paper::of(job)?;
        paper.begin(job, summary);
        write_views(job, staged, &OfficialFiles(&paper), summary)?;
        paper.require_written_train(job, summary)?;
        let Some(dist) = job.inputs.dist else {
            return Ok(());
        };
        let train = summary
            .splits
            .iter()
            .find(|s| s.split == TRAIN)
            .expect("checked");
        if let Some((block, mut rows)) = dist(&train.image_ids)? {
            let n = train.image_ids.len();
            let file = format!("dist_{}.pckl", job.cfg.name);
            let path = staged.out().join(&file);
            let io = |e| crate::error::ExportError::io(&path, e);
            staged.write_with(&file, &mut |w| {
                crate::pickle::write_matrix_dict(
                    w,
                    "dist_matrix",
                    n,
                    block,
                    &mut |r| Ok(rows(r)?),
                    &io,
                )
            })?;
            summary.dist_pickle = Some(file);
        }
        Ok(())
    }
}

/// One view as the official layout's four PNGs.
struct OfficialFiles<'a>(&'a Paper);

impl ViewEncoder for OfficialFiles<'_> {
    fn check_view(&self, v: &ViewRow) -> Result<()> {
        self.0.check_view(v)
    }

    fn skip(&self, v: &ViewRow) -> Option<String> {
        self.0.skip(v)
    }

    fn encode(&self, v: &ViewRow, split: &str, index: &str) -> Result<Encoded> {
        use nrw_dataset::codec::{encode_gray, encode_rgb, encode_rgba};
        let paper = self.0;
        let stem = format!("{split}/{index}");
        let name = &v.name;
        let (reference, color, depth, seg) = match paper.crop {
            // Uncropped, the stored photo and render PNGs are the files already: no decode,
            // no re-encode.
            None => (
                v.photo_png.clone(),
                v.color_png.clone(),
                paper.scale.image(v.width, v.height, &v.depth()?.data),
                paper.seg(v)?,
            ),
            Some(_) => {
                let o = paper.view(v)?;
                (
                    encode_rgb(name, &o.reference)?,
                    encode_rgba(name, &o.color)?,
                    o.depth,
                    o.seg,
                )
            }
        };
        let mut files = vec![
            (format!("{stem}_reference.png"), reference),
            (format!("{stem}_color.png"), color),
            (
                format!("{stem}_depth.png"),
                encode_gray(name, depth.width(), depth.height(), depth.as_raw())?,
            ),
        ];
        if let Some(s) = &seg {
            files.push((format!("{stem}_seg_rgb.png"), encode_rgb(name, s)?));
        }
        Ok(files)
    }
}
