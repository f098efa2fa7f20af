//! Renders against ground truth (synthetic scenes), against COLMAP's own observations (real
//! scene), and on the hard cases.

#[path = "../../../tests/support/shared.rs"]
mod shared;

use std::path::{Path, PathBuf};

use glam::{DQuat, DVec2, DVec3, Vec3};
use nrw_colmap::{read_model, read_ply, read_scene, Camera, CameraModel, Format, Image, Rigid3};
use nrw_dataset::depth::read_exr;
use nrw_render::{render, render_with, Chunk, Kernel, RenderCloud, View};
use nrw_synth::{generate, SceneSpec};

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

fn synth(name: &str, edit: impl Fn(&mut SceneSpec)) -> tempfile::TempDir {
    let text = std::fs::read_to_string(root().join("scenes").join(format!("{name}.toml"))).unwrap();
    // Dense enough that neighbouring points are about a pixel apart at these sizes.
    let mut s = SceneSpec::from_toml(&text, name)
        .unwrap()
        .shrunk(3, (120, 150), 400_000);
    s.observations.features = 300;
    s.effects.transients = None;
    edit(&mut s);
    let dir = tempfile::tempdir().unwrap();
    generate(&s, dir.path(), &|| {}).unwrap();
    dir
}

/// (covered pixels, within 1% of true depth, median relative error) over a scene's photos,
/// rendered at photo size with radius `r`, on pixels whose true label is in `classes`.
fn depth_vs_truth(dir: &Path, r: f32, classes: &[u8]) -> (usize, usize, f64) {
    let rec = read_model(&dir.join("sparse/0"), Some(Format::Binary)).unwrap();
    let cloud = read_ply(&dir.join("dense/fused.ply")).unwrap();
    let origin = rec.scene_origin();
    let rc = RenderCloud::from_ply(origin, &cloud);
    let mut errs = Vec::new();
    for img in rec.images.values() {
        let cam = &rec.cameras[&img.camera_id];
        let view = View::new(img, cam, origin, cam.width as u32, cam.height as u32, r);
        let buf = render(&view, &rc);
        let stem = Path::new(&img.name).with_extension("");
        let truth = read_exr(
            &dir.join("ground_truth/depth")
                .join(format!("{}.exr", stem.display())),
        )
        .unwrap();
        let labels = image::open(
            dir.join("ground_truth/semantics")
                .join(format!("{}.png", stem.display())),
        )
        .unwrap()
        .to_luma8();
        for ((d, t), l) in buf.depth.iter().zip(&truth.data).zip(labels.as_raw()) {
            if *d > 0.0 && *t > 0.0 && classes.contains(l) {
                errs.push(((d - t) / t).abs() as f64);
            }
        }
    }
    let within = errs.iter().filter(|e| **e <= 0.01).count();
    errs.sort_by(|a, b| a.partial_cmp(b).unwrap());
    (errs.len(), within, errs[errs.len() / 2])
}

#[test]
fn rendered_depth_matches_true_depth_on_covered_pixels() {
    // Tolerances (landmark pixels: building, windows, columns), measured and then fixed:
    // (scene, splat radius, max median relative error, min fraction within 1%).
    // A splat gives its point's depth to pixels up to r away, where depth differs on
    // oblique faces (fisheye pixels span more of the scene, so more so); where a surface's
    // points leave a gap, a farther point shows through (more so at r = 0). The ground,
    // seen at grazing angles, is reported, not bounded.
    let cases = [
        ("demo", 1.0, 0.003, 0.80),
        ("demo", 0.0, 0.003, 0.60),
        ("fisheye", 0.0, 0.006, 0.70),
        ("fisheye", 1.0, 0.015, 0.45),
    ];
    let mut dirs = std::collections::BTreeMap::new();
    for (name, r, max_median, min_within) in cases {
        let dir = dirs.entry(name).or_insert_with(|| synth(name, |_| {}));
        let (covered, within, median) = depth_vs_truth(dir.path(), r, &[2, 9, 43]);
        let ground = depth_vs_truth(dir.path(), r, &[12]);
        eprintln!("{name} r={r}: landmark {within} of {covered} within 1%, median {median:.5}; ground {} of {}, median {:.5}", ground.1, ground.0, ground.2);
        assert!(covered > 3_000, "{name}: {covered}");
        assert!(
            median < max_median,
            "{name} r={r}: median relative depth error {median}"
        );
        assert!(
            within as f64 > min_within * covered as f64,
            "{name} r={r}: {within} of {covered} within 1%"
        );
    }
}

