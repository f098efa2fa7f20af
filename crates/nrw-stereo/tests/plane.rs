//! Stereo and fusion on views ray-cast from a textured slanted plane, where every pixel's
//! true depth is known in closed form.

use glam::{DMat3, DVec3};
use nrw_stereo::{
    filter, fuse, geometric, photometric, FusionMaps, FusionOptions, FusionView, GrayImage,
    PatchMatchOptions, Pinhole, Source, StereoView, BAND_ROWS,
};

const W: usize = 120;
const H: usize = 90;

/// The plane n · X = c (world), and a texture on it.
struct Plane {
    n: DVec3,
    c: f64,
}

fn hash(i: i64, j: i64) -> f64 {
    let mut x = (i as u64).wrapping_mul(0x9e37_79b9_7f4a_7c15)
        ^ (j as u64).wrapping_mul(0xc2b2_ae3d_27d4_eb4f);
    x ^= x >> 31;
    x = x.wrapping_mul(0xbf58_476d_1ce4_e5b9);
    x ^= x >> 29;
    (x >> 11) as f64 / (1u64 << 53) as f64
}

/// Bilinear value noise with 0.08 m cells (a few pixels at the views' distance).
fn texture(p: DVec3) -> f64 {
    let (u, v) = (p.x / 0.08, p.y / 0.08);
    let (i, j) = (u.floor(), v.floor());
    let (fu, fv) = (u - i, v - j);
    let (i, j) = (i as i64, j as i64);
    let a = hash(i, j) * (1.0 - fu) + hash(i + 1, j) * fu;
    let b = hash(i, j + 1) * (1.0 - fu) + hash(i + 1, j + 1) * fu;
    0.2 + 0.6 * (a * (1.0 - fv) + b * fv)
}

fn lens() -> Pinhole {
    Pinhole {
        fx: 100.0,
        fy: 100.0,
        cx: W as f64 / 2.0,
        cy: H as f64 / 2.0,
    }
}

/// A camera at `centre` looking down +z (world), far from the origin by `offset`.
fn view(plane: &Plane, centre: DVec3) -> (StereoView, Vec<f64>) {
    let k = lens();
    let rotation = DMat3::IDENTITY;
    let translation = -centre;
    let mut data = Vec::with_capacity(W * H);
    let mut depth = Vec::with_capacity(W * H);
    for row in 0..H {
        for col in 0..W {
            // Supersample 3×3 so the image is the pixel's mean, not a point sample.
            let mut acc = 0.0;
            for sy in 0..3 {
                for sx in 0..3 {
                    let u = glam::DVec2::new(
                        col as f64 + (sx as f64 + 0.5) / 3.0,
                        row as f64 + (sy as f64 + 0.5) / 3.0,
                    );
                    let ray = k.ray(u);
                    let t = (plane.c - plane.n.dot(centre)) / plane.n.dot(ray);
                    acc += texture(centre + ray * t);
                }
            }
            data.push((acc / 9.0) as f32);
            let ray = k.pixel_ray(col, row);
            depth.push((plane.c - plane.n.dot(centre)) / plane.n.dot(ray));
        }
    }
    let image = GrayImage {
        width: W,
        height: H,
        data,
    };
    (
        StereoView {
            id: (centre.x * 1000.0) as i64 as u64,
            image,
            lens: k,
            rotation,
            translation,
        },
        depth,
    )
}

fn scene() -> (Vec<StereoView>, Vec<Vec<f64>>) {
    let plane = Plane {
        n: DVec3::new(0.25, 0.1, 1.0).normalize(),
        c: 6.0,
    };
    let mut views = Vec::new();
    let mut truths = Vec::new();
    for x in [-0.6, 0.0, 0.6] {
        let (v, d) = view(&plane, DVec3::new(x, 0.1 * x, 0.0));
        views.push(v);
        truths.push(d);
    }
    (views, truths)
}

