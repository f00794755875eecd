//! Unit tests of the traversal layout.

use super::*;
use crate::cluster::{BuildNode, BuildTree, ClusterConfig, Strategy};
use hirad_core::geom::Aabb;
use hirad_scene::{Material, RawScene, SceneOptions};

fn two_tri_scene() -> Scene {
    let raw = RawScene {
        name: "two".into(),
        positions: vec![
            Vec3::ZERO,
            Vec3::X,
            Vec3::Y,
            Vec3::new(0.0, 0.0, 1.0),
            Vec3::new(2.0, 0.0, 1.0),
            Vec3::new(0.0, 2.0, 1.0),
        ],
        triangles: vec![[0, 1, 2], [3, 4, 5]],
        tri_material: vec![0, 0],
        tri_object: vec![0, 0],
        materials: vec![Material::diffuse("m", Vec3::splat(0.5))],
        ..Default::default()
    };
    Scene::from_raw(raw, &SceneOptions::default()).unwrap()
}

/// A scene of `n` separate triangles, triangle `i` with the corners `corners(i)`.
fn tri_scene(name: &str, n: usize, corners: impl Fn(usize) -> [Vec3; 3]) -> Scene {
    let raw = RawScene {
        name: name.into(),
        positions: (0..n).flat_map(&corners).collect(),
        triangles: (0..n as u32)
            .map(|i| [3 * i, 3 * i + 1, 3 * i + 2])
            .collect(),
        tri_material: vec![0; n],
        tri_object: vec![0; n],
        materials: vec![Material::diffuse("m", Vec3::splat(0.5))],
        ..Default::default()
    };
    Scene::from_raw(raw, &SceneOptions::default()).unwrap()
}

/// Corners (min, max) of a random box with corners drawn from `grid`.
fn grid_box(
    g: &mut hirad_core::rng::SplitMix64,
    grid: impl Fn(&mut hirad_core::rng::SplitMix64) -> f32,
) -> (Vec3, Vec3) {
    let a = Vec3::new(grid(g), grid(g), grid(g));
    let b = Vec3::new(grid(g), grid(g), grid(g));
    (a.min(b), a.max(b))
}

/// Unit right triangles in the plane z = 0, two apart along x.
fn row_of_triangles(name: &str, n: usize) -> Scene {
    tri_scene(name, n, |i| {
        let x = i as f32 * 2.0;
        [
            Vec3::new(x, 0.0, 0.0),
            Vec3::new(x + 1.0, 0.0, 0.0),
            Vec3::new(x, 1.0, 0.0),
        ]
    })
}

/// Batch occlusion of segments straight down from `origins`, `t ∈ [0, 2]`.
fn stream_down(rc: &RayCaster, origins: impl Iterator<Item = Vec3>) -> Vec<bool> {
    let segs: Vec<Segment> = origins
        .map(|origin| Segment {
            origin,
            dir: -Vec3::Z,
            tmin: 0.0,
            tmax: 2.0,
        })
        .collect();
    let mut out = vec![false; segs.len()];
    rc.occluded_stream(&segs, &mut out);
    out
}

/// One leaf node of `b` per triangle of `tris`.
fn leaves(b: &mut BuildTree, s: &Scene, tris: std::ops::Range<usize>) -> Vec<u32> {
    tris.map(|i| {
        b.push(BuildNode {
            bbox: s.tri_bbox(i),
            children: vec![],
            surfaces: vec![i as u32],
        })
    })
    .collect()
}

/// A root whose children are one leaf per triangle.
fn one_leaf_per_triangle(s: &Scene) -> ClusterTree {
    let n = s.num_triangles();
    let mut b = BuildTree::default();
    let kids = leaves(&mut b, s, 0..n);
    b.root = b.push(BuildNode {
        bbox: s.bbox,
        children: kids,
        surfaces: vec![],
    });
    ClusterTree::from_build(b, n, Strategy::Sah, ClusterConfig::default())
}

/// Root holding the triangles `own` with one leaf child holding triangle `leaf`.
fn root_and_leaf(scene: &Scene, own: Vec<u32>, leaf: u32) -> ClusterTree {
    let mut b = BuildTree::default();
    let child = b.push(BuildNode {
        bbox: scene.tri_bbox(leaf as usize),
        children: vec![],
        surfaces: vec![leaf],
    });
    b.root = b.push(BuildNode {
        bbox: scene.bbox,
        children: vec![child],
        surfaces: own,
    });
    let n = scene.num_triangles();
    ClusterTree::from_build(b, n, Strategy::Sah, ClusterConfig::default())
}

/// Root holding triangle 1 with one leaf child holding triangle 0.
fn inner_surface_tree(scene: &Scene) -> ClusterTree {
    root_and_leaf(scene, vec![1], 0)
}

#[test]
fn layout_is_depth_first_with_inner_surfaces() {
    let s = two_tri_scene();
    let t = inner_surface_tree(&s);
    for boxes in Boxes::ALL {
        let lay = layout::Layout::new(&s, &t, boxes);
        let l = &lay;
        // The root has a child: one group holding its own triangle (1) and the leaf's box; the
        // leaf is encoded in place and holds triangle 0 in the second packet. With tight boxes
        // the root's triangle has a box of its own in the second lane.
        assert_eq!(l.root, Some(0));
        // One group.
        assert_eq!(l.groups.len(), 1);
        let g = &l.groups[0];
        let (lanes, run) = match boxes {
            Boxes::Tight | Boxes::Nodes => (2, 0b10),
            Boxes::Cluster => (1, 0),
        };
        assert_eq!(
            (
                g.tri_start,
                g.num_tris,
                g.num_groups,
                g.lanes,
                g.run,
                g.eager
            ),
            (0, 1, 1, lanes, run, run as u8)
        );
        assert_eq!(l.packets.len(), 2);
        assert_eq!(l.packets[0].id, [1, u32::MAX, u32::MAX, u32::MAX]);
        assert_eq!(l.packets[1].id, [0, u32::MAX, u32::MAX, u32::MAX]);
        let leaf = g.child[0];
        assert_ne!(leaf & layout::LEAF, 0);
        assert_eq!(layout::leaf_run(leaf), (1, 1));
        let lane1 = match boxes {
            // The run's reference: the group holding it.
            Boxes::Tight | Boxes::Nodes => layout::RUN,
            Boxes::Cluster => layout::NONE,
        };
        assert_eq!(g.child[1..], [lane1, layout::NONE, layout::NONE]);
        if boxes != Boxes::Cluster {
            // Visiting the run's reference tests the root's triangle; visiting the root does
            // not.
            assert_eq!(l.node(layout::RUN), (0, 1, 0, 0));
            assert_eq!(l.node(0), (0, 0, 0, 1));
        } else {
            assert_eq!(l.node(0), (0, 1, 0, 1));
        }
        // The leaf's box is triangle 0's box; empty lanes are inverted.
        assert_eq!([g.b[0][0], g.b[1][0], g.b[2][0]], [0.0, 0.0, 0.0]);
        assert_eq!([g.b[3][0], g.b[4][0], g.b[5][0]], [1.0, 1.0, 0.0]);
        let lane1 = [1, 4].map(|a| g.b[a][1]);
        if boxes != Boxes::Cluster {
            // Triangle 1's box: (0, 0, 1)–(2, 2, 1).
            assert_eq!(lane1, [0.0, 2.0]);
            assert_eq!([g.b[2][1], g.b[5][1]], [1.0, 1.0]);
        } else {
            assert!(lane1[0] > lane1[1]);
        }
        assert!(g.b[0][2] > g.b[3][2]);
        assert_eq!(l.root_box, [0.0, 0.0, 0.0, 2.0, 2.0, 1.0]);
    }
}