#[test]
fn a_georeferenced_scene_renders_like_the_centred_one() {
    let near = synth("demo", |_| {});
    let far = synth("demo", |s| s.geometry.origin = [5.0e6, 5.0e6, 120.0]);
    let render_all = |dir: &Path| {
        let rec = read_model(&dir.join("sparse/0"), Some(Format::Binary)).unwrap();
        let cloud = read_ply(&dir.join("dense/fused.ply")).unwrap();
        let origin = rec.scene_origin();
        let rc = RenderCloud::from_ply(origin, &cloud);
        rec.images
            .values()
            .map(|img| {
                let cam = &rec.cameras[&img.camera_id];
                render(
                    &View::new(img, cam, origin, cam.width as u32, cam.height as u32, 1.0),
                    &rc,
                )
            })
            .collect::<Vec<_>>()
    };
    for (a, b) in render_all(near.path()).iter().zip(render_all(far.path())) {
        // The near scene's cloud is f32 on disk, the far one f64: positions differ by f32
        // rounding of the near one (< 1e-6 relative), so a few splats may flip at edges.
        let differ = a
            .depth
            .iter()
            .zip(&b.depth)
            .filter(|(x, y)| (**x > 0.0) != (**y > 0.0))
            .count();
        assert!(
            differ * 1000 < a.depth.len(),
            "{differ} pixels changed coverage"
        );
        let both: Vec<f32> = a
            .depth
            .iter()
            .zip(&b.depth)
            .filter(|(x, y)| **x > 0.0 && **y > 0.0)
            .map(|(x, y)| ((x - y) / x).abs())
            .collect();
        let moved = both.iter().filter(|e| **e > 1e-5).count();
        assert!(
            moved * 200 < both.len(),
            "{moved} of {} pixels changed depth by more than 1e-5",
            both.len()
        );
    }
}

#[test]
fn projected_sparse_points_land_on_their_colmap_observations() {
    let Some(_) = shared::shared("data") else {
        return;
    };
    let scene = shared::shared_path("data/sceaux_castle");
    let rec = read_scene(&scene).unwrap();
    let origin = rec.scene_origin();
    let rc = RenderCloud::from_sparse(origin, &rec);
    let views: std::collections::BTreeMap<u32, View> = rec
        .images
        .values()
        .map(|i| {
            let c = &rec.cameras[&i.camera_id];
            (
                i.id,
                View::new(i, c, origin, c.width as u32, c.height as u32, 0.0),
            )
        })
        .collect();
    let (mut sum, mut n) = (0.0, 0usize);
    for p in rec.points.values() {
        let local = (p.xyz - origin).as_vec3();
        for el in &p.track {
            let px = views[&el.image_id]
                .project(local, rc.near)
                .expect("observed point is visible");
            sum += (px - rec.images[&el.image_id].points2d[el.point2d_idx as usize].xy).length();
            n += 1;
        }
    }
    let ours = sum / n as f64;
    let colmap = nrw_colmap::reprojection_stats(&rec).mean_px.unwrap();
    eprintln!(
        "sceaux_castle: {n} observations, renderer {ours:.6} px, COLMAP model {colmap:.6} px"
    );
    // The renderer's path casts to f32 after re-centring: agreement to a thousandth of a pixel.
    assert!(
        (ours - colmap).abs() < 1e-3,
        "renderer {ours} vs model {colmap}"
    );
}

