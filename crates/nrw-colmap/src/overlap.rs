//! What multi-view stereo needs from a sparse model before it matches a pixel: for each image,
//! the source images it is matched against and the depth range it searches. Both follow
//! COLMAP 3.8's `mvs::Model` (`GetMaxOverlappingImages`, `ComputeSharedPoints`,
//! `ComputeTriangulationAngles`, `ComputeDepthRanges`), which `patch_match_stereo` uses for
//! `__auto__` source images, with two deliberate differences: the geometry is f64 (COLMAP's is
//! f32), and ties in the shared-point count are broken by image id (COLMAP's `std::sort` leaves
//! their order to the standard library), so the choice is the same on every machine.

use std::collections::BTreeMap;

use glam::DVec3;

use crate::model::Reconstruction;

/// COLMAP's percentile of a pair's triangulation angles that must reach the minimum angle.
pub const ANGLE_PERCENTILE: f64 = 75.0;

/// COLMAP's `__auto__` defaults in `patch-match.cfg`: 20 source images, 1° minimum angle.
pub const DEFAULT_SOURCES: usize = 20;
/// See [`DEFAULT_SOURCES`].
pub const DEFAULT_MIN_ANGLE_DEG: f64 = 1.0;

/// The angle (radians, at most π/2) between the rays from two camera centres to a point:
/// COLMAP's `CalculateTriangulationAngle` (the smaller of the angle and its supplement), here
/// from atan2 of the cross and dot products, which stays exact for the near-parallel rays of
/// distant points where the law of cosines loses every digit.
pub fn triangulation_angle(centre1: DVec3, centre2: DVec3, point: DVec3) -> f64 {
    let (a, b) = (point - centre1, point - centre2);
    if a == DVec3::ZERO || b == DVec3::ZERO {
        return 0.0;
    }
    let angle = a.cross(b).length().atan2(a.dot(b));
    angle.min(std::f64::consts::PI - angle)
}

/// COLMAP's `Percentile`: the element at rank round(p / 100 × (n − 1)) of the sorted values.
fn percentile(values: &mut [f64], p: f64) -> f64 {
    let last = values.len() - 1;
    let rank = ((p / 100.0 * last as f64).round() as usize).min(last);
    values.sort_unstable_by(f64::total_cmp);
    values[rank]
}

/// For every registered image (by id), up to `max` other images that share the most sparse
/// points with it, among those whose 75th-percentile triangulation angle over the shared
/// points is at least `min_angle_deg`; most shared points first, ties by image id. One image
/// at a time: the angles of every pair at once would be Σ track length² values.
pub fn source_images(
    rec: &Reconstruction,
    max: usize,
    min_angle_deg: f64,
) -> BTreeMap<u32, Vec<u32>> {
    let ids: Vec<u32> = rec.images.keys().copied().collect();
    let centres: Vec<DVec3> = rec
        .images
        .values()
        .map(|im| im.cam_from_world.centre())
        .collect();
    let mut seen: Vec<Vec<u64>> = vec![Vec::new(); ids.len()];
    for p in rec.points.values() {
        for e in &p.track {
            if let Ok(i) = ids.binary_search(&e.image_id) {
                seen[i].push(p.id);
            }
        }
    }
    let mut pairs = PairAngles::new(ids.len());
    let min_angle = min_angle_deg.to_radians();
    (0..ids.len())
        .map(|a| {
            seen[a].sort_unstable();
            seen[a].dedup();
            for id in &seen[a] {
                pairs.add_point(&ids, &centres, a, &rec.points[id]);
            }
            (ids[a], pairs.drain_ranked(&ids, max, min_angle))
        })
        .collect()
}

/// The triangulation angles of one image's points with each other image, by image index:
/// lists kept between images so that their memory is reused, not made again.
struct PairAngles {
    lists: Vec<Vec<f64>>,
    touched: Vec<usize>,
}

impl PairAngles {
    fn new(images: usize) -> PairAngles {
        PairAngles {
            lists: vec![Vec::new(); images],
            touched: Vec::new(),
        }
    }