#[test]
fn occlusion_visits_a_wall_before_clusters_of_small_triangles() {
    // Root children in tree order: a wall (two triangles filling x = 10, |y|, |z| ≤ 5) and two
    // leaves of sixteen small triangles each (x in [2, 2.75] and [5, 5.75], |y|, |z| in [0.5,
    // 0.9]), all crossed by a ray along x that passes between the small triangles and hits the
    // wall. Occlusion visits the highest lane first: without the order it would test both
    // leaves (32 triangles) before the wall, which blocks the ray with 2.
    let small = |x0: f32, k: usize| {
        let (x, sg) = (
            x0 + 0.05 * k as f32,
            if k.is_multiple_of(2) { 1.0 } else { -1.0 },
        );
        [
            Vec3::new(x, 0.5 * sg, 0.5 * sg),
            Vec3::new(x, 0.9 * sg, 0.5 * sg),
            Vec3::new(x, 0.5 * sg, 0.9 * sg),
        ]
    };
    let s = tri_scene("wall", 34, |i| match i {
        0 => [
            Vec3::new(10.0, -5.0, -5.0),
            Vec3::new(10.0, 5.0, -5.0),
            Vec3::new(10.0, 5.0, 5.0),
        ],
        1 => [
            Vec3::new(10.0, -5.0, -5.0),
            Vec3::new(10.0, 5.0, 5.0),
            Vec3::new(10.0, -5.0, 5.0),
        ],
        i if i < 18 => small(2.0, i - 2),
        i => small(5.0, i - 18),
    });
    let mut b = BuildTree::default();
    let leaf = |b: &mut BuildTree, ids: std::ops::Range<u32>| {
        let mut bb = Aabb::EMPTY;
        ids.clone()
            .for_each(|i| bb.grow_box(&s.tri_bbox(i as usize)));
        b.push(BuildNode {
            bbox: bb,
            children: vec![],
            surfaces: ids.collect(),
        })
    };
    let kids = vec![
        leaf(&mut b, 0..2),
        leaf(&mut b, 2..18),
        leaf(&mut b, 18..34),
    ];
    b.root = b.push(BuildNode {
        bbox: s.bbox,
        children: kids,
        surfaces: vec![],
    });
    let t = ClusterTree::from_build(b, 34, Strategy::Sah, ClusterConfig::default());
    let rc = RayCaster::new(&s, &t);
    let mut st = RayStats::default();
    let o = Vec3::new(0.0, 0.1, -0.2);
    assert!(rc.occluded_stats(o, Vec3::X, 0.0, 20.0, &mut st));
    assert_eq!((st.nodes, st.tris), (2, 2));
    assert!(!rc.occluded(o, Vec3::X, 0.0, 9.0));
    assert!(rc.occluded_brute(o, Vec3::X, 0.0, 20.0));
}

#[test]
fn a_sparse_run_is_visited_in_distance_order() {
    // A root holding 99 small triangles spread along a row (a random line through their box
    // crosses 0.25 of them, 0.0025 per triangle tested) and a leaf child holding the last
    // one: the run's reference is pushed, not tested at once.
    let s = row_of_triangles("row", 100);
    let t = root_and_leaf(&s, (0..99).collect(), 99);
    // The run kept whole (tight boxes split it: `a_long_run_is_split_into_pieces`).
    let rc = RayCaster::with_boxes(&s, &t, Boxes::Nodes);
    let lay = layout::Layout::new(&s, &t, Boxes::Nodes);
    let g = &lay.groups[0];
    assert_eq!((g.run, g.eager, g.child[1]), (0b10, 0, layout::RUN));
    // Down onto the leaf's triangle: the leaf is visited, the run's box (x ≤ 197) is missed.
    let st = down_onto(&rc, 99);
    assert_eq!((st.nodes, st.tris), (2, 1));
    // Down onto triangle 50 of the run: the run is visited and tested up to the sixteen-wide
    // packet holding triangle 50 (the fourth: 64 triangles).
    let st = down_onto(&rc, 50);
    assert_eq!((st.nodes, st.tris), (1, 64));
    let out = stream_down(
        &rc,
        [0.25f32, 1.25]
            .map(|y| Vec3::new(100.25, y, 1.0))
            .into_iter(),
    );
    assert_eq!(out, [true, false]);
}

/// A row of `n` triangles whose root holds the first `run` and has a leaf child for each of
/// the others.
fn root_run_and_leaves(n: usize, run: usize) -> (Scene, ClusterTree) {
    let s = row_of_triangles("row", n);
    let mut b = BuildTree::default();
    let kids = leaves(&mut b, &s, run..n);
    b.root = b.push(BuildNode {
        bbox: s.bbox,
        children: kids,
        surfaces: (0..run as u32).collect(),
    });
    let t = ClusterTree::from_build(b, n, Strategy::Sah, ClusterConfig::default());
    (s, t)
}

/// The counts of a segment straight down onto triangle `i` of a row, which it hits.
fn down_onto(rc: &RayCaster, i: usize) -> RayStats {
    let o = Vec3::new(2.0 * i as f32 + 0.25, 0.25, 1.0);
    let mut st = RayStats::default();
    assert!(rc.occluded_stats(o, -Vec3::Z, 0.0, 2.0, &mut st));
    st
}