/// The 64 × 48 camera the small tests look through.
fn test_camera(model: CameraModel, params: Vec<f64>) -> Camera {
    Camera {
        id: 1,
        model,
        width: 64,
        height: 48,
        params,
    }
}

fn test_view(model: CameraModel, params: Vec<f64>) -> (View, Image) {
    let cam = test_camera(model, params);
    let img = Image {
        id: 1,
        name: "t".into(),
        camera_id: 1,
        cam_from_world: Rigid3::IDENTITY,
        stored_quat_norm: 1.0,
        points2d: vec![],
    };
    (View::new(&img, &cam, DVec3::ZERO, 64, 48, 1.0), img)
}

fn cloud_of(points: &[DVec3]) -> RenderCloud {
    let colors = vec![[200, 100, 50]; points.len()];
    let mut c = RenderCloud::new(DVec3::ZERO, points, Some(&colors), None);
    c.near = 1e-4;
    c
}

#[test]
fn points_on_or_behind_the_camera_plane_are_never_drawn() {
    let (view, _) = test_view(CameraModel::Pinhole, vec![50.0, 50.0, 32.0, 24.0]);
    let pts = [
        DVec3::new(0.0, 0.0, 0.0),
        DVec3::new(0.01, 0.0, 1e-7),
        DVec3::new(0.0, 0.0, -1.0),
        DVec3::new(0.3, 0.2, -2.0),
    ];
    let buf = render(&view.with_radius(1.0), &cloud_of(&pts));
    assert_eq!(buf.covered, 0);
    let buf = render(
        &view.with_radius(0.0),
        &cloud_of(&[DVec3::new(0.0, 0.0, 2.0)]),
    );
    assert_eq!(buf.covered, 1);
    assert_eq!(buf.depth[24 * 64 + 32], 2.0);
}

#[test]
fn fisheye_points_beyond_90_degrees_are_not_drawn() {
    let (view, _) = test_view(
        CameraModel::OpenCvFisheye,
        vec![20.0, 20.0, 32.0, 24.0, 0.0, 0.0, 0.0, 0.0],
    );
    let at = |deg: f64| {
        let a = deg.to_radians();
        DVec3::new(a.sin(), 0.0, a.cos()) * 3.0
    };
    assert_eq!(
        render(&view.with_radius(0.0), &cloud_of(&[at(95.0)])).covered,
        0
    );
    assert_eq!(
        render(&view.with_radius(0.0), &cloud_of(&[at(60.0)])).covered,
        1
    );
}

#[test]
fn a_negative_radial_lens_does_not_fold_far_points_into_the_image() {
    // k = -0.2 folds at tan θ = 1/√0.6 ≈ 1.29 (52°); a point at 61° lands back inside.
    let (view, _) = test_view(CameraModel::SimpleRadial, vec![30.0, 32.0, 24.0, -0.2]);
    let a = 61f64.to_radians();
    let p = DVec3::new(a.sin(), 0.0, a.cos());
    assert!(
        view.camera
            .img_from_cam(p)
            .is_some_and(|px| px.x > 0.0 && px.x < 64.0),
        "COLMAP's projection folds it in"
    );
    assert_eq!(render(&view.with_radius(0.0), &cloud_of(&[p])).covered, 0);
}

#[test]
fn one_point_covers_its_splat_and_an_empty_cloud_covers_nothing() {
    let (view, _) = test_view(CameraModel::Pinhole, vec![50.0, 50.0, 32.0, 24.0]);
    // Projects onto the centre of pixel (32, 24): radius 1.2 covers it and its 4 neighbours
    // (the diagonal ones are √2 away).
    let p = DVec3::new(0.5 / 50.0, 0.5 / 50.0, 1.0);
    let buf = render(&view.with_radius(1.2), &cloud_of(&[p]));
    assert_eq!(buf.covered, 5);
    assert_eq!(buf.color.as_ref().unwrap()[24 * 64 + 32], [200, 100, 50]);
    assert!(
        buf.normal.is_none(),
        "a cloud without normals renders no normal channel"
    );
    let buf = render(&view.with_radius(1.0), &cloud_of(&[]));
    assert_eq!((buf.covered, buf.empty_ratio()), (0, 1.0));
    // The cloud's channels are kept (black), so every row of a dataset has the same columns.
    let black = buf
        .color
        .map(|c| c.len() == 64 * 48 && c.iter().all(|p| *p == [0, 0, 0]));
    assert_eq!(black, Some(true));
}