/// Whether the true point of each pixel of `views[1]` lies inside both other views (with
/// the window's margin): only there can two sources agree on it.
fn seen_by_both(views: &[StereoView], truth: &[f64]) -> Vec<bool> {
    let margin = 6.0;
    (0..W * H)
        .map(|i| {
            let (x, y) = (i % W, i / W);
            let world = views[1].rotation.transpose()
                * (views[1].lens.pixel_ray(x, y) * truth[i] - views[1].translation);
            [0, 2].iter().all(|&j| {
                let u = views[j]
                    .lens
                    .project(views[j].rotation * world + views[j].translation);
                u.x >= margin
                    && u.y >= margin
                    && u.x <= W as f64 - margin
                    && u.y <= H as f64 - margin
            }) && x >= 5
                && y >= 5
                && x < W - 5
                && y < H - 5
        })
        .collect()
}

/// The share of the kept depths (among `mask`) within `rel` of the truth, and how many.
/// The views `of` as sources, with their depth maps from `depths` in the geometric pass.
fn sources<'a>(
    views: &'a [StereoView],
    of: &[usize],
    depths: Option<&'a [Vec<f32>]>,
) -> Vec<Source<'a>> {
    of.iter()
        .map(|&j| Source {
            view: &views[j],
            depth: depths.map(|d| d[j].as_slice()),
        })
        .collect()
}

fn share_within(depth: &[f32], truth: &[f64], mask: &[bool], rel: f64) -> (f64, usize) {
    let kept: Vec<(f32, f64)> = depth
        .iter()
        .zip(truth)
        .zip(mask)
        .filter(|((d, _), m)| **d > 0.0 && **m)
        .map(|((d, t), _)| (*d, *t))
        .collect();
    let good = kept
        .iter()
        .filter(|(d, t)| ((*d as f64 - t) / t).abs() <= rel)
        .count();
    (good as f64 / kept.len().max(1) as f64, kept.len())
}

#[test]
fn a_textured_plane_gets_its_depth_within_one_percent() {
    let (views, truths) = scene();
    let opts = PatchMatchOptions::default();
    let range = (3.0, 12.0);
    let sources: Vec<Source> = sources(&views, &[0, 2], None);
    let state = photometric(&views[1], &sources, range, &opts).expect("has sources");
    let maps = filter(&views[1], &sources, range, &state, false, &opts);
    let both = seen_by_both(&views, &truths[1]);
    let seen = both.iter().filter(|b| **b).count();
    let (share, kept) = share_within(&maps.depth, &truths[1], &both, 0.01);
    eprintln!(
        "photometric: {kept} of the {seen} pixels both sources see kept, {share:.4} within 1%"
    );
    assert!(kept as f64 > 0.8 * seen as f64, "only {kept} pixels kept");
    assert!(share >= 0.95, "only {share} of kept depths within 1%");
}