#[test]
fn a_node_with_eight_children_splits_its_run_into_eight_pieces() {
    // A root holding 64 triangles in a row and eight leaf children (an octree node): its eight
    // children fill one eight-lane node, and its run takes a second one of eight pieces (four
    // when pieces only fill a group of four): a ray onto one of them tests a piece of eight
    // (sixteen with four pieces; splitting a piece of a row of eight does not pay).
    let (s, t) = root_run_and_leaves(72, 64);
    let rc = RayCaster::new(&s, &t);
    let mut lanes = 0;
    let mut m = rc.nodes.root.unwrap();
    while m != NONE {
        let n = &rc.nodes.nodes[m as usize];
        lanes += n.lanes as usize;
        m = n.more;
    }
    assert_eq!(lanes, 8 + 8);
    for i in [5, 30, 63, 64, 71] {
        let st = down_onto(&rc, i);
        assert!(st.tris <= 8, "{i}: {st:?}");
    }
}

#[test]
fn a_run_beside_four_children_gets_a_lane_of_its_own() {
    // A root holding three triangles and four leaf children: the children fill one group of
    // four, and the run takes a lane in a second one (the root is one eight-lane node either
    // way), so a ray onto a child tests only that child's triangle. Without the lane, the run
    // is tested at every visit of the root: four triangles.
    let (s, t) = root_run_and_leaves(7, 3);
    let rc = RayCaster::new(&s, &t);
    let root = &rc.nodes.nodes[rc.nodes.root.unwrap() as usize];
    assert_eq!((root.lanes, root.num_tris, root.more), (5, 0, NONE));
    for i in 0..7 {
        let st = down_onto(&rc, i);
        let most = if i < 3 { 3 } else { 1 };
        assert!(st.tris <= most, "{i}: {st:?}");
    }
}

#[test]
fn a_run_without_a_lane_is_tested_only_when_its_box_is_hit() {
    // A root holding two triangles and eight leaf children: the children fill its eight-lane
    // node and the run, too short to split, has no lane. A ray onto a child away from the run
    // misses the run's box and tests only the child's triangle (three without the box); a ray
    // onto the run tests it.
    let (s, t) = root_run_and_leaves(10, 2);
    let rc = RayCaster::new(&s, &t);
    let root = &rc.nodes.nodes[rc.nodes.root.unwrap() as usize];
    assert_eq!((root.lanes, root.num_tris, root.more), (8, 2, NONE));
    for i in 2..10 {
        let st = down_onto(&rc, i);
        assert_eq!(st.tris, 1, "{i}: {st:?}");
    }
    for i in 0..2 {
        let st = down_onto(&rc, i);
        assert!((1..=2).contains(&st.tris), "{i}: {st:?}");
    }
}

#[test]
fn a_long_run_is_split_into_pieces() {
    // The root of `a_sparse_run_is_visited_in_distance_order` (99 triangles in a row and a
    // leaf child): with tight boxes its run is split into pieces that fill the three free lanes
    // of its group, groups of pieces below them, and chunks of at most 16 triangles (at most
    // four where splitting a piece further pays).
    let s = row_of_triangles("row", 100);
    let t = root_and_leaf(&s, (0..99).collect(), 99);
    let rc = RayCaster::new(&s, &t);
    let lay = layout::Layout::new(&s, &t, Boxes::Tight);
    let l = &lay;
    let g = &l.groups[0];
    assert_eq!((g.lanes, g.num_tris, g.run, g.num_groups), (4, 0, 0, 1));
    let subs = l.groups.iter().filter(|g| g.run & layout::SUB != 0).count();
    assert!(subs >= 3, "{subs}");
    // Every triangle is stored once, in chunks of at most 16 nearby triangles.
    let mut chunks = Vec::new();
    for g in &l.groups {
        for &r in g
            .child
            .iter()
            .filter(|&&r| r != layout::NONE && r & layout::LEAF != 0)
        {
            let (ps, n) = layout::leaf_run(r);
            let ids: Vec<u32> = if n >= layout::WIDE_MIN {
                l.wide[ps].id[..n].to_vec()
            } else {
                (0..n).map(|i| l.packets[ps + i / 4].id[i % 4]).collect()
            };
            chunks.push(ids);
        }
    }
    let mut all: Vec<u32> = chunks.iter().flatten().copied().collect();
    all.sort_unstable();
    assert_eq!(all, (0..100).collect::<Vec<u32>>());
    for c in &chunks {
        let (lo, hi) = (c.iter().min().unwrap(), c.iter().max().unwrap());
        assert!(c.len() <= 16 && (hi - lo) as usize == c.len() - 1, "{c:?}");
    }
    // Down onto triangle 50: the root is the only node of the tree visited, and only the
    // chunk holding triangle 50 is tested: a packet of four, as the piece of sixteen around it
    // is split where its parts pay for their boxes (64 triangles with the run whole, 12 when
    // pieces stopped at sixteen).
    let st = down_onto(&rc, 50);
    assert!(st.nodes == 1 && st.tris <= 4, "{st:?}");
    // Every triangle is found, by closest hit, single occlusion and the stream; the gaps
    // between them are empty.
    let origin = |i: usize| Vec3::new(i as f32 + 0.25, 0.25, 1.0);
    let out = stream_down(&rc, (0..200).map(origin));
    for (i, &o) in out.iter().enumerate() {
        let hit = i % 2 == 0;
        assert_eq!(o, hit, "{i}");
        assert_eq!(rc.occluded(origin(i), -Vec3::Z, 0.0, 2.0), hit, "{i}");
        let h = rc.closest(origin(i), -Vec3::Z, 0.0, 2.0).map(|h| h.tri);
        assert_eq!(h, hit.then_some(i as u32 / 2), "{i}");
    }
}