/// The winner at every pixel by the definition: among points whose projection (by
/// `View::project`, the splatter's own arithmetic) is within r of the pixel centre (r = 0: in
/// the pixel), the nearest, then the lowest index; `None` where no point covers the pixel.
fn reference_winners(view: &View, cloud: &RenderCloud, r: f64) -> Vec<Option<usize>> {
    let (w, h) = (view.width as usize, view.height as usize);
    let mut best: Vec<Option<(u32, usize)>> = vec![None; w * h];
    for (i, p) in cloud.positions().enumerate() {
        let Some(px) = view.project(p, cloud.near) else {
            continue;
        };
        let z = (view.rotation * p + view.translation).z;
        for y in 0..h {
            for x in 0..w {
                let (dx, dy) = (x as f64 + 0.5 - px.x, y as f64 + 0.5 - px.y);
                let inside = if r == 0.0 {
                    px.x.floor() as usize == x
                        && px.y.floor() as usize == y
                        && px.x >= 0.0
                        && px.y >= 0.0
                } else {
                    dx * dx + dy * dy <= r * r
                };
                let cand = (z.to_bits(), i);
                if inside && best[y * w + x].is_none_or(|b| cand < b) {
                    best[y * w + x] = Some(cand);
                }
            }
        }
    }
    best.into_iter().map(|b| b.map(|(_, i)| i)).collect()
}

#[test]
fn splats_match_their_definition_at_the_border_and_for_wide_radii() {
    use rand::{Rng, SeedableRng};
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
    // Projections over the image and 10 px beyond every border; a few share a pixel.
    let pts: Vec<DVec3> = (0..300)
        .map(|_| {
            let z = rng.random_range(1.0..4.0);
            let (u, v) = (rng.random_range(-10.0..74.0), rng.random_range(-10.0..58.0));
            DVec3::new((u - 32.0) / 50.0 * z, (v - 24.0) / 50.0 * z, z)
        })
        .collect();
    let cloud = indexed_cloud(&pts);
    let (view, _) = test_view(CameraModel::Pinhole, vec![50.0, 50.0, 32.0, 24.0]);
    // The f32 pinhole projection stays within 6e-4 px of COLMAP's f64 one (stated in
    // `view::pinhole_pixel`; here pixels are < 100, so far tighter).
    for p in cloud.positions() {
        let c = view.rotation * p + view.translation;
        let f32_px = view.project(p, cloud.near).unwrap();
        let f64_px = view
            .camera
            .img_from_cam(DVec3::new(c.x as f64, c.y as f64, c.z as f64))
            .unwrap();
        assert!(
            (f32_px - f64_px).abs().max_element() < 6e-4,
            "{f32_px} vs {f64_px}"
        );
    }
    // 0: the point's own pixel; 0.3: reach 0 but a disc; 0.5–2.7: reach 1–3; 6: reach 6.
    assert_definition(&view, &cloud, &[0.0, 0.3, 0.5, 1.0, 1.5, 2.7, 6.0]);
}

/// A cloud whose colour is the point's input index, so a render's winners can be read back.
fn indexed_cloud(pts: &[DVec3]) -> RenderCloud {
    let colors: Vec<[u8; 3]> = (0..pts.len())
        .map(|i| [i as u8, (i >> 8) as u8, 0])
        .collect();
    let mut cloud = RenderCloud::new(DVec3::ZERO, pts, Some(&colors), None);
    cloud.near = 1e-4;
    cloud
}

