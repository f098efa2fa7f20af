//! PLY variants COLMAP and other tools write, and broken ones.

use glam::DVec3;
use nrw_colmap::{read_ply, write_ply, PointCloud};

fn write(bytes: &[u8]) -> (tempfile::TempDir, std::path::PathBuf) {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("cloud.ply");
    std::fs::write(&p, bytes).unwrap();
    (dir, p)
}

fn cloud() -> PointCloud {
    PointCloud {
        path: Default::default(),
        positions: vec![DVec3::new(1.0, 2.0, 3.0), DVec3::new(-4.5, 0.25, 1e3)],
        colors: Some(vec![[255, 0, 7], [1, 2, 3]]),
        normals: Some(vec![[0.0, 0.0, 1.0], [1.0, 0.0, 0.0]]),
    }
}

#[test]
fn binary_round_trip_keeps_every_channel() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("fused.ply");
    write_ply(&cloud(), &p).unwrap();
    let back = read_ply(&p).unwrap();
    assert_eq!(back.positions, cloud().positions);
    assert_eq!(back.colors, cloud().colors);
    assert_eq!(back.normals, cloud().normals);
}

#[test]
fn missing_channels_stay_missing() {
    let mut c = cloud();
    c.normals = None;
    c.colors = None;
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("xyz.ply");
    write_ply(&c, &p).unwrap();
    let back = read_ply(&p).unwrap();
    assert!(back.normals.is_none() && back.colors.is_none());
    assert_eq!(back.positions, c.positions);
}

#[test]
fn ascii_with_any_property_order_and_doubles() {
    let text = "ply\nformat ascii 1.0\ncomment made by hand\nelement vertex 2\nproperty uchar blue\nproperty double z\nproperty uchar red\nproperty double x\nproperty uchar green\nproperty double y\nend_header\n9 3.5 1 1.25 5 2.0\n0 -1 255 0.1 128 1e-3\n";
    let (_d, p) = write(text.as_bytes());
    let c = read_ply(&p).unwrap();
    assert_eq!(
        c.positions,
        vec![DVec3::new(1.25, 2.0, 3.5), DVec3::new(0.1, 1e-3, -1.0)]
    );
    assert_eq!(c.colors.unwrap(), vec![[1, 5, 9], [255, 128, 0]]);
    assert!(c.normals.is_none());
}

#[test]
fn big_endian_binary() {
    let mut bytes = b"ply\nformat binary_big_endian 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\nproperty uchar red\nproperty uchar green\nproperty uchar blue\nend_header\n".to_vec();
    for v in [1.5f32, -2.0, 8.0] {
        bytes.extend_from_slice(&v.to_be_bytes());
    }
    bytes.extend_from_slice(&[10, 20, 30]);
    let (_d, p) = write(&bytes);
    let c = read_ply(&p).unwrap();
    assert_eq!(c.positions, vec![DVec3::new(1.5, -2.0, 8.0)]);
    assert_eq!(c.colors.unwrap(), vec![[10, 20, 30]]);
}

#[test]
fn truncated_body_names_the_vertex() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("fused.ply");
    write_ply(&cloud(), &p).unwrap();
    let full = std::fs::read(&p).unwrap();
    std::fs::write(&p, &full[..full.len() - 5]).unwrap();
    let e = read_ply(&p).unwrap_err().to_string();
    assert!(e.contains("fused.ply") && e.contains("vertex #1"), "{e}");
}

#[test]
fn huge_vertex_count_is_an_error_not_an_allocation() {
    let text = "ply\nformat binary_little_endian 1.0\nelement vertex 18446744073709551615\nproperty float x\nproperty float y\nproperty float z\nend_header\n\x00\x00\x00\x3f";
    let (_d, p) = write(text.as_bytes());
    let e = read_ply(&p).unwrap_err().to_string();
    assert!(e.contains("cloud.ply") && e.contains("vertex #0"), "{e}");
}

#[test]
fn an_element_of_empty_rows_with_a_huge_count_is_an_error_not_a_spin() {
    // Rows without properties take no bytes, so nothing ends the skip but the count.
    let text = "ply\nformat binary_little_endian 1.0\nelement face 4000000000\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\nend_header\n\x00\x00\x00\x3f\x00\x00\x00\x3f\x00\x00\x00\x3f";
    let (_d, p) = write(text.as_bytes());
    let e = read_ply(&p).unwrap_err().to_string();
    assert!(
        e.contains("cloud.ply") && e.contains("4000000000 rows"),
        "{e}"
    );
}

#[test]
fn non_finite_and_partial_channels_are_errors() {
    let text = "ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\nend_header\n1 2 3\n4 nan 6\n";
    let (_d, p) = write(text.as_bytes());
    let e = read_ply(&p).unwrap_err().to_string();
    assert!(e.contains("vertex #1") && e.contains("field `y`"), "{e}");

    let text = "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\nproperty float nx\nend_header\n1 2 3 0\n";
    let (_d, p) = write(text.as_bytes());
    let e = read_ply(&p).unwrap_err().to_string();
    assert!(e.contains("ny, nz") && e.contains("only part"), "{e}");

    let (_d, p) = write(b"not a ply\n");
    let e = read_ply(&p).unwrap_err().to_string();
    assert!(e.contains("cloud.ply") && e.contains("header"), "{e}");
}

#[test]
fn faces_before_vertices_are_skipped() {
    let text = "ply\nformat ascii 1.0\nelement face 1\nproperty list uchar int vertex_indices\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\nend_header\n3 0 1 2\n7 8 9\n";
    let (_d, p) = write(text.as_bytes());
    assert_eq!(
        read_ply(&p).unwrap().positions,
        vec![DVec3::new(7.0, 8.0, 9.0)]
    );
}