#[test]
fn rays_pass_through_nodes_holding_only_one_child() {
    // Root → (leaf: triangle 0, node without triangles → leaf: triangle 1), the empty half of
    // a k-d cell. With tight boxes the middle node's box is its child's: the root's lane
    // refers to the leaf directly and the middle node has no group; with the cluster's boxes
    // every node is visited.
    let s = row_of_triangles("chain", 2);
    let mut b = BuildTree::default();
    let leaf0 = b.push(BuildNode {
        bbox: s.tri_bbox(0),
        children: vec![],
        surfaces: vec![0],
    });
    let leaf1 = b.push(BuildNode {
        bbox: s.tri_bbox(1),
        children: vec![],
        surfaces: vec![1],
    });
    let mid = b.push(BuildNode {
        bbox: s.tri_bbox(1),
        children: vec![leaf1],
        surfaces: vec![],
    });
    b.root = b.push(BuildNode {
        bbox: s.bbox,
        children: vec![leaf0, mid],
        surfaces: vec![],
    });
    let t = ClusterTree::from_build(b, 2, Strategy::Kdt, ClusterConfig::default());
    assert_eq!(t.nodes.len(), 4);
    let o = Vec3::new(2.25, 0.25, 1.0);
    for (boxes, groups, nodes) in [
        (Boxes::Tight, 1, 2),
        (Boxes::Nodes, 1, 2),
        (Boxes::Cluster, 2, 3),
    ] {
        let rc = RayCaster::with_boxes(&s, &t, boxes);
        assert_eq!(
            layout::Layout::new(&s, &t, boxes).groups.len(),
            groups,
            "{boxes:?}"
        );
        assert_eq!(rc.nodes.nodes.len(), groups, "{boxes:?}");
        let mut st = RayStats::default();
        assert!(rc.occluded_stats(o, -Vec3::Z, 0.0, 2.0, &mut st));
        assert_eq!((st.nodes, st.tris), (nodes, 1), "{boxes:?}");
        assert_eq!(rc.closest(o, -Vec3::Z, 0.0, 2.0).map(|h| h.tri), Some(1));
        assert_eq!(
            stream_down(&rc, [o, o - Vec3::X].into_iter()),
            [true, false]
        );
    }
}

#[test]
fn tight_boxes_shrink_a_loose_cluster_box() {
    // A root box far larger than its contents (a k-d cell): the tight root box is the
    // triangles' box, so a ray through the empty part of the cell visits nothing (with the
    // cluster's box it visits the root and tests the root's own triangle).
    let s = two_tri_scene();
    let mut t = inner_surface_tree(&s);
    t.nodes[0].bbox.max = Vec3::splat(10.0);
    let (o, d) = (Vec3::new(5.0, 5.0, -1.0), Vec3::Z);
    for (boxes, root_max, visits) in [(Boxes::Cluster, 10.0, 1), (Boxes::Tight, 2.0, 0)] {
        let rc = RayCaster::with_boxes(&s, &t, boxes);
        assert_eq!(rc.layout.root_box[3], root_max);
        let mut st = RayStats::default();
        assert!(!rc.occluded_stats(o, d, 0.0, 20.0, &mut st));
        assert_eq!((st.nodes, st.tris), (visits, visits), "{boxes:?}");
    }
}

#[test]
fn packets_and_groups_hold_wide_nodes() {
    // A root with six leaf children of one triangle each: two groups (4 + 2 lanes), one node.
    let s = row_of_triangles("six", 6);
    let t = one_leaf_per_triangle(&s);
    let rc = RayCaster::new(&s, &t);
    let lay = layout::Layout::new(&s, &t, Boxes::Tight);
    let l = &lay;
    assert_eq!(l.groups.len(), 2);
    assert_eq!((l.groups[0].num_groups, l.groups[0].lanes), (2, 4));
    assert_eq!(l.groups[1].lanes, 2);
    // One eight-wide node of six lanes.
    assert_eq!(rc.nodes.nodes.len(), 1);
    assert_eq!(rc.nodes.nodes[0].lanes, 6);
    assert_eq!(l.packets.len(), 6);
    // Every triangle is found from above, by both query kinds, with the right id.
    for i in 0..6u32 {
        let o = Vec3::new(i as f32 * 2.0 + 0.25, 0.25, 1.0);
        let h = rc.closest(o, -Vec3::Z, 0.0, 2.0).unwrap();
        assert_eq!(h.tri, i);
        assert!((h.t - 1.0).abs() < 1e-6);
        assert!(rc.occluded(o, -Vec3::Z, 0.0, 2.0));
        assert!(!rc.occluded(o + Vec3::new(0.0, 2.0, 0.0), -Vec3::Z, 0.0, 2.0));
    }
    // The stream gives the same answers, in order.
    let out = stream_down(
        &rc,
        (0..12).map(|i| {
            Vec3::new(
                (i / 2) as f32 * 2.0 + 0.25,
                0.25 + 2.0 * (i % 2) as f32,
                1.0,
            )
        }),
    );
    let want: Vec<bool> = (0..12).map(|i| i % 2 == 0).collect();
    assert_eq!(out, want);
}

#[test]
fn closest_is_nearest_through_inner_node() {
    let s = two_tri_scene();
    let t = inner_surface_tree(&s);
    let rc = RayCaster::new(&s, &t);
    // From above, downwards: triangle 1 (z = 1) first, then triangle 0 (z = 0).
    let h = rc
        .closest(Vec3::new(0.2, 0.2, 2.0), -Vec3::Z, 0.0, 10.0)
        .unwrap();
    assert_eq!(h.tri, 1);
    assert!((h.t - 1.0).abs() < 1e-6);
    // From below, upwards: triangle 0 first.
    let h = rc
        .closest(Vec3::new(0.2, 0.2, -1.0), Vec3::Z, 0.0, 10.0)
        .unwrap();
    assert_eq!(h.tri, 0);
    assert!((h.t - 1.0).abs() < 1e-6);
    // Segment ending before triangle 1.
    assert!(!rc.occluded(Vec3::new(0.2, 0.2, 2.0), -Vec3::Z, 0.0, 0.9));
    assert!(rc.occluded(Vec3::new(0.2, 0.2, 2.0), -Vec3::Z, 0.0, 1.0));
    // Counters, for both kinds of boxes: (closest from above, any hit from below, any hit
    // from below with tmax = 1.5) as (nodes, triangles, boxes).
    for (boxes, want) in [
        // The root's own triangle is tested on visiting the root (after its children's boxes
        // for occlusion).
        (Boxes::Cluster, [(1, 1, 2), (1, 1, 2), (2, 2, 2)]),
        // The root's own triangle has a lane (one box test more). Closest hit visits it like a
        // leaf, in order of distance; occlusion tests it as soon as its box is hit (a big
        // triangle filling its box: `EAGER_HITS_PER_TEST`), before the nearer leaf.
        (Boxes::Tight, [(1, 1, 3), (1, 1, 3), (2, 1, 3)]),
    ] {
        let rc = RayCaster::with_boxes(&s, &t, boxes);
        let mut st = RayStats::default();
        assert!(rc
            .closest_stats(Vec3::new(0.2, 0.2, 2.0), -Vec3::Z, 0.0, 10.0, &mut st)
            .is_some());
        assert_eq!(st.rays, 1);
        // The hit at the root (t = 1) culls the child box (entry t = 2).
        assert_eq!((st.nodes, st.tris, st.boxes), want[0], "{boxes:?}");
        let mut st = RayStats::default();
        assert!(rc.occluded_stats(Vec3::new(0.2, 0.2, -1.0), Vec3::Z, 0.0, 10.0, &mut st));
        // Any hit stops the query (with the cluster's box the root's own triangle, t = 2, is
        // tested on visiting the root, and hit).
        assert_eq!((st.nodes, st.tris, st.boxes), want[1], "{boxes:?}");
        let mut st = RayStats::default();
        assert!(rc.occluded_stats(Vec3::new(0.2, 0.2, -1.0), Vec3::Z, 0.0, 1.5, &mut st));
        // With tmax = 1.5 the root triangle is missed and the leaf's is hit.
        assert_eq!((st.nodes, st.tris, st.boxes), want[2], "{boxes:?}");
    }
}