/// Every pixel's winner, for each radius and both kernels (Auto is AVX2 where the CPU has
/// it), is the definition's (`reference_winners`). Colours must encode point indices.
fn assert_definition(view: &View, cloud: &RenderCloud, radii: &[f32]) {
    let (w, h) = (view.width as usize, view.height as usize);
    for &r in radii {
        let want = reference_winners(view, cloud, r as f64);
        for kernel in [Kernel::Auto, Kernel::Portable] {
            let buf = render_with(&view.with_radius(r), cloud, kernel);
            let color = buf.color.as_ref().unwrap();
            for (px, w_) in want.iter().enumerate() {
                let got = (buf.depth[px] > 0.0).then(|| {
                    let c = color[px];
                    // Colours were permuted with the points by the Morton sort: map back.
                    c[0] as usize | (c[1] as usize) << 8
                });
                let want = w_.map(|i| {
                    let c = cloud.colors.as_ref().unwrap()[i];
                    c[0] as usize | (c[1] as usize) << 8
                });
                let at = (px % w, px / w);
                assert_eq!(got, want, "r = {r}, {kernel:?}, pixel {at:?}");
            }
            assert_eq!(buf.covered, want.iter().flatten().count(), "r = {r}");
            assert_eq!(buf.depth.len(), w * h);
        }
    }
}

#[test]
fn splats_on_exact_pixel_boundaries_follow_the_definition() {
    use rand::{Rng, SeedableRng};
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(9);
    // f = 128, c = (32, 24), depths powers of two: every projection is exactly a pixel
    // corner, edge midpoint or centre, so pixel centres lie exactly at distance r (for r a
    // multiple of 0.5) and points exactly on pixel edges: the ≤ and the floor are tested
    // where a rounding slip would show.
    let pts: Vec<DVec3> = (0..600)
        .map(|_| {
            let z = [0.5, 1.0, 2.0, 4.0][rng.random_range(0..4usize)];
            let (m, n) = (rng.random_range(-72..=72), rng.random_range(-56..=56));
            DVec3::new(m as f64 / 256.0 * z, n as f64 / 256.0 * z, z)
        })
        .collect();
    let cloud = indexed_cloud(&pts);
    let (view, _) = test_view(CameraModel::Pinhole, vec![128.0, 128.0, 32.0, 24.0]);
    for p in cloud.positions() {
        let px = view.project(p, cloud.near).unwrap();
        assert_eq!(
            (px * 2.0).round(),
            px * 2.0,
            "{px} is on the half-pixel lattice"
        );
    }
    assert_definition(&view, &cloud, &[0.0, 0.5, 1.0, 1.5, 2.0, 2.5]);
}

#[test]
fn the_kernels_render_bit_for_bit_alike() {
    use rand::{Rng, SeedableRng};
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
    // A box around and behind a tilted camera: points off-image, at the border, on and
    // behind the camera plane; every 50th point duplicated (equal depths, index decides).
    let mut pts: Vec<DVec3> = (0..200_000)
        .map(|_| {
            DVec3::new(
                rng.random_range(-4.0..4.0),
                rng.random_range(-3.0..3.0),
                rng.random_range(-1.0..9.0),
            )
        })
        .collect();
    let dups: Vec<DVec3> = pts.iter().step_by(50).copied().collect();
    pts.extend(dups);
    let colors: Vec<[u8; 3]> = (0..pts.len())
        .map(|i| [i as u8, (i >> 8) as u8, 7])
        .collect();
    let normals: Vec<[f32; 3]> = (0..pts.len()).map(|i| [1.0, i as f32, 0.0]).collect();
    let cloud = RenderCloud::new(DVec3::ZERO, &pts, Some(&colors), Some(&normals));
    // Undistorted (f32 projection), and lenses with distortion (COLMAP's f64 projection),
    // including a fisheye that sees beyond 90°.
    let cams = [
        (CameraModel::Pinhole, vec![260.0, 250.0, 161.3, 118.9]),
        (CameraModel::SimpleRadial, vec![255.0, 161.3, 118.9, -0.12]),
        (
            CameraModel::OpenCv,
            vec![260.0, 250.0, 161.3, 118.9, -0.1, 0.02, 0.001, -0.002],
        ),
        (
            CameraModel::OpenCvFisheye,
            vec![120.0, 118.0, 161.3, 118.9, 0.05, -0.01, 0.002, 0.0],
        ),
    ];
    let img = Image {
        id: 1,
        name: "t".into(),
        camera_id: 1,
        cam_from_world: Rigid3 {
            rotation: DQuat::from_euler(glam::EulerRot::XYZ, 0.2, -0.3, 0.1),
            translation: DVec3::new(0.3, -0.2, 0.5),
        },
        stored_quat_norm: 1.0,
        points2d: vec![],
    };
    for (model, params) in cams {
        let cam = Camera {
            id: 1,
            model,
            width: 320,
            height: 240,
            params,
        };
        for r in [0.0f32, 0.3, 0.6, 1.0, 1.3, 2.0, 3.0, 7.5, 32.0] {
            let view = View::new(&img, &cam, DVec3::ZERO, 320, 240, r);
            let a = render_with(&view, &cloud, Kernel::Auto);
            let b = render_with(&view, &cloud, Kernel::Portable);
            assert!(
                a.covered > 1000,
                "{model:?}, r = {r}: the scene covers the view"
            );
            assert!(a == b, "{model:?}, r = {r}: kernels differ");
        }
    }
}

