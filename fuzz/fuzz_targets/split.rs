// Shared by the model targets: cut the input into the five model files at offsets taken
// from its first bytes, so the fuzzer can grow each file independently.
use std::path::PathBuf;

use nrw_colmap::ModelFiles;

pub fn split(data: &[u8], ext: &str) -> ModelFiles {
    if data.len() < 8 {
        return ModelFiles::default();
    }
    let (head, body) = data.split_at(8);
    let mut cuts: Vec<usize> = head
        .chunks(2)
        .map(|c| u16::from_le_bytes([c[0], c[1]]) as usize % (body.len() + 1))
        .collect();
    cuts.sort_unstable();
    let part = |i: usize| {
        let a = if i == 0 { 0 } else { cuts[i - 1] };
        let b = if i < 4 { cuts[i] } else { body.len() };
        body[a..b].to_vec()
    };
    let name = |n: &str| PathBuf::from(format!("{n}.{ext}"));
    ModelFiles {
        cameras: (name("cameras"), part(0)),
        images: (name("images"), part(1)),
        points: (name("points3D"), part(2)),
        rigs: Some((name("rigs"), part(3))).filter(|r| !r.1.is_empty()),
        frames: Some((name("frames"), part(4))).filter(|f| !f.1.is_empty()),
    }
}