#[test]
fn eight_lanes_push_as_one_by_one_in_lane_order() {
    // `push8` against `push` of the selected lanes in lane order, on a stack that fits them
    // and on one that spills part way (its fixed array too small for eight more).
    let mut g = hirad_core::rng::SplitMix64::new(9);
    for round in 0..200 {
        let mut fast: Stack<u32, 24> = Stack::new();
        let mut slow: Stack<u32, 24> = Stack::new();
        let mut small_fast: Stack<u32, 8> = Stack::new();
        let mut small_slow: Stack<u32, 8> = Stack::new();
        for k in 0..4 {
            let a: [u32; 8] = std::array::from_fn(|i| (100 * round + 10 * k + i) as u32);
            let mask = (g.next_u64() & 0xFF) as u32;
            fast.push8(&a, mask);
            small_fast.push8(&a, mask);
            for (i, &c) in a.iter().enumerate() {
                if mask >> i & 1 == 1 {
                    slow.push(c);
                    small_slow.push(c);
                }
            }
        }
        let all = |s: &mut Stack<u32, 24>| std::iter::from_fn(|| s.pop()).collect::<Vec<_>>();
        assert_eq!(all(&mut fast), all(&mut slow));
        let all8 = |s: &mut Stack<u32, 8>| std::iter::from_fn(|| s.pop()).collect::<Vec<_>>();
        assert_eq!(all8(&mut small_fast), all8(&mut small_slow));
    }
}

#[test]
fn stack_spills_to_heap_in_order() {
    let mut s: Stack<u32, 4> = Stack::new();
    for i in 0..10 {
        s.push(i);
    }
    assert_eq!(s.size(), 10);
    assert_eq!(s.top_mut(3), &[7, 8, 9]);
    let popped: Vec<u32> = std::iter::from_fn(|| s.pop()).collect();
    assert_eq!(popped, (0..10).rev().collect::<Vec<_>>());
}

#[test]
fn pop_if_takes_the_top_only_when_asked() {
    // On the fixed array and after a spill: the top is popped only if `keep` accepts it.
    for n in [3, 10] {
        let mut s: Stack<u32, 4> = Stack::new();
        for i in 0..n {
            s.push(i);
        }
        assert_eq!(
            s.pop_if(|&x| x % 2 == 0),
            ((n - 1) % 2 == 0).then_some(n - 1)
        );
        let left = if (n - 1) % 2 == 0 { n - 1 } else { n };
        assert_eq!(s.size(), left as usize);
        assert_eq!(s.pop_if(|_| true), Some(left - 1));
        assert_eq!(s.size(), left as usize - 1);
    }
    let mut e: Stack<u32, 4> = Stack::new();
    assert_eq!(e.pop_if(|_| true), None);
}

#[test]
fn node_test_equals_scalar_slab() {
    // The 8-wide box test of a node, compiled for the baseline and for AVX2, gives the scalar
    // slab test's answer and entry distance in every lane, including rays with zero direction
    // components (both signs) whose origin lies in a box plane (0·∞ = NaN), and never hits an
    // empty lane. The one exception: a lane is skipped when the ray lies in the plane of one
    // of its box's faces whose face bit is set (what touches that plane lies in it: coplanar
    // with the ray; `Slab8::flat_in_plane`).
    // Every other ray starts at t = 1/16 (a grid step of the boxes' planes along a unit
    // direction component), where the running bounds are integers if every 1/d is finite.
    let mut g = hirad_core::rng::SplitMix64::new(4);
    let grid = |g: &mut hirad_core::rng::SplitMix64| (g.next_u64() % 9) as f32 * 0.5 - 2.0;
    let mut hits = 0;
    let mut skipped = 0;
    for i in 0..20000 {
        let o = Vec3::new(grid(&mut g), grid(&mut g), grid(&mut g));
        let mut d = Vec3::new(g.next_f32() - 0.5, g.next_f32() - 0.5, g.next_f32() - 0.5);
        if i % 3 == 0 {
            d[(i / 3) % 3] = if i % 2 == 0 { 0.0 } else { -0.0 };
        }
        let r = RayPre::new(o, d).unwrap();
        let slab = Slab8::new(&r);
        let mut node = layout::Node8::EMPTY;
        let mut boxes = Vec::new();
        let full = 1 + i % 8;
        for lane in 0..full {
            let (lo, hi) = grid_box(&mut g, grid);
            for a in 0..3 {
                node.b[a][lane] = lo[a];
                node.b[a + 3][lane] = hi[a];
            }
            boxes.push([lo.x, lo.y, lo.z, hi.x, hi.y, hi.z]);
        }
        node.faces = g.next_u64() & 0x3F3F_3F3F_3F3F_3F3F;
        let faces = node.faces;
        let tmin = if i % 4 < 2 { 0.0 } else { 1.0 / 16.0 };
        let (mask, tn) = slab.test::<false>(&node, tmin, 10.0);
        assert_eq!(mask >> full, 0, "empty lane hit");
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: AVX2 was detected above.
            let (m8, t8) = unsafe { slab.test_avx(&node, tmin, 10.0) };
            assert_eq!(m8, mask);
            for lane in 0..8 {
                if mask >> lane & 1 == 1 {
                    assert_eq!(t8[lane].to_bits(), tn[lane].to_bits());
                }
            }
        }
        for (lane, b) in boxes.iter().enumerate() {
            let s = r.slab(b, tmin, 10.0);
            let f = (faces >> (8 * lane)) as u32;
            let flat_in_plane = (0..3).any(|a| {
                d[a] == 0.0
                    && ((b[a] == o[a] && f >> a & 1 == 1)
                        || (b[a + 3] == o[a] && f >> (a + 3) & 1 == 1))
            });
            skipped += (s.is_some() && flat_in_plane) as u32;
            let s = s.filter(|_| !flat_in_plane);
            assert_eq!(mask >> lane & 1 == 1, s.is_some(), "{o} {d} {b:?}");
            if let Some(t) = s {
                assert_eq!(tn[lane], t, "{o} {d} {b:?}");
                hits += 1;
            }
        }
    }
    assert!(hits > 6000, "{hits}");
    assert!(skipped > 50, "{skipped}");
}