#[test]
fn nearest_point_wins_and_ties_go_to_the_lower_index() {
    let (view, _) = test_view(CameraModel::Pinhole, vec![50.0, 50.0, 32.0, 24.0]);
    let colors = [[1, 1, 1], [2, 2, 2], [3, 3, 3]];
    let pts = [
        DVec3::new(0.0, 0.0, 3.0),
        DVec3::new(0.0, 0.0, 2.0),
        DVec3::new(0.0, 0.0, 2.0),
    ];
    let mut c = RenderCloud::new(DVec3::ZERO, &pts, Some(&colors), None);
    c.near = 1e-4;
    let buf = render(&view.with_radius(0.0), &c);
    let got = buf.color.unwrap()[24 * 64 + 32];
    // Both depth-2 points tie; the Morton sort keeps input order for equal positions.
    assert_eq!(got, [2, 2, 2]);
}

#[test]
fn chunk_culling_changes_nothing() {
    let dir = synth("demo", |s| s.cameras.count = 2);
    let rec = read_model(&dir.path().join("sparse/0"), Some(Format::Binary)).unwrap();
    let cloud = read_ply(&dir.path().join("dense/fused.ply")).unwrap();
    let origin = rec.scene_origin();
    let culled = RenderCloud::from_ply(origin, &cloud);
    let whole = one_chunk(&culled);
    for img in rec.images.values() {
        let cam = &rec.cameras[&img.camera_id];
        let v = View::new(
            img,
            cam,
            origin,
            300,
            300 * cam.height as u32 / cam.width as u32,
            2.0,
        );
        let (a, b) = (render(&v, &culled), render(&v, &whole));
        assert!(a.chunks_visited < culled.chunks.len(), "some chunks culled");
        assert_eq!((a.depth, a.color), (b.depth, b.color));
    }
}

/// The cloud as one chunk: nothing is culled by frustum, and nothing by occlusion (every
/// point's depth is at least the chunk's least, so no drawn point can hide the chunk).
fn one_chunk(cloud: &RenderCloud) -> RenderCloud {
    let mut whole = cloud.clone();
    let (lo, hi) = whole
        .chunks
        .iter()
        .fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(l, h), c| {
            (l.min(c.min), h.max(c.max))
        });
    whole.chunks = vec![Chunk {
        start: 0,
        end: whole.len() as u32,
        min: lo,
        max: hi,
    }];
    whole
}

