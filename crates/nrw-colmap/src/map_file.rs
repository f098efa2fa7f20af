//! Part of a COLMAP depth or normal map read from its file (the layout in [`crate::dense`]):
//! fusion reads the rows its walks need instead of whole maps.

use std::path::{Path, PathBuf};

use crate::error::{ColmapError, Record, Result};

/// The longest header COLMAP writes (three decimal numbers and three `&`), with room to spare:
/// a file whose first `&`s are further in is not a map.
pub(crate) const MAX_HEADER: usize = 64;

/// The three numbers of a map header and the bytes after its third `&`; `None` when the
/// header is not three decimal numbers each ended by `&` within [`MAX_HEADER`] bytes.
pub(crate) fn split_header(bytes: &[u8]) -> Option<([usize; 3], &[u8])> {
    let mut dims = [0usize; 3];
    let mut at = 0;
    for d in &mut dims {
        let len = bytes[at..]
            .iter()
            .take(MAX_HEADER - at.min(MAX_HEADER))
            .position(|&b| b == b'&')?;
        let text = std::str::from_utf8(&bytes[at..at + len]).ok()?;
        if text.is_empty() || !text.bytes().all(|b| b.is_ascii_digit()) {
            return None;
        }
        *d = text.parse().ok()?;
        at += len + 1;
    }
    Some((dims, &bytes[at..]))
}

/// A map file opened for reading part of it: its header checked against the file's length, so
/// fusion can read the rows it needs instead of the whole map.
#[derive(Debug, Clone)]
pub struct MapFile {
    path: PathBuf,
    header_len: usize,
    pub width: usize,
    pub height: usize,
    pub channels: usize,
}

impl MapFile {
    /// Open `path`: its header must hold three whole numbers and the file exactly their
    /// product of float32 after it.
    pub fn open(path: &Path) -> Result<MapFile> {
        use std::io::Read;
        let mut head = Vec::with_capacity(MAX_HEADER);
        let file = std::fs::File::open(path).map_err(|e| ColmapError::io(path, e))?;
        let len = file.metadata().map_err(|e| ColmapError::io(path, e))?.len();
        file.take(MAX_HEADER as u64)
            .read_to_end(&mut head)
            .map_err(|e| ColmapError::io(path, e))?;
        let (dims, body) = split_header(&head).ok_or_else(|| {
            ColmapError::invalid(
                path,
                Record::File,
                "header",
                format!("no `WIDTH&HEIGHT&CHANNELS&` header in the first {MAX_HEADER} bytes (not a COLMAP depth or normal map)"),
            )
        })?;
        let header_len = head.len() - body.len();
        let [width, height, channels] = dims;
        let need = (width as u128) * (height as u128) * (channels as u128) * 4;
        if need == 0 || need + header_len as u128 != len as u128 {
            return Err(ColmapError::invalid(
                path,
                Record::File,
                "data",
                format!(
                    "{width} × {height} × {channels} float32 need {need} bytes after the header, the file has {}",
                    len.saturating_sub(header_len as u64)
                ),
            ));
        }
        Ok(MapFile {
            path: path.to_path_buf(),
            header_len,
            width,
            height,
            channels,
        })
    }

    /// Channel `channel` of the pixels `pixels` (row-major indices: `y × width + x`), read from
    /// the file's planar layout without reading the rest.
    pub fn read_plane(&self, channel: usize, pixels: std::ops::Range<usize>) -> Result<Vec<f32>> {
        use std::os::unix::fs::FileExt;
        let plane = self.width * self.height;
        assert!(channel < self.channels && pixels.end <= plane && pixels.start <= pixels.end);
        let mut bytes = vec![0u8; pixels.len() * 4];
        let at = self.header_len + (channel * plane + pixels.start) * 4;
        let file = std::fs::File::open(&self.path).map_err(|e| ColmapError::io(&self.path, e))?;
        file.read_exact_at(&mut bytes, at as u64)
            .map_err(|e| ColmapError::io(&self.path, e))?;
        Ok(bytes
            .chunks_exact(4)
            .map(|w| f32::from_le_bytes([w[0], w[1], w[2], w[3]]))
            .collect())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::dense::DenseMap;

    #[test]
    fn a_map_file_reads_any_rows_of_any_channel_as_the_whole_map_has_them() {
        let dir = tempfile::tempdir().unwrap();
        let mut m = DenseMap::filled(5, 4, 3, 0.0);
        for y in 0..4 {
            for x in 0..5 {
                for c in 0..3 {
                    m.set(x, y, c, (100 * c + 10 * y + x) as f32);
                }
            }
        }
        let path = dir.path().join("a.bin");
        std::fs::write(&path, m.to_bytes()).unwrap();
        let f = MapFile::open(&path).unwrap();
        assert_eq!((f.width, f.height, f.channels), (5, 4, 3));
        for c in 0..3 {
            let rows = f.read_plane(c, 5..15).unwrap();
            let want: Vec<f32> = (5..15).map(|p| m.get(p % 5, p / 5, c)).collect();
            assert_eq!(rows, want);
        }
        // A file one byte short is refused when opened, naming it and the field.
        let bytes = m.to_bytes();
        std::fs::write(&path, &bytes[..bytes.len() - 1]).unwrap();
        let e = MapFile::open(&path).unwrap_err().to_string();
        assert!(e.contains("a.bin") && e.contains("field `data`"), "{e}");
        std::fs::write(&path, b"1073741824&1073741824&1073741824&").unwrap();
        let e = MapFile::open(&path).unwrap_err().to_string();
        assert!(e.contains("the file has 0"), "{e}");
    }
}