#[test]
fn a_node_of_twenty_lanes_continues_in_two_more_nodes() {
    // A root with twenty leaf children: three eight-wide nodes chained by `more` (8 + 8 + 4
    // lanes). Every triangle is found, with its id, by closest hit, single occlusion and the
    // stream, and the chain counts as one node of the tree.
    let n = 20;
    let s = row_of_triangles("twenty", n);
    let t = one_leaf_per_triangle(&s);
    let rc = RayCaster::new(&s, &t);
    assert_eq!(rc.validate(), Ok(()));
    let nodes = &rc.nodes.nodes;
    assert_eq!(nodes.len(), 3);
    assert_eq!(
        nodes.iter().map(|x| (x.lanes, x.more)).collect::<Vec<_>>(),
        [(8, 1), (8, 2), (4, layout::NONE)]
    );
    let origins: Vec<Vec3> = (0..n)
        .flat_map(|i| {
            let o = Vec3::new(i as f32 * 2.0 + 0.25, 0.25, 1.0);
            [o, o + Vec3::new(1.0, 0.0, 0.0)]
        })
        .collect();
    for (k, &o) in origins.iter().enumerate() {
        let want = k % 2 == 0;
        assert_eq!(rc.occluded(o, -Vec3::Z, 0.0, 2.0), want, "{k}");
        assert_eq!(
            rc.closest(o, -Vec3::Z, 0.0, 2.0).map(|h| h.tri),
            want.then_some(k as u32 / 2)
        );
        let mut st = RayStats::default();
        assert_eq!(rc.occluded_stats(o, -Vec3::Z, 0.0, 2.0, &mut st), want);
        // Over a triangle, the root (its three nodes) and the leaf; beside the last one the
        // ray misses the root's box.
        let nodes = if want {
            2
        } else if k + 1 < 2 * n {
            1
        } else {
            0
        };
        assert_eq!(st.nodes, nodes, "{k}");
    }
    let out = stream_down(&rc, origins.iter().copied());
    assert_eq!(out, (0..2 * n).map(|k| k % 2 == 0).collect::<Vec<_>>());
}

/// A closest hit so far: triangle id and barycentric coordinates.
type Best = Option<(u32, f32, f32)>;

#[test]
fn wide_packets_answer_alike_with_every_instruction_set() {
    // A root run of 40 random triangles (three wide packets: 16 + 16 + 8 lanes), tested by
    // the baseline (edge masks, then the scalar test), the AVX2 (four lanes at a time) and
    // the AVX-512 packet tests: the same occluder (the first hit in run order that `skip`
    // does not leave out) and the same closest hit as a loop over the run's triangles.
    let n = 41usize;
    let mut g = hirad_core::rng::SplitMix64::new(5);
    // Coordinates on a coarse grid: hits at the range's ends and zero edge functions occur.
    let mut c = || (g.next_u64() % 9) as f32 * 0.5 - 2.0;
    let mut corners: Vec<[Vec3; 3]> = Vec::new();
    while corners.len() < n {
        let t: [Vec3; 3] = std::array::from_fn(|_| Vec3::new(c(), c(), c()));
        if (t[1] - t[0]).cross(t[2] - t[0]) != Vec3::ZERO {
            corners.push(t);
        }
    }
    let s = tri_scene("wide", n, |i| corners[i]);
    assert_eq!(s.num_triangles(), n);
    let t = root_and_leaf(&s, (0..40).collect(), 40);
    let l = layout::Layout::new(&s, &t, Boxes::Nodes);
    assert_eq!(l.wide.len(), 3);
    let run: Vec<u32> = (0..40).map(|k| l.wide[k / 16].id[k % 16]).collect();
    let (mut hits, mut found) = (0, 0);
    for i in 0..4000 {
        let (o, q) = (Vec3::new(c(), c(), c()), Vec3::new(c(), c(), c()));
        let Some(r) = RayPre::new(o, q - o) else {
            continue;
        };
        let (tmin, tmax) = if i % 2 == 0 { (0.0, 1.0) } else { (0.25, 0.75) };
        let skip = |id: u32| id % 5 == i % 5;
        let tv = |id: u32| watertight::tri_verts(&s, id as usize);
        let want = run
            .iter()
            .copied()
            .find(|&id| !skip(id) && intersect(&r, &tv(id), tmin, tmax).is_some());
        let mut want_closest: Best = None;
        let mut want_t = tmax;
        for &id in &run {
            if let Some((t, u, v)) = intersect(&r, &tv(id), tmin, want_t) {
                let better = match want_closest {
                    None => true,
                    Some((b, _, _)) => t < want_t || id < b,
                };
                if better {
                    (want_t, want_closest) = (t, Some((id, u, v)));
                }
            }
        }
        let mut tested = 0;
        assert_eq!(
            l.any_hit_wide(&r, 0, 40, tmin, tmax, &mut tested, &skip),
            want
        );
        let bits = |bt: f32, b: Best| {
            (
                bt.to_bits(),
                b.map(|(id, u, v)| (id, u.to_bits(), v.to_bits())),
            )
        };
        let want_c = bits(want_t, want_closest);
        let closest = |f: &dyn Fn(&mut f32, &mut Best)| {
            let (mut bt, mut b) = (tmax, None);
            f(&mut bt, &mut b);
            bits(bt, b)
        };
        assert_eq!(
            closest(&|bt, b| l.closest_hit::<false>(&r, 0, 40, tmin, bt, b)),
            want_c
        );
        #[cfg(target_arch = "x86_64")]
        if has_avx2() {
            let range = (tmin, tmax);
            // SAFETY: AVX2 was detected.
            let avx2 = unsafe { l.any_hit_wide_avx2(&r, (0, 40), range, &mut tested, &skip) };
            assert_eq!(avx2, want);
            let c2 = closest(&|bt, b| unsafe { l.closest_wide_avx2(&r, (0, 40), tmin, bt, b) });
            assert_eq!(c2, want_c);
            if layout::has_avx512() {
                // SAFETY: AVX-512F was detected.
                let a = unsafe { l.any_hit_wide_avx512(&r, (0, 40), range, &mut tested, &skip) };
                assert_eq!(a, want);
                let c =
                    closest(&|bt, b| unsafe { l.closest_wide_avx512(&r, (0, 40), tmin, bt, b) });
                assert_eq!(c, want_c);
            }
        }
        hits += want.is_some() as u32;
        found += want_closest.is_some() as u32;
    }
    assert!(hits > 400 && found > hits, "{hits} {found}");
}