/// A cloud whose chunks are the given groups of points, in order (no Morton sort), with
/// colours encoding point indices.
fn grouped_cloud(groups: &[Vec<DVec3>]) -> RenderCloud {
    let mut cloud = RenderCloud {
        near: 1e-4,
        ..Default::default()
    };
    let mut colors = Vec::new();
    for g in groups {
        let start = cloud.len() as u32;
        let (mut lo, mut hi) = (Vec3::INFINITY, Vec3::NEG_INFINITY);
        for p in g {
            let p = p.as_vec3();
            (lo, hi) = (lo.min(p), hi.max(p));
            for (axis, v) in cloud.xyz.iter_mut().zip(p.to_array()) {
                axis.push(v);
            }
            let i = colors.len();
            colors.push([i as u8, (i >> 8) as u8, (i >> 16) as u8]);
        }
        let end = cloud.len() as u32;
        cloud.chunks.push(Chunk {
            start,
            end,
            min: lo,
            max: hi,
        });
    }
    cloud.colors = Some(colors);
    cloud
}

#[test]
fn occlusion_culling_changes_nothing() {
    // Through each lens, points placed by pixel: a front patch at 3 m with 12 points at every
    // pixel centre of x 4..=59, y 4..=43 (dense enough for culling to run); behind it at
    // 6 m, a chunk in the patch's middle (hidden at every radius), a chunk in the patch's
    // corner pixel whose splats reach the uncovered diagonal neighbour once r >= 1 (culling
    // that forgot the splat's reach would drop it), and a chunk in the image's corner, clear
    // of the patch, that strong distortion (k > 0) moves there from behind the patch
    // (culling that bounded the undistorted position would drop it).
    let cams = [
        (CameraModel::Pinhole, vec![50.0, 50.0, 32.0, 24.0]),
        (CameraModel::SimpleRadial, vec![50.0, 32.0, 24.0, 0.5]),
        (CameraModel::Radial, vec![50.0, 32.0, 24.0, 0.1, 1.5]),
    ];
    for (model, params) in cams {
        let cam = test_camera(model, params.clone());
        let (_, img) = test_view(model, params);
        let at = |x: f64, y: f64, z: f64| {
            let ray = cam.cam_ray_from_img(DVec2::new(x, y)).unwrap();
            ray / ray.z * z
        };
        let front: Vec<DVec3> = (4..=43)
            .flat_map(|y| (4..=59).map(move |x| (x as f64 + 0.5, y as f64 + 0.5)))
            .flat_map(|(x, y)| (0..12).map(move |k| (x, y, 3.0 + 0.001 * k as f64)))
            .map(|(x, y, z)| at(x, y, z))
            .collect();
        let grid = |x0: f64, x1: f64, y0: f64, y1: f64| -> Vec<DVec3> {
            (0..100)
                .map(|i| {
                    let (a, b) = ((i % 10) as f64 / 9.0, (i / 10) as f64 / 9.0);
                    at(x0 + a * (x1 - x0), y0 + b * (y1 - y0), 6.0)
                })
                .collect()
        };
        let middle = grid(20.0, 40.0, 15.0, 30.0);
        let corner = grid(59.05, 59.95, 43.05, 43.95);
        let image_corner = grid(62.05, 62.95, 46.05, 46.95);
        let behind = middle.len();
        let cloud = grouped_cloud(&[front, middle, corner, image_corner]);
        let whole = one_chunk(&cloud);
        for r in [0.0f32, 1.0, 1.5] {
            let view = View::new(&img, &cam, DVec3::ZERO, 64, 48, r);
            let want = render_with(&view, &whole, Kernel::Portable);
            assert_eq!(want.points_hidden, 0);
            for kernel in [Kernel::Auto, Kernel::Portable] {
                let got = render_with(&view, &cloud, kernel);
                assert!(
                    got.points_hidden >= behind,
                    "{model:?}, r = {r}, {kernel:?}: the middle chunk is hidden ({} points)",
                    got.points_hidden
                );
                assert!(
                    got.depth == want.depth && got.color == want.color,
                    "{model:?}, r = {r}, {kernel:?}: culling changed the render"
                );
            }
        }
    }
}