    /// Adds point `p`'s angle with image `a` to each other image of its track, once for each
    /// pair of observations (an image that sees a point twice counts twice, as in COLMAP).
    fn add_point(&mut self, ids: &[u32], centres: &[DVec3], a: usize, p: &crate::model::Point3D) {
        let times = p.track.iter().filter(|e| e.image_id == ids[a]).count();
        for e in &p.track {
            let Ok(b) = ids.binary_search(&e.image_id) else {
                continue;
            };
            if b == a {
                continue;
            }
            let angle = triangulation_angle(centres[a], centres[b], p.xyz);
            if self.lists[b].is_empty() {
                self.touched.push(b);
            }
            self.lists[b].extend(std::iter::repeat_n(angle, times));
        }
    }

    /// The other images that pass the angle test, most shared points first (ties by id), at
    /// most `max`; the lists are emptied for the next image.
    fn drain_ranked(&mut self, ids: &[u32], max: usize, min_angle: f64) -> Vec<u32> {
        let mut ranked: Vec<(u32, usize)> = Vec::with_capacity(self.touched.len());
        for &b in &self.touched {
            let list = &mut self.lists[b];
            let shared = list.len();
            if percentile(list, ANGLE_PERCENTILE) >= min_angle {
                ranked.push((ids[b], shared));
            }
            list.clear();
        }
        self.touched.clear();
        ranked.sort_by(|x, y| y.1.cmp(&x.1).then(x.0.cmp(&y.0)));
        ranked.into_iter().take(max).map(|(b, _)| b).collect()
    }
}

