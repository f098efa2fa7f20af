//! The tfrecord layout: `<name>_<split>.tfrecord` (or `--tfrecord-files` of them) of the Examples
//! `dataset_utils._generate_tfrecord_dataset` writes and `data._parser_rendered_dataset`
//! parses. The wire encoding is in [`crate::record`].

use nrw_dataset::ViewRow;

use crate::error::Result;
use crate::paper::Paper;
use crate::record::{encode_record, Feature};
use crate::staging::Staged;
use crate::stream::{write_views, Encoded, ViewEncoder};
use crate::writer::{About, Job, LayoutWriter};
use crate::ExportSummary;

/// The `tfrecord` layout, as the CLI, pipeline files and `export.json` name it.
pub const ABOUT: About = About {
    name: "tfrecord",
    summary: "NAME_train.tfrecord / NAME_val.tfrecord (or NAME-0000i-of-0000N_SPLIT.tfrecord with `export.tfrecord_files` N): the Examples the published data.py parses",
    needs_points: false,
    writes_depth_priors: false,
    default_crop: Some(crate::published::PUBLISHED_CROP),
};

/// The tfrecord layout.
pub struct Tfrecord;

impl LayoutWriter for Tfrecord {
    fn check(&self, job: &Job) -> Result<()> {
        crate::paper::check(job)
    }

    fn write(&self, job: &Job, staged: &Staged, summary: &mut ExportSummary) -> Result<()> {
        let paper = Paper::of(job)?;
        paper.begin(job, summary);
        let records = Records {
            paper: &paper,
            name: &job.cfg.name,
            files: job.cfg.paper.tfrecord_files,
        };
        write_views(job, staged, &records, summary)?;
        paper.require_written_train(job, summary)
    }
}

/// One view as one Example, appended to its split's file.
struct Records<'a> {
    paper: &'a Paper,
    name: &'a str,
    files: usize,
}

impl ViewEncoder for Records<'_> {
    fn check_view(&self, v: &ViewRow) -> Result<()> {
        self.paper.check_view(v)
    }

    fn skip(&self, v: &ViewRow) -> Option<String> {
        self.paper.skip(v)
    }

    /// The TFRecord frame of the Example `AlignedRenderedDataset` + `_to_example` make of a
    /// view: `height`, `width`, `rendered` (RGBA u8), `depth` (u16, little-endian), `real` (RGB
    /// u8), `seg` (RGB u8; empty with --no-semantics, which the published parser reads only
    /// with --use_semantic).
    fn encode(&self, v: &ViewRow, _split: &str, _index: &str) -> Result<Encoded> {
        let o = self.paper.view(v)?;
        let depth16: Vec<u8> = o
            .depth
            .as_raw()
            .iter()
            .flat_map(|&l| (l as u16).to_le_bytes())
            .collect();
        let empty: &[u8] = &[];
        let frame = encode_record(&[
            ("height", Feature::Int64(o.reference.height() as i64)),
            ("width", Feature::Int64(o.reference.width() as i64)),
            ("rendered", Feature::Bytes(o.color.as_raw())),
            ("depth", Feature::Bytes(&depth16)),
            ("real", Feature::Bytes(o.reference.as_raw())),
            (
                "seg",
                Feature::Bytes(o.seg.as_ref().map_or(empty, |s| s.as_raw().as_slice())),
            ),
        ]);
        Ok(vec![(String::new(), frame)])
    }

    fn records(&self, split: &str) -> Vec<String> {
        (0..self.files)
            .map(|i| tfrecord_name(self.name, split, i, self.files))
            .collect()
    }
}

/// TFRecord file name of file `i` of `n` of a split, matched by the published glob
/// `<name>*_<split>.tfrecord`.
pub fn tfrecord_name(name: &str, split: &str, i: usize, n: usize) -> String {
    if n <= 1 {
        format!("{name}_{split}.tfrecord")
    } else {
        format!("{name}-{i:05}-of-{n:05}_{split}.tfrecord")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tfrecord_names_match_the_published_glob() {
        assert_eq!(
            tfrecord_name("trevi", "train", 0, 1),
            "trevi_train.tfrecord"
        );
        let s = tfrecord_name("trevi", "val", 3, 12);
        assert_eq!(s, "trevi-00003-of-00012_val.tfrecord");
        assert!(s.starts_with("trevi") && s.ends_with("_val.tfrecord"));
    }
}