#[test]
fn the_geometric_pass_keeps_what_agrees_and_fusion_puts_points_on_the_plane() {
    let (views, truths) = scene();
    let opts = PatchMatchOptions {
        scales: 1,
        ..PatchMatchOptions::default()
    };
    let range = (3.0, 12.0);
    let others = |i: usize| -> Vec<usize> { (0..3).filter(|&j| j != i).collect() };
    let photo: Vec<Vec<f32>> = (0..3)
        .map(|i| {
            let s: Vec<Source> = sources(&views, &others(i), None);
            photometric(&views[i], &s, range, &opts).unwrap().depth
        })
        .collect();
    let mut maps = Vec::new();
    for i in 0..3 {
        let s: Vec<Source> = sources(&views, &others(i), Some(&photo));
        let start = photometric(&views[i], &s, range, &opts).unwrap();
        let refined = geometric(&views[i], &s, range, start, &opts);
        maps.push(filter(&views[i], &s, range, &refined, true, &opts));
    }
    let both = seen_by_both(&views, &truths[1]);
    let (share, kept) = share_within(&maps[1].depth, &truths[1], &both, 0.01);
    eprintln!("geometric: {kept} kept where both sources see, {share:.4} within 1%");
    assert!(share >= 0.97, "{share}");
    let all = vec![true; W * H];
    let (share_all, kept_all) = share_within(&maps[1].depth, &truths[1], &all, 0.01);
    eprintln!("geometric: {kept_all} kept in all, {share_all:.4} within 1%");
    assert!(share_all >= 0.9, "{share_all}");
    assert!(maps[1]
        .confidence
        .iter()
        .all(|c| (c[1] == 0.0) == (c[0] == 0.0)));
    let rgb: Vec<Vec<u8>> = views
        .iter()
        .map(|v| {
            v.image
                .data
                .iter()
                .flat_map(|g| [(g * 255.0) as u8; 3])
                .collect()
        })
        .collect();
    let inputs: Vec<FusionView> = (0..3)
        .map(|i| FusionView {
            lens: views[i].lens,
            rotation: views[i].rotation,
            translation: views[i].translation,
            width: W,
            height: H,
            overlapping: others(i),
        })
        .collect();
    let mut all_maps: Vec<FusionMaps> = (0..3)
        .map(|i| FusionMaps {
            depth: maps[i].depth.clone(),
            normal: maps[i].normal.clone(),
            rgb: rgb[i].clone(),
        })
        .collect();
    let opts = FusionOptions::default();
    let (cloud, roomy) = fuse(&inputs, all_maps.as_mut_slice(), usize::MAX, &opts).unwrap();
    assert_eq!(roomy.bands, 3 * H.div_ceil(BAND_ROWS));
    assert_eq!(
        roomy.reads, roomy.bands,
        "a cache with room reads each band once"
    );
    // A cache with room for one band: the same cloud from more reads, never two bands held.
    let one_band = FusionMaps::bytes_for(W * BAND_ROWS);
    let (tight, stats) = fuse(&inputs, all_maps.as_mut_slice(), one_band, &opts).unwrap();
    eprintln!(
        "cache of one band: {} reads, peak {} bytes",
        stats.reads, stats.peak_bytes
    );
    assert_eq!(tight, cloud);
    assert!(stats.reads > roomy.bands, "{stats:?}");
    assert_eq!(stats.peak_bytes, one_band);
    let n = DVec3::new(0.25, 0.1, 1.0).normalize();
    let off: Vec<f64> = cloud
        .positions
        .iter()
        .map(|p| (n.dot(*p) - 6.0).abs() / p.z)
        .collect();
    let good = off.iter().filter(|e| **e <= 0.01).count();
    eprintln!(
        "fused {} points, {good} within 1% of depth of the plane",
        cloud.positions.len()
    );
    assert!(cloud.positions.len() > 500);
    assert!(good as f64 >= 0.95 * cloud.positions.len() as f64);
    // Every point fused at least min_num_pixels pixels from more than one image.
    assert!(cloud
        .visibility
        .iter()
        .all(|v| !v.is_empty() && v.windows(2).all(|w| w[0] < w[1])));
    let unit_facing: Vec<(bool, bool)> = cloud
        .normals
        .iter()
        .map(|m| {
            let m = DVec3::new(m[0] as f64, m[1] as f64, m[2] as f64);
            ((m.length() - 1.0).abs() < 1e-5, m.dot(-n) > 0.9)
        })
        .collect();
    let facing = unit_facing.iter().filter(|(_, f)| *f).count();
    eprintln!(
        "{} unit normals, {facing} within 26° of the plane's of {}",
        unit_facing.iter().filter(|(u, _)| *u).count(),
        cloud.normals.len()
    );
    assert!(unit_facing.iter().all(|(u, _)| *u));
    // As the positions: two-pixel points (the default) at the views' edges stray.
    assert!(facing as f64 >= 0.95 * cloud.normals.len() as f64);
}

#[test]
fn a_flat_grey_view_gets_no_depth_rather_than_a_guess() {
    let (mut views, _) = scene();
    for v in &mut views {
        v.image.data.iter_mut().for_each(|g| *g = 0.5);
    }
    let opts = PatchMatchOptions::default();
    let sources: Vec<Source> = sources(&views, &[0, 2], None);
    let state = photometric(&views[1], &sources, (3.0, 12.0), &opts).unwrap();
    let maps = filter(&views[1], &sources, (3.0, 12.0), &state, false, &opts);
    assert!(maps.depth.iter().all(|d| *d == 0.0));
    assert!(photometric(&views[1], &[], (3.0, 12.0), &opts).is_none());
}

#[test]
fn the_maps_do_not_depend_on_the_thread_count() {
    let (views, _) = scene();
    let opts = PatchMatchOptions {
        iterations: 2,
        ..PatchMatchOptions::default()
    };
    let sources: Vec<Source> = sources(&views, &[0, 2], None);
    let run = |threads: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| photometric(&views[1], &sources, (3.0, 12.0), &opts).unwrap())
    };
    assert_eq!(run(1), run(3));
}