/// For every registered image (by id), the depth range its stereo search covers: COLMAP's
/// `ComputeDepthRanges` — the 1st and 99th percentile of its sparse points' depths (ranks
/// ⌊0.01 n⌋ and ⌊0.99 n⌋ of the positive depths), stretched to 0.75× and 1.25×; `None` for an
/// image that sees no point in front of it (COLMAP writes −1, −1).
pub fn depth_ranges(rec: &Reconstruction) -> BTreeMap<u32, Option<(f64, f64)>> {
    let mut depths: BTreeMap<u32, Vec<f64>> =
        rec.images.keys().map(|&id| (id, Vec::new())).collect();
    for p in rec.points.values() {
        for e in &p.track {
            let (Some(im), Some(list)) = (rec.images.get(&e.image_id), depths.get_mut(&e.image_id))
            else {
                continue;
            };
            let z = im.cam_from_world.transform(p.xyz).z;
            if z > 0.0 {
                list.push(z);
            }
        }
    }
    depths
        .into_iter()
        .map(|(id, mut d)| {
            if d.is_empty() {
                return (id, None);
            }
            d.sort_unstable_by(f64::total_cmp);
            let at = |q: f64| d[((d.len() as f64 * q) as usize).min(d.len() - 1)];
            (id, Some((at(0.01) * 0.75, at(0.99) * 1.25)))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::{Image, Point3D, TrackElement};
    use crate::pose::Rigid3;

    /// Cameras on the x axis at `xs`, looking down +z, with `points` seen by the listed images.
    fn scene(xs: &[f64], points: &[(DVec3, &[u32])]) -> Reconstruction {
        let mut rec = Reconstruction::default();
        for (i, &x) in xs.iter().enumerate() {
            let id = i as u32 + 1;
            let (pose, _) = Rigid3::from_colmap([1.0, 0.0, 0.0, 0.0], [-x, 0.0, 0.0]).unwrap();
            rec.images.insert(
                id,
                Image {
                    id,
                    name: format!("{id}.jpg"),
                    camera_id: 1,
                    cam_from_world: pose,
                    stored_quat_norm: 1.0,
                    points2d: Vec::new(),
                },
            );
        }
        for (k, (xyz, seen)) in points.iter().enumerate() {
            let track = seen
                .iter()
                .map(|&image_id| TrackElement {
                    image_id,
                    point2d_idx: 0,
                })
                .collect();
            rec.points.insert(
                k as u64,
                Point3D {
                    id: k as u64,
                    xyz: *xyz,
                    rgb: [0; 3],
                    error: 0.0,
                    track,
                },
            );
        }
        rec
    }

    #[test]
    fn sources_rank_by_shared_points_drop_narrow_baselines_and_break_ties_by_id() {
        // Image 2 sits 1 mm beside image 1: many shared points, but a baseline too narrow.
        let xs = [0.0, 0.001, 1.0, -1.0, 2.0];
        let p = |x| DVec3::new(x, 0.0, 10.0);
        let pts: Vec<(DVec3, &[u32])> = vec![
            (p(0.0), &[1, 2, 3, 4]),
            (p(0.1), &[1, 2, 3, 4, 5]),
            (p(0.2), &[1, 2, 3]),
            (p(0.3), &[1, 2, 5]),
        ];
        let s = source_images(&scene(&xs, &pts), 20, 1.0);
        // 3 shares 3 points with 1, 4 and 5 share 2 (tie: id order); 2 is too close.
        assert_eq!(s[&1], vec![3, 4, 5]);
        assert_eq!(source_images(&scene(&xs, &pts), 2, 1.0)[&1], vec![3, 4]);
        // With no minimum angle, the close image wins on shared points.
        assert_eq!(source_images(&scene(&xs, &pts), 1, 0.0)[&1], vec![2]);
    }

    #[test]
    fn far_from_origin_coordinates_give_the_same_choice_and_angles() {
        let xs = [0.0, 0.3, 1.0];
        let pts: Vec<(DVec3, &[u32])> = (0..5)
            .map(|k| (DVec3::new(k as f64 * 0.1, 0.0, 8.0), &[1, 2, 3][..]))
            .collect();
        let near = scene(&xs, &pts);
        // The same scene moved 5,000 km away (UTM-sized coordinates).
        let off = DVec3::new(4.5e6, 5.2e6, 300.0);
        let far_pts: Vec<(DVec3, &[u32])> = pts.iter().map(|(x, s)| (*x + off, *s)).collect();
        let far_xs: Vec<f64> = xs.to_vec();
        let mut far = scene(&far_xs, &far_pts);
        for im in far.images.values_mut() {
            let c = im.cam_from_world.centre() + off;
            let (pose, _) = Rigid3::from_colmap([1.0, 0.0, 0.0, 0.0], (-c).to_array()).unwrap();
            im.cam_from_world = pose;
        }
        assert_eq!(source_images(&near, 20, 1.0), source_images(&far, 20, 1.0));
        let (a, b) = (depth_ranges(&near), depth_ranges(&far));
        for id in 1..=3 {
            let ((n0, n1), (f0, f1)) = (a[&id].unwrap(), b[&id].unwrap());
            assert!((n0 - f0).abs() < 1e-8 && (n1 - f1).abs() < 1e-8, "{id}");
        }
        // A 1 mm baseline at 8 m, 5,000 km from the origin: 1.25e-4 rad to the digits the
        // baseline keeps at that offset (1e-6 relative). acos of the law of cosines resolves
        // angles near 0 only to about 1.5e-8 rad (1e-4 relative) here.
        let t = triangulation_angle(off, off + DVec3::X * 1e-3, off + DVec3::Z * 8.0);
        assert!((t / (1e-3f64 / 8.0).atan() - 1.0).abs() < 1e-5, "{t}");
    }

    #[test]
    fn depth_ranges_are_colmaps_stretched_percentiles_and_none_behind() {
        // 200 points at depths 1..=200 in front of image 1; image 2 sees one point behind it.
        let pts: Vec<(DVec3, &[u32])> = (1..=200)
            .map(|z| (DVec3::new(0.0, 0.0, z as f64), &[1][..]))
            .chain([(DVec3::new(0.0, 0.0, -5.0), &[2][..])])
            .collect();
        let r = depth_ranges(&scene(&[0.0, 0.0], &pts));
        // Ranks ⌊2⌋ and ⌊198⌋ of the sorted depths 1..200: 3 and 199.
        assert_eq!(r[&1], Some((3.0 * 0.75, 199.0 * 1.25)));
        assert_eq!(r[&2], None);
        // One point: both ends are it.
        let one = depth_ranges(&scene(&[0.0], &[(DVec3::new(0.0, 0.0, 4.0), &[1][..])]));
        assert_eq!(one[&1], Some((3.0, 5.0)));
    }

    #[test]
    fn an_image_with_no_shared_point_has_no_source_and_a_bad_track_is_skipped() {
        // Point 0's track names image 9, which is not in the model; image 3 shares nothing.
        let pts: Vec<(DVec3, &[u32])> = vec![(DVec3::new(0.0, 0.0, 5.0), &[1, 2, 9, 2])];
        let s = source_images(&scene(&[0.0, 1.0, 2.0], &pts), 20, 1.0);
        assert_eq!(s[&1], vec![2]);
        assert_eq!(s[&3], Vec::<u32>::new());
    }
}
