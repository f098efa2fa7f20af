//! `fused.ply` and `fused.ply.vis` written as fusion makes its points, so fusion never holds
//! its cloud: the bytes are those of [`crate::write_ply`] and [`crate::dense::visibility_to_bytes`]
//! over the whole cloud.

use std::fs::File;
use std::io::{BufReader, BufWriter, Read, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

use glam::DVec3;

/// A point's bytes in the scratch body: f64 x y z, f32 nx ny nz, u8 r g b.
const RECORD: usize = 3 * 8 + 3 * 4 + 3;

/// Writes a cloud with normals and colours, and its visibility, one point at a time.
pub struct FusedWriter {
    ply: PathBuf,
    vis: PathBuf,
    /// Scratch: the points in f64, as [`crate::write_ply`]'s choice of f32 or f64 waits for
    /// the last point.
    body_path: PathBuf,
    body: BufWriter<File>,
    /// `fused.ply.vis` being written, its point count filled in at the end.
    vis_tmp: PathBuf,
    vis_body: BufWriter<File>,
    count: u64,
    double: bool,
}

impl FusedWriter {
    /// Start writing `ply` and `vis` (both appear, whole, only at [`FusedWriter::finish`]).
    pub fn create(ply: &Path, vis: &Path) -> std::io::Result<FusedWriter> {
        let body_path = ply.with_extension("ply.body.tmp");
        let vis_tmp = vis.with_extension("vis.tmp");
        let mut vis_body = BufWriter::new(File::create(&vis_tmp)?);
        vis_body.write_all(&0u64.to_le_bytes())?;
        Ok(FusedWriter {
            ply: ply.to_path_buf(),
            vis: vis.to_path_buf(),
            body: BufWriter::new(File::create(&body_path)?),
            body_path,
            vis_tmp,
            vis_body,
            count: 0,
            double: false,
        })
    }

    /// Append one point and the images (workspace indices) it was fused from.
    pub fn push(
        &mut self,
        position: DVec3,
        normal: [f32; 3],
        colour: [u8; 3],
        images: &[u32],
    ) -> std::io::Result<()> {
        self.double |= position.abs().max_element() > 1e5;
        for v in position.to_array() {
            self.body.write_all(&v.to_le_bytes())?;
        }
        for v in normal {
            self.body.write_all(&v.to_le_bytes())?;
        }
        self.body.write_all(&colour)?;
        self.vis_body
            .write_all(&(images.len() as u32).to_le_bytes())?;
        for i in images {
            self.vis_body.write_all(&i.to_le_bytes())?;
        }
        self.count += 1;
        Ok(())
    }

    /// The points written so far.
    pub fn len(&self) -> u64 {
        self.count
    }

    /// Whether no point was written.
    pub fn is_empty(&self) -> bool {
        self.count == 0
    }

    /// Write both files in place (each renamed whole) and remove the scratch.
    pub fn finish(self) -> std::io::Result<u64> {
        let mut vis = self.vis_body.into_inner().map_err(|e| e.into_error())?;
        vis.seek(SeekFrom::Start(0))?;
        vis.write_all(&self.count.to_le_bytes())?;
        vis.sync_all()?;
        drop(vis);
        self.body
            .into_inner()
            .map_err(|e| e.into_error())?
            .sync_all()?;
        write_final_ply(&self.body_path, &self.ply, self.count, self.double)?;
        std::fs::remove_file(&self.body_path)?;
        std::fs::rename(&self.vis_tmp, &self.vis)?;
        Ok(self.count)
    }
}

/// `fused.ply` from the scratch body: the header [`crate::write_ply`] writes, then each point
/// with its position in f32 unless `double`.
fn write_final_ply(body: &Path, ply: &Path, count: u64, double: bool) -> std::io::Result<()> {
    let ty = if double { "double" } else { "float" };
    let header = format!(
        "ply\nformat binary_little_endian 1.0\nelement vertex {count}\n\
         property {ty} x\nproperty {ty} y\nproperty {ty} z\n\
         property float nx\nproperty float ny\nproperty float nz\n\
         property uchar red\nproperty uchar green\nproperty uchar blue\nend_header\n"
    );
    let tmp = ply.with_extension("ply.tmp");
    let mut w = BufWriter::new(File::create(&tmp)?);
    w.write_all(header.as_bytes())?;
    let mut r = BufReader::new(File::open(body)?);
    let mut record = [0u8; RECORD];
    for _ in 0..count {
        r.read_exact(&mut record)?;
        if double {
            w.write_all(&record[..24])?;
        } else {
            for k in 0..3 {
                let v = f64::from_le_bytes(record[8 * k..8 * k + 8].try_into().expect("8 bytes"));
                // Precision given up here: COLMAP's layout stores f32 positions.
                w.write_all(&(v as f32).to_le_bytes())?;
            }
        }
        w.write_all(&record[24..])?;
    }
    w.into_inner().map_err(|e| e.into_error())?.sync_all()?;
    std::fs::rename(&tmp, ply)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::dense::visibility_to_bytes;
    use crate::{write_ply, PointCloud};

    fn both_ways(positions: Vec<DVec3>) {
        let dir = tempfile::tempdir().unwrap();
        let n = positions.len();
        let normals: Vec<[f32; 3]> = (0..n).map(|i| [i as f32, 0.5, -1.0]).collect();
        let colors: Vec<[u8; 3]> = (0..n).map(|i| [i as u8, 7, 250]).collect();
        let vis: Vec<Vec<u32>> = (0..n).map(|i| (0..i as u32 % 4).collect()).collect();
        let whole = dir.path().join("whole.ply");
        write_ply(
            &PointCloud {
                path: whole.clone(),
                positions: positions.clone(),
                colors: Some(colors.clone()),
                normals: Some(normals.clone()),
            },
            &whole,
        )
        .unwrap();
        let (ply, vis_path) = (
            dir.path().join("fused.ply"),
            dir.path().join("fused.ply.vis"),
        );
        let mut w = FusedWriter::create(&ply, &vis_path).unwrap();
        for i in 0..n {
            w.push(positions[i], normals[i], colors[i], &vis[i])
                .unwrap();
        }
        assert_eq!(w.finish().unwrap(), n as u64);
        assert_eq!(std::fs::read(&ply).unwrap(), std::fs::read(&whole).unwrap());
        assert_eq!(std::fs::read(&vis_path).unwrap(), visibility_to_bytes(&vis));
        // Only the two files are left.
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 3);
    }

    #[test]
    fn streamed_points_give_the_bytes_of_the_whole_cloud_written_at_once() {
        both_ways(
            (0..50)
                .map(|i| DVec3::new(i as f64 * 0.1, -2.5, 1e-3))
                .collect(),
        );
        // A georeferenced cloud: doubles, as write_ply chooses from every point.
        let mut far: Vec<DVec3> = (0..50).map(|i| DVec3::new(i as f64, 1.0, 2.0)).collect();
        far[49].x = 4.5e6 + 0.123;
        both_ways(far);
        both_ways(Vec::new());
    }
}