#[test]
fn long_runs_go_to_wide_packets() {
    // A root holding 20 triangles of its own (a run of two wide packets: 16 + 4 lanes) and a
    // leaf child with 3 (one four-wide packet). Every triangle is found, with its id, by
    // closest hit, single occlusion and the stream.
    let n = 23usize;
    let s = row_of_triangles("long", n);
    let mut b = BuildTree::default();
    let mut leaf_box = s.tri_bbox(20);
    leaf_box.grow_box(&s.tri_bbox(22));
    let leaf = b.push(BuildNode {
        bbox: leaf_box,
        children: vec![],
        surfaces: vec![20, 21, 22],
    });
    b.root = b.push(BuildNode {
        bbox: s.bbox,
        children: vec![leaf],
        surfaces: (0..20).collect(),
    });
    let t = ClusterTree::from_build(b, n, Strategy::Sah, ClusterConfig::default());
    // The run kept whole (tight boxes may split it into pieces).
    let rc = RayCaster::with_boxes(&s, &t, Boxes::Nodes);
    let l = &rc.layout;
    assert_eq!((l.wide.len(), l.packets.len()), (2, 1));
    assert_eq!(l.wide[1].id[..5], [16, 17, 18, 19, u32::MAX]);
    assert_eq!(l.packets[0].id, [20, 21, 22, u32::MAX]);
    let mut segs = Vec::new();
    for i in 0..n as u32 {
        let o = Vec3::new(i as f32 * 2.0 + 0.25, 0.25, 1.0);
        let h = rc.closest(o, -Vec3::Z, 0.0, 2.0).unwrap();
        assert_eq!(h.tri, i);
        assert!((h.t - 1.0).abs() < 1e-6);
        assert!(rc.occluded(o, -Vec3::Z, 0.0, 2.0));
        // Beside the triangle (in the gap to the next one): nothing.
        let miss = o + Vec3::new(1.0, 0.0, 0.0);
        assert!(!rc.occluded(miss, -Vec3::Z, 0.0, 2.0));
        segs.push(Segment::between(o, o - 2.0 * Vec3::Z));
        segs.push(Segment::between(miss, miss - 2.0 * Vec3::Z));
    }
    let out = rc.occluded_batch(&segs);
    assert_eq!(out, (0..2 * n).map(|k| k % 2 == 0).collect::<Vec<_>>());
}

#[test]
fn stream_overflow_falls_back_to_single_ray() {
    // A root with 100 leaf children stacked along z: a ray along z through all their boxes
    // but beside the triangles pushes more entries than a ray in flight can hold; the stream
    // hands it to the single-ray traversal, whose stack grows, and the answers stay exact.
    let n = 100u32;
    let s = tri_scene("stack", n as usize, |i| {
        let z = i as f32 * 0.1;
        [
            Vec3::new(0.0, 0.0, z),
            Vec3::new(1.0, 0.0, z),
            Vec3::new(0.0, 1.0, z),
        ]
    });
    let t = one_leaf_per_triangle(&s);
    let rc = RayCaster::new(&s, &t);
    let segs: Vec<Segment> = [(0.9, 0.9), (0.2, 0.2), (0.6, 0.3), (0.3, 0.75)]
        .iter()
        .flat_map(|&(x, y)| {
            [
                Segment::between(Vec3::new(x, y, -1.0), Vec3::new(x, y, 11.0)),
                Segment::between(Vec3::new(x, y, 11.0), Vec3::new(x, y, -1.0)),
            ]
        })
        .collect();
    let brute: Vec<bool> = segs
        .iter()
        .map(|s| rc.occluded_brute(s.origin, s.dir, s.tmin, s.tmax))
        .collect();
    assert_eq!(brute, [false, false, true, true, true, true, false, false]);
    assert_eq!(rc.occluded_batch(&segs), brute);
    let single: Vec<bool> = segs
        .iter()
        .map(|s| rc.occluded(s.origin, s.dir, s.tmin, s.tmax))
        .collect();
    assert_eq!(single, brute);
}

/// `validate` accepts every strategy's layout and finds a lane that refers to nothing and a
/// triangle no reference reaches.
#[test]
fn validate_finds_broken_references() {
    let scene = tri_scene("grid", 200, |i| {
        let (x, y) = ((i % 20) as f32 * 1.5, (i / 20) as f32 * 1.5);
        [
            Vec3::new(x, y, (i % 7) as f32),
            Vec3::new(x + 1.0, y, (i % 5) as f32),
            Vec3::new(x, y + 1.0, (i % 3) as f32),
        ]
    });
    for s in [Strategy::Kdt, Strategy::Proxi, Strategy::Sah] {
        let tree = ClusterTree::build(&scene, s, &ClusterConfig::default());
        for boxes in Boxes::ALL {
            let rc = RayCaster::with_boxes(&scene, &tree, boxes);
            assert_eq!(rc.validate(), Ok(()), "{s:?} {boxes:?}");
            let mut broken = RayCaster::with_boxes(&scene, &tree, boxes);
            let n = &mut broken.nodes.nodes[0];
            n.child[0] = layout::NONE;
            assert!(broken.validate().is_err(), "{s:?} {boxes:?}");
            let mut emptied = RayCaster::with_boxes(&scene, &tree, boxes);
            let n = &mut emptied.nodes.nodes[0];
            n.b[0][0] = f32::INFINITY;
            assert!(emptied.validate().is_err(), "{s:?} {boxes:?}");
            let mut dropped = RayCaster::with_boxes(&scene, &tree, boxes);
            let p = &mut dropped.layout.packets[0];
            let k = (0..4).find(|&k| p.id[k] != u32::MAX).unwrap();
            p.id[k] = if p.id[k] == 0 { 1 } else { 0 };
            assert!(dropped.validate().is_err(), "{s:?} {boxes:?}");
        }
    }
}

