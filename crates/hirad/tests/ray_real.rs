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
