//! The ray-casting test on a real scene: every strategy's tree gives the same occluded count,
//! equal to brute force, and the golden count of the spec's sampling (seed 1).

use hirad::cluster::{ClusterConfig, ClusterTree, Strategy};
use hirad::ray::sample::sample_segments;
use hirad::ray::RayCaster;
use hirad::scene::{Scene, SceneOptions};

const GRAZ: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../../../shared/scenes/graz_office/graz_office.obj"
);

#[test]
fn graz_office_counts_identical_across_strategies() {
    let scene = Scene::load(GRAZ, &SceneOptions::default()).unwrap();
    assert_eq!(scene.num_triangles(), 26_928);
    let segs = sample_segments(&scene, 20_000, 1);
    let mut counts = Vec::new();
    for st in Strategy::ALL {
        let tree = ClusterTree::build(&scene, st, &ClusterConfig::default());
        let rc = RayCaster::new(&scene, &tree);
        let occ = rc.count_occluded(&segs);
        // Closest hits exist exactly for the occluded segments.
        let hits = rc.closest_batch(&segs[..2000]);
        let occ_first = rc.occluded_batch(&segs[..2000]);
        for (h, o) in hits.iter().zip(&occ_first) {
            assert_eq!(h.is_some(), *o);
        }
        if st == Strategy::Sah {
            // Brute force on a subset (every triangle per segment).
            for s in &segs[..300] {
                assert_eq!(
                    rc.occluded(s.origin, s.dir, s.tmin, s.tmax),
                    rc.occluded_brute(s.origin, s.dir, s.tmin, s.tmax)
                );
                assert_eq!(
                    rc.closest(s.origin, s.dir, s.tmin, s.tmax).map(|h| h.t),
                    rc.closest_brute(s.origin, s.dir, s.tmin, s.tmax)
                        .map(|h| h.t)
                );
            }
        }
        counts.push((st, occ));
    }
    println!("{counts:?}");
    assert!(counts.iter().all(|&(_, c)| c == counts[0].1), "{counts:?}");
    assert_eq!(counts[0].1, GOLDEN_20K);
}

/// Occluded segments among the first 20,000 pairs of seed 1 on graz_office (measured with
/// every strategy and brute force agreeing).
const GOLDEN_20K: u64 = 17_575;

/// The shadow cache: `occluder` with any hint (none, the triangle an earlier ray found, a
/// triangle the ray misses, one that `skip` leaves out) answers as `occluded_except`, and
/// the triangle it names is hit by the ray and not left out.
#[test]
fn occluder_hint_never_changes_the_answer() {
    use hirad::ray::watertight::intersect_triangle;
    let scene = Scene::load(GRAZ, &SceneOptions::default()).unwrap();
    let tree = ClusterTree::build(&scene, Strategy::Proxi, &ClusterConfig::default());
    let rc = RayCaster::new(&scene, &tree);
    let segs = sample_segments(&scene, 4000, 3);
    let n = scene.num_triangles() as u32;
    let mut last = None;
    let (mut blocked, mut from_hint) = (0, 0);
    for (i, s) in segs.iter().enumerate() {
        // Leave out every third triangle for half of the segments.
        let thirds = i % 2 == 0;
        let skip = |t: u32| thirds && t.is_multiple_of(3);
        let range = (s.tmin, s.tmax);
        let want = rc.occluded_except(s.origin, s.dir, range, &skip);
        let found = rc.occluder(s.origin, s.dir, range, &skip, None);
        let hints = [last, Some(i as u32 * 7919 % n), Some(3), Some(n + 5), found];
        for h in hints {
            let got = rc.occluder(s.origin, s.dir, range, &skip, h);
            assert_eq!(got.is_some(), want, "segment {i}, hint {h:?}");
            if let Some(t) = got {
                assert!(!skip(t));
                let v = scene.tri_vertices(t as usize);
                assert!(intersect_triangle(v, s.origin, s.dir, s.tmin, s.tmax).is_some());
                from_hint += (Some(t) == h) as u32;
            }
        }
        blocked += want as u32;
        if found.is_some() {
            last = found;
        }
    }
    assert!(blocked > 1000 && from_hint > 1000, "{blocked} {from_hint}");
}