/// `n` random triangles (corners within `size(i)` of a centre in [-4, 4]³) and then `m` random
/// segments (ends in [-4.5, 4.5]³), from one SplitMix64 stream seeded with `seed`.
fn random_scene(
    name: &str,
    seed: u64,
    n: usize,
    size: impl Fn(usize) -> f32,
    m: usize,
) -> (Scene, Vec<Segment>) {
    let mut g = hirad_core::rng::SplitMix64::new(seed);
    let mut f = |s: f32| (g.next_f32() - 0.5) * s;
    let corners: Vec<[Vec3; 3]> = (0..n)
        .map(|i| {
            let c = Vec3::new(f(8.0), f(8.0), f(8.0));
            let s = size(i);
            [
                c,
                c + Vec3::new(f(s), f(s), f(s)),
                c + Vec3::new(f(s), f(s), f(s)),
            ]
        })
        .collect();
    let scene = tri_scene(name, corners.len(), |i| corners[i]);
    let segs = (0..m)
        .map(|_| {
            Segment::between(
                Vec3::new(f(9.0), f(9.0), f(9.0)),
                Vec3::new(f(9.0), f(9.0), f(9.0)),
            )
        })
        .collect();
    (scene, segs)
}

#[test]
fn baseline_and_avx2_traversals_equal_brute_force() {
    // The occlusion traversals (single ray and batch) compiled for the x86_64 baseline
    // (scalar box tests) and for AVX2 answer as the brute-force loop does, for every
    // strategy, on random triangles of mixed sizes and random segments.
    let (s, segs) = random_scene(
        "random",
        21,
        600,
        |i| if i % 7 == 0 { 3.0 } else { 0.6 },
        3000,
    );
    for st in Strategy::ALL {
        let t = ClusterTree::build(&s, st, &ClusterConfig::default());
        let rc = RayCaster::new(&s, &t);
        let root = rc.nodes.root.unwrap();
        let (mut blocked, mut wide) = (0, 0);
        for q in &segs {
            let want = rc.occluded_brute(q.origin, q.dir, q.tmin, q.tmax);
            let r = RayPre::new(q.origin, q.dir).unwrap();
            let none = &|_| false;
            let st0 = &mut RayStats::default();
            let inside = r.slab(&rc.layout.root_box, q.tmin, q.tmax).is_some();
            let base = inside
                && rc
                    .occluded_loop::<false, false, _>(&r, root, q.tmin, q.tmax, st0, none)
                    .is_some();
            assert_eq!(base, want, "{st:?} {q:?}");
            #[cfg(target_arch = "x86_64")]
            if has_avx2() {
                // SAFETY: AVX2 was detected.
                let avx = inside
                    && unsafe { rc.occluded_avx2::<false, _>(&r, root, q.tmin, q.tmax, st0, none) }
                        .is_some();
                assert_eq!(avx, want, "{st:?} {q:?}");
                wide += 1;
            }
            blocked += want as u32;
        }
        assert!(blocked > 300 && blocked < 2700, "{st:?} {blocked}");
        let _ = wide;
        // The batch traversal (several rays in flight), compiled both ways.
        let want: Vec<bool> = segs
            .iter()
            .map(|q| rc.occluded_brute(q.origin, q.dir, q.tmin, q.tmax))
            .collect();
        let mut out = vec![false; segs.len()];
        rc.stream_impl::<false>(&segs, &mut out);
        assert_eq!(out, want, "{st:?}");
        #[cfg(target_arch = "x86_64")]
        if has_avx2() {
            out.fill(false);
            // SAFETY: AVX2 was detected.
            unsafe { rc.stream_avx2(&segs, &mut out) };
            assert_eq!(out, want, "{st:?}");
        }
    }
}

#[test]
fn casters_timed_in_turns_count_as_alone() {
    // Two trees over random triangles, 40,000 segments (three turns of each), two passes with
    // closest hits: every caster's counts equal its own batch count and brute force, and every
    // caster was timed.
    let (s, segs) = random_scene("turns", 3, 300, |_| 1.0, 40_000);
    let trees: Vec<ClusterTree> = [Strategy::Sah, Strategy::Kdt]
        .iter()
        .map(|&st| ClusterTree::build(&s, st, &ClusterConfig::default()))
        .collect();
    let casters: Vec<RayCaster> = trees.iter().map(|t| RayCaster::new(&s, t)).collect();
    let list: Vec<&dyn turns::TurnCaster> = casters
        .iter()
        .map(|c| c as &dyn turns::TurnCaster)
        .collect();
    let ticks = std::cell::Cell::new(0);
    let t = turns::time_in_turns(&list, &segs, 2, true, || ticks.set(ticks.get() + 1));
    let brute = segs
        .iter()
        .filter(|q| casters[0].occluded_brute(q.origin, q.dir, q.tmin, q.tmax))
        .count() as u64;
    assert!(brute > 1000, "{brute}");
    assert_eq!(t.batch_occluded, vec![brute; 2]);
    assert_eq!(t.single_occluded, vec![brute; 2]);
    assert_eq!(ticks.get(), 2 * 3);
    for k in 0..2 {
        assert!(t.batch_s[k] > 0.0 && t.single_s[k] > 0.0 && t.closest_s[k] > 0.0);
    }
}

#[test]
fn embree_counts_what_brute_force_counts() {
    // Embree 3 (when installed; required where HIRAD_REQUIRE_EMBREE is set) on random
    // triangles: its occluded and hit counts, batch and single, within 0.1% of brute force
    // (Embree's default test is not watertight), and timed in turns beside our caster.
    let (s, segs) = random_scene("embree", 5, 300, |_| 1.0, 20_000);
    let em = match super::embree::EmbreeCaster::new(&s, false) {
        Ok(e) => e,
        Err(e) if std::env::var_os("HIRAD_REQUIRE_EMBREE").is_none() => {
            eprintln!("skipped: {e}");
            return;
        }
        Err(e) => panic!("{e}"),
    };
    let tree = ClusterTree::build(&s, Strategy::Sah, &ClusterConfig::default());
    let rc = RayCaster::new(&s, &tree);
    let brute = segs
        .iter()
        .filter(|q| rc.occluded_brute(q.origin, q.dir, q.tmin, q.tmax))
        .count() as u64;
    let hits = rc.closest_batch(&segs).iter().flatten().count() as u64;
    assert!(brute > 1000 && hits == brute, "{brute} {hits}");
    let close = |x: u64| x.abs_diff(brute) * 1000 <= segs.len() as u64;
    let list: [&dyn turns::TurnCaster; 2] = [&rc, &em];
    let t = turns::time_in_turns(&list, &segs, 1, true, || ());
    assert_eq!(t.batch_occluded[0], brute);
    for n in [
        t.batch_occluded[1],
        t.single_occluded[1],
        turns::TurnCaster::count_hits(&em, &segs),
    ] {
        assert!(close(n), "Embree {n}, brute force {brute}");
    }
    assert!(t.batch_s[1] > 0.0 && t.single_s[1] > 0.0 && t.closest_s[1] > 0.0);
}
