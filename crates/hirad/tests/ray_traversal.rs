//! Ray casting through cluster trees: the traversal must agree exactly with a brute-force loop
//! over every triangle (occlusion and closest hit), for any tree shape (surfaces at inner nodes,
//! overlapping boxes, many children), and never let a ray slip through shared edges.

use glam::Vec3;
use hirad::cluster::{BuildNode, BuildTree, ClusterConfig, ClusterTree, Prims, Strategy};
use hirad::geom::Aabb;
use hirad::ray::{Boxes, RayCaster, RayStats, Segment};
use hirad::rng::SplitMix64;
use hirad::scene::{Material, RawScene, Scene, SceneOptions};
use proptest::prelude::*;

fn scene_from(positions: Vec<Vec3>, triangles: Vec<[u32; 3]>) -> Scene {
    let n = triangles.len();
    let raw = RawScene {
        name: "test".into(),
        positions,
        triangles,
        tri_material: vec![0; n],
        tri_object: vec![0; n],
        materials: vec![Material::diffuse("m", Vec3::splat(0.5))],
        ..Default::default()
    };
    Scene::from_raw(raw, &SceneOptions::default()).unwrap()
}

/// Random small scene: random triangles plus axis-aligned quads on a coarse grid (coplanar
/// faces, shared edges and boxes that are flat, so that grazing cases occur).
fn random_scene(seed: u64, n_random: usize, n_quads: usize) -> Scene {
    let mut g = SplitMix64::new(seed);
    let mut pos = Vec::new();
    let mut tris = Vec::new();
    for _ in 0..n_random {
        let c = Vec3::new(g.next_f32(), g.next_f32(), g.next_f32()) * 4.0;
        let s = 0.05 + g.next_f32() * 1.0;
        let base = pos.len() as u32;
        for _ in 0..3 {
            pos.push(c + (Vec3::new(g.next_f32(), g.next_f32(), g.next_f32()) - 0.5) * s);
        }
        tris.push([base, base + 1, base + 2]);
    }
    let grid = |g: &mut SplitMix64| (g.next_u64() % 17) as f32 * 0.25;
    for _ in 0..n_quads {
        let axis = (g.next_u64() % 3) as usize;
        let c = grid(&mut g);
        let (u0, u1) = {
            let a = grid(&mut g);
            let b = grid(&mut g);
            (a.min(b), a.max(b) + 0.25)
        };
        let (v0, v1) = {
            let a = grid(&mut g);
            let b = grid(&mut g);
            (a.min(b), a.max(b) + 0.25)
        };
        let mk = |u: f32, v: f32| match axis {
            0 => Vec3::new(c, u, v),
            1 => Vec3::new(u, c, v),
            _ => Vec3::new(u, v, c),
        };
        let base = pos.len() as u32;
        pos.extend([mk(u0, v0), mk(u1, v0), mk(u1, v1), mk(u0, v1)]);
        tris.push([base, base + 1, base + 2]);
        tris.push([base, base + 2, base + 3]);
    }
    scene_from(pos, tris)
}

/// Random tree over the scene's surfaces: surfaces kept at inner nodes, 1..=6 children of
/// random sizes, tight boxes (which overlap freely).
fn random_tree(scene: &Scene, seed: u64) -> ClusterTree {
    random_tree_keeping(scene, seed, 3)
}

/// [`random_tree`] where a node keeps up to `1/share` of its triangles (all with `share` 1:
/// long runs at inner nodes).
fn random_tree_keeping(scene: &Scene, seed: u64, share: u64) -> ClusterTree {
    fn rec(
        b: &mut BuildTree,
        prims: &Prims,
        mut items: Vec<u32>,
        g: &mut SplitMix64,
        depth: u32,
        share: u64,
    ) -> u32 {
        // Shuffle.
        for i in (1..items.len()).rev() {
            let j = (g.next_u64() % (i as u64 + 1)) as usize;
            items.swap(i, j);
        }
        let keep = if items.len() <= 3 || depth > 8 {
            items.len()
        } else {
            (g.next_u64() % (items.len() as u64 / share + 1)) as usize
        };
        let rest = items.split_off(keep);
        let mut children = Vec::new();
        let mut rest = rest;
        while !rest.is_empty() {
            let k = 1 + (g.next_u64() % 6) as usize;
            let take = (rest.len() / k).max(1).min(rest.len());
            let part: Vec<u32> = rest.drain(..take).collect();
            children.push(rec(b, prims, part, g, depth + 1, share));
        }
        let mut bbox = Aabb::EMPTY;
        for &s in &items {
            bbox.grow_box(&prims.bbox[s as usize]);
        }
        for &c in &children {
            let cb = b.nodes[c as usize].bbox;
            bbox.grow_box(&cb);
        }
        b.push(BuildNode {
            bbox,
            children,
            surfaces: items,
        })
    }
    let prims = Prims::from_scene(scene);
    let mut g = SplitMix64::new(seed);
    let mut b = BuildTree::default();
    let all: Vec<u32> = (0..scene.num_triangles() as u32).collect();
    b.root = rec(&mut b, &prims, all, &mut g, 0, share);
    let t = ClusterTree::from_build(
        b,
        scene.num_triangles(),
        Strategy::Sah,
        ClusterConfig::default(),
    );
    t.validate(&prims).unwrap();
    t
}

/// Random segments between random points of the scene box and grid points (so that some run
/// exactly in the planes of the axis-aligned quads).
fn random_segments(scene: &Scene, seed: u64, n: usize) -> Vec<Segment> {
    let mut g = SplitMix64::new(seed);
    let b = scene.bbox;
    let mut out = Vec::with_capacity(n);
    for i in 0..n {
        let pt = |g: &mut SplitMix64| {
            if i % 3 == 0 {
                Vec3::new(
                    (g.next_u64() % 19) as f32 * 0.25 - 0.25,
                    (g.next_u64() % 19) as f32 * 0.25 - 0.25,
                    (g.next_u64() % 19) as f32 * 0.25 - 0.25,
                )
            } else {
                b.min - 0.5
                    + Vec3::new(g.next_f32(), g.next_f32(), g.next_f32()) * (b.extent() + 1.0)
            }
        };
        let p = pt(&mut g);
        let mut q = pt(&mut g);
        if i % 3 == 0 && i % 2 == 0 {
            // Axis-parallel segment in a grid plane.
            let axis = (g.next_u64() % 3) as usize;
            for a in 0..3 {
                if a != axis {
                    q[a] = p[a];
                }
            }
        }
        if q == p {
            q.x += 1.0;
        }
        out.push(Segment::between(p, q));
    }
    out
}

/// Every query kind (single any hit, stream any hit, closest hit, bounded and not) equals
/// brute force, with either kind of boxes; returns the number of occluded segments.
fn check_against_brute(scene: &Scene, tree: &ClusterTree, segs: &[Segment]) -> u64 {
    let mut occluded = 0;
    for boxes in Boxes::ALL {
        let rc = RayCaster::with_boxes(scene, tree, boxes);
        rc.validate().unwrap_or_else(|e| panic!("{boxes:?}: {e}"));
        let mut stream = vec![false; segs.len()];
        rc.occluded_stream(segs, &mut stream);
        occluded = 0;
        for (s, &o) in segs.iter().zip(&stream) {
            let brute = rc.occluded_brute(s.origin, s.dir, s.tmin, s.tmax);
            assert_eq!(rc.occluded(s.origin, s.dir, s.tmin, s.tmax), brute, "{s:?}");
            assert_eq!(o, brute, "stream {boxes:?} {s:?}");
            occluded += brute as u64;
            let bc = rc.closest_brute(s.origin, s.dir, s.tmin, s.tmax);
            assert_eq!(rc.closest(s.origin, s.dir, s.tmin, s.tmax), bc, "{s:?}");
            assert_eq!(bc.is_some(), brute);
            // Unbounded rays too.
            let bc = rc.closest_brute(s.origin, s.dir, 0.0, f32::INFINITY);
            assert_eq!(rc.closest(s.origin, s.dir, 0.0, f32::INFINITY), bc, "{s:?}");
        }
    }
    occluded
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    #[test]
    fn random_trees_match_brute_force(
        seed in any::<u64>(),
        n_random in 0usize..40,
        n_quads in 1usize..12,
    ) {
        let scene = random_scene(seed, n_random, n_quads);
        let tree = random_tree(&scene, seed ^ 0x55);
        let segs = random_segments(&scene, seed ^ 0xAA, 300);
        check_against_brute(&scene, &tree, &segs);
        // The same through every strategy's tree.
        for st in Strategy::ALL {
            let t = ClusterTree::build(&scene, st, &ClusterConfig::default());
            check_against_brute(&scene, &t, &segs[..100]);
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(24))]

    /// Nodes holding up to all of their triangles: runs long enough to be split into pieces
    /// behind boxes of their own with tight boxes.
    #[test]
    fn long_inner_runs_match_brute_force(seed in any::<u64>(), n_random in 40usize..400) {
        let scene = random_scene(seed, n_random, 2);
        let tree = random_tree_keeping(&scene, seed ^ 0x55, 1);
        let segs = random_segments(&scene, seed ^ 0xAA, 200);
        check_against_brute(&scene, &tree, &segs);
    }
}

/// Split runs find the same occluders as whole ones (brute force, every kind of boxes) and test
/// far fewer triangles (measured 69.4 against 447.8 per ray).
#[test]
fn split_runs_test_fewer_triangles() {
    let scene = random_scene(5, 600, 0);
    let tree = random_tree_keeping(&scene, 6, 1);
    let long = tree.nodes.iter().filter(|n| n.num_surfaces > 64).count();
    assert!(long >= 1, "{long}");
    let segs = random_segments(&scene, 7, 2000);
    let occ = check_against_brute(&scene, &tree, &segs);
    assert!(occ > 200 && occ < 1900, "{occ}");
    let split = occlusion_stats(&scene, &tree, Boxes::Tight, &segs);
    let whole = occlusion_stats(&scene, &tree, Boxes::Nodes, &segs);
    assert!(
        split.tris_per_ray() < 0.25 * whole.tris_per_ray(),
        "{} {}",
        split.tris_per_ray(),
        whole.tris_per_ray()
    );
    // Pieces are not nodes of the tree: the nodes visited differ only through the order in
    // which occluders are found (measured 4,259 against 4,157).
    let ratio = split.nodes as f64 / whole.nodes as f64;
    assert!(
        ratio > 0.9 && ratio < 1.1,
        "{} {}",
        split.nodes,
        whole.nodes
    );
}

/// `n` triangles, each with its corners in a cube of side `size` around a centre drawn in the
/// cube `[0, extent]³`.
fn scattered_triangles(seed: u64, n: u32, extent: f32, size: f32) -> Scene {
    let mut g = SplitMix64::new(seed);
    let mut pos = Vec::new();
    let mut tris = Vec::new();
    for i in 0..n {
        let c = Vec3::new(g.next_f32(), g.next_f32(), g.next_f32()) * extent;
        for _ in 0..3 {
            pos.push(c + (Vec3::new(g.next_f32(), g.next_f32(), g.next_f32()) - 0.5) * size);
        }
        tris.push([3 * i, 3 * i + 1, 3 * i + 2]);
    }
    scene_from(pos, tris)
}

/// Binary trees laid out with tight boxes pull inner children up into their parent's lanes
/// (up to eight): a ray visits far fewer nodes than through the tree's own two-lane nodes,
/// with the same answers as brute force (closest hits too).
#[test]
fn binary_trees_are_collapsed_into_wide_nodes() {
    // Small triangles, so that few cross a k-d split plane and stay at inner nodes.
    let scene = scattered_triangles(11, 3000, 4.0, 0.1);
    let segs = random_segments(&scene, 12, 2000);
    for strategy in [Strategy::Kdt, Strategy::Obt, Strategy::Okdt] {
        let tree = ClusterTree::build(&scene, strategy, &ClusterConfig::default());
        assert!(tree.nodes.iter().all(|n| n.num_children <= 2));
        let occ = check_against_brute(&scene, &tree, &segs);
        assert!(occ > 100 && occ < 1900, "{occ}");
        let wide = occlusion_stats(&scene, &tree, Boxes::Tight, &segs);
        let own = occlusion_stats(&scene, &tree, Boxes::Nodes, &segs);
        println!(
            "{strategy:?}: nodes per ray {:.2} collapsed, {:.2} as built",
            wide.nodes_per_ray(),
            own.nodes_per_ray()
        );
        assert!(
            wide.nodes_per_ray() < 0.7 * own.nodes_per_ray(),
            "{strategy:?} {} {}",
            wide.nodes_per_ray(),
            own.nodes_per_ray()
        );
    }
}

/// A malformed tree whose node 9 is a child of both 1 and 2 (contiguous child ranges that
/// overlap; 2 has a triangle of its own, so its box is not empty): every lane of the layout
/// refers to something and rays equal brute force (the layout then keeps the tree's own
/// nodes, without pulling children up).
#[test]
fn a_node_with_two_parents_is_laid_out_safely() {
    let scene = scattered_triangles(5, 12, 2.0, 0.8);
    // (first child, children, surface or none) per node; surface i is listed at index i.
    let shape: [(u32, u32, Option<u32>); 15] = [
        (1, 8, Some(0)),
        (9, 2, None),
        (9, 1, Some(11)),
        (0, 0, Some(1)),
        (0, 0, Some(2)),
        (0, 0, Some(3)),
        (0, 0, Some(4)),
        (0, 0, Some(5)),
        (0, 0, Some(6)),
        (11, 2, None),
        (0, 0, Some(7)),
        (13, 2, None),
        (0, 0, Some(8)),
        (0, 0, Some(9)),
        (0, 0, Some(10)),
    ];
    let mut tree = ClusterTree::build(&scene, Strategy::Sah, &ClusterConfig::default());
    tree.surfaces = (0..12).collect();
    tree.nodes = shape
        .iter()
        .map(
            |&(first_child, num_children, s)| hirad::cluster::ClusterNode {
                bbox: Aabb::EMPTY,
                first_child,
                num_children,
                first_surface: s.unwrap_or(0),
                num_surfaces: s.map_or(0, |_| 1),
                parent: 0,
                depth: 0,
            },
        )
        .collect();
    for (i, &(_, _, s)) in shape.iter().enumerate() {
        if let Some(s) = s {
            tree.surface_node[s as usize] = i as u32;
        }
    }
    for i in (0..shape.len()).rev() {
        let mut b = Aabb::EMPTY;
        let n = tree.nodes[i];
        if n.num_surfaces > 0 {
            b.grow_box(&scene.tri_bbox(n.first_surface as usize));
        }
        for c in n.children() {
            let cb = tree.nodes[c as usize].bbox;
            b.grow_box(&cb);
        }
        tree.nodes[i].bbox = b;
    }
    let segs = random_segments(&scene, 6, 2000);
    let occ = check_against_brute(&scene, &tree, &segs);
    assert!(occ > 20, "{occ}");
}

#[test]
fn hand_built_trees_hit_something() {
    // The random scenes are not trivially empty: a good share of the segments is occluded.
    let scene = random_scene(7, 30, 10);
    let tree = random_tree(&scene, 8);
    let segs = random_segments(&scene, 9, 2000);
    let occ = check_against_brute(&scene, &tree, &segs);
    assert!(occ > 200 && occ < 1900, "{occ}");
    // The tree has inner surfaces and several levels.
    assert!(tree
        .nodes
        .iter()
        .any(|n| n.num_children > 0 && n.num_surfaces > 0));
    assert!(tree.nodes.iter().map(|n| n.depth).max().unwrap() >= 2);
}

/// Closed tessellated surface check: a warped N×N grid; rays aimed at its vertices, edge
/// midpoints and random points from random origins above and below must all hit.
#[test]
fn watertight_on_shared_edges_and_vertices() {
    let n = 24usize;
    let mut g = SplitMix64::new(3);
    let mut pos = Vec::new();
    for j in 0..=n {
        for i in 0..=n {
            // Irregular coordinates (not exactly representable steps) and a warp in z.
            let x = i as f32 / n as f32 * 1.37 + 0.113;
            let y = j as f32 / n as f32 * 0.91 - 0.271;
            let z = 0.05 * (3.1 * x).sin() * (2.3 * y).cos() + 0.002 * g.next_f32();
            pos.push(Vec3::new(x, y, z));
        }
    }
    let id = |i: usize, j: usize| (j * (n + 1) + i) as u32;
    let mut tris = Vec::new();
    for j in 0..n {
        for i in 0..n {
            // Alternate diagonals so that vertices have valence 4 and 8.
            if (i + j) % 2 == 0 {
                tris.push([id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
                tris.push([id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
            } else {
                tris.push([id(i, j), id(i + 1, j), id(i, j + 1)]);
                tris.push([id(i + 1, j), id(i + 1, j + 1), id(i, j + 1)]);
            }
        }
    }
    let scene = scene_from(pos.clone(), tris);
    let tree = random_tree(&scene, 11);
    let rc = RayCaster::new(&scene, &tree);
    let mut targets = Vec::new();
    for j in 1..n {
        for i in 1..n {
            let p = pos[id(i, j) as usize];
            targets.push(p);
            targets.push((p + pos[id(i + 1, j) as usize]) * 0.5);
            targets.push((p + pos[id(i, j + 1) as usize]) * 0.5);
            targets.push((p + pos[id(i + 1, j + 1) as usize]) * 0.5);
            targets.push((pos[id(i + 1, j) as usize] + pos[id(i, j + 1) as usize]) * 0.5);
        }
    }
    let mut rays = 0;
    for (k, &t) in targets.iter().enumerate() {
        for side in [1.0f32, -1.0] {
            let o = Vec3::new(
                0.3 + 0.8 * g.next_f32(),
                -0.2 + 0.6 * g.next_f32(),
                side * (0.5 + 2.0 * g.next_f32()),
            );
            // Long ray through the target: its exact crossing point is within rounding of an
            // edge or vertex of the mesh.
            let d = t - o;
            assert!(
                rc.occluded(o, d, 0.0, 2.0),
                "ray {k} slipped through at {t}"
            );
            assert!(rc.occluded_brute(o, d, 0.0, 2.0));
            let h = rc.closest(o, d, 0.0, 2.0).unwrap();
            assert_eq!(Some(h), rc.closest_brute(o, d, 0.0, 2.0));
            // Targets on a diagonal that is not an edge of the warped mesh lie slightly off it.
            assert!((h.t - 1.0).abs() < 2e-2, "t = {}", h.t);
            // Number of triangles the ray hits: at least one, at most the vertex valence.
            let hits = (0..scene.num_triangles())
                .filter(|&i| {
                    hirad::ray::watertight::intersect_triangle(
                        scene.tri_vertices(i),
                        o,
                        d,
                        0.0,
                        2.0,
                    )
                    .is_some()
                })
                .count();
            assert!((1..=8).contains(&hits), "{hits}");
            rays += 1;
        }
    }
    assert_eq!(rays, 2 * 5 * (n - 1) * (n - 1));
    // Rays along the mesh plane direction through a flat grid of quads (grazing, axis-aligned):
    // the watertight test decides; tree and brute force must agree.
    let flat = random_scene(5, 0, 30);
    let t = random_tree(&flat, 6);
    let segs = random_segments(&flat, 12, 3000);
    check_against_brute(&flat, &t, &segs);
}

/// A straight line through a vertex shared by the fan of a flat polygon hits exactly the
/// triangles that meet there, and a ray through the middle of a shared edge hits both sides.
#[test]
fn shared_edge_hit_counts() {
    // Square split along its diagonal.
    let scene = scene_from(
        vec![Vec3::ZERO, Vec3::X, Vec3::new(1.0, 1.0, 0.0), Vec3::Y],
        vec![[0, 1, 2], [0, 2, 3]],
    );
    let count = |o: Vec3, d: Vec3| {
        (0..2)
            .filter(|&i| {
                hirad::ray::watertight::intersect_triangle(scene.tri_vertices(i), o, d, 0.0, 10.0)
                    .is_some()
            })
            .count()
    };
    // Through the diagonal: both triangles report the hit (no slip, no gap).
    assert_eq!(count(Vec3::new(0.5, 0.5, 1.0), -Vec3::Z), 2);
    assert_eq!(count(Vec3::new(0.25, 0.25, 1.0), -Vec3::Z), 2);
    // Inside one triangle only.
    assert_eq!(count(Vec3::new(0.7, 0.2, 1.0), -Vec3::Z), 1);
    // Oblique rays crossing the diagonal at many points: always at least one hit.
    let mut g = SplitMix64::new(1);
    let tree = ClusterTree::build(&scene, Strategy::Sah, &ClusterConfig::default());
    let rc = RayCaster::new(&scene, &tree);
    for _ in 0..2000 {
        let s = 0.01 + 0.98 * g.next_f32();
        let target = Vec3::new(s, s, 0.0);
        let o = Vec3::new(g.next_f32() * 3.0 - 1.0, g.next_f32() * 3.0 - 1.0, 1.0);
        assert!(count(o, target - o) >= 1);
        assert!(rc.occluded(o, target - o, 0.0, 2.0));
    }
}

#[test]
fn batch_results_do_not_depend_on_threads() {
    let scene = random_scene(21, 200, 40);
    let tree = random_tree(&scene, 22);
    let rc = RayCaster::new(&scene, &tree);
    let segs = hirad::ray::sample::sample_segments(&scene, 5000, 1);
    let run = |threads: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| {
                (
                    rc.occluded_batch(&segs),
                    rc.closest_batch(&segs),
                    rc.occluded_batch_stats(&segs),
                    rc.count_occluded(&segs),
                )
            })
    };
    let a = run(1);
    let b = run(2);
    assert_eq!(a, b);
    let occ = a.0.iter().filter(|&&x| x).count() as u64;
    assert_eq!(occ, a.3);
    assert_eq!(occ, a.2 .0);
    assert_eq!(a.1.iter().filter(|h| h.is_some()).count() as u64, occ);
    let st: RayStats = a.2 .1;
    assert_eq!(st.rays, segs.len() as u64);
    assert!(st.nodes >= st.rays / 2 && st.tris > 0);
    // Sequential calls give the same answers.
    for (s, &o) in segs.iter().zip(&a.0).take(500) {
        assert_eq!(rc.occluded(s.origin, s.dir, s.tmin, s.tmax), o);
    }
}

/// Strategies may leave boxes a hair smaller than their contents (`validate` allows a relative
/// slack of 1e-5): the traversal grows them, so grazing rays still agree with brute force.
#[test]
fn boxes_with_slack_still_exact() {
    let scene = random_scene(31, 10, 20);
    let mut tree = random_tree(&scene, 32);
    let eps = 5e-6 * scene.bbox.size();
    for n in &mut tree.nodes {
        n.bbox.min += Vec3::splat(eps);
        n.bbox.max -= Vec3::splat(eps);
    }
    tree.validate(&Prims::from_scene(&scene)).unwrap();
    // Segments running exactly in the planes of the quads' faces and edges.
    let segs = random_segments(&scene, 33, 3000);
    let occ = check_against_brute(&scene, &tree, &segs);
    assert!(occ > 100, "{occ}");
}

/// Traversal counters of occlusion queries over `segs`.
fn occlusion_stats(scene: &Scene, tree: &ClusterTree, boxes: Boxes, segs: &[Segment]) -> RayStats {
    let rc = RayCaster::with_boxes(scene, tree, boxes);
    let mut st = RayStats::default();
    for s in segs {
        rc.occluded_stats(s.origin, s.dir, s.tmin, s.tmax, &mut st);
    }
    st
}

/// A floor of 48×48 unit squares (two triangles each) at y = 0.25, `quads` upright quads of
/// width `w` and height 1 at random positions at least `margin` from the floor's edges, their
/// bottom `lift` above the floor, and `segs` random segments lying in the floor's plane.
fn floor_with_quads(
    seed: u64,
    quads: usize,
    margin: f32,
    w: f32,
    lift: f32,
    segs: usize,
) -> (Scene, Vec<Segment>) {
    let n = 48usize;
    let y = 0.25f32;
    let mut pos = Vec::new();
    let mut tris = Vec::new();
    for j in 0..=n {
        for i in 0..=n {
            pos.push(Vec3::new(i as f32, y, j as f32));
        }
    }
    let id = |i: usize, j: usize| (j * (n + 1) + i) as u32;
    for j in 0..n {
        for i in 0..n {
            tris.push([id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
            tris.push([id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
        }
    }
    let mut g = SplitMix64::new(seed);
    let span = n as f32 - 2.0 * margin;
    for _ in 0..quads {
        let x = margin + span * g.next_f32();
        let z = margin + span * g.next_f32();
        let b = pos.len() as u32;
        pos.extend([
            Vec3::new(x, y + lift, z),
            Vec3::new(x + w, y + lift, z),
            Vec3::new(x + w, y + lift + 1.0, z),
            Vec3::new(x, y + lift + 1.0, z),
        ]);
        tris.push([b, b + 1, b + 2]);
        tris.push([b, b + 2, b + 3]);
    }
    let scene = scene_from(pos, tris);
    let segs = (0..segs)
        .map(|_| {
            let p = Vec3::new(n as f32 * g.next_f32(), y, n as f32 * g.next_f32());
            let q = Vec3::new(n as f32 * g.next_f32(), y, n as f32 * g.next_f32());
            Segment::between(p, q)
        })
        .collect();
    (scene, segs)
}

/// Segments lying in the plane of a floor (a 48×48 grid of quads at y = 0.25 with boxes
/// standing on it) are coplanar with every floor triangle, which the watertight test never
/// reports as hit: the traversal skips the flat floor boxes such a ray touches and tests almost
/// no triangles, and still agrees with brute force (the boxes standing on the floor occlude).
#[test]
fn rays_in_a_floor_plane_skip_the_floor() {
    // Upright quads standing on the floor (their bottom edge on it).
    let (scene, segs) = floor_with_quads(7, 12, 2.0, 1.5, 0.0, 2000);
    let tris_per_ray = |tree: &ClusterTree, boxes: Boxes| {
        occlusion_stats(&scene, tree, boxes, &segs).tris_per_ray()
    };
    let tree = ClusterTree::build(&scene, Strategy::Sah, &ClusterConfig::default());
    let occ = check_against_brute(&scene, &tree, &segs);
    assert!(occ > 100 && occ < 1900, "{occ}");
    // Without the skip a ray crossing ~24 cells would test dozens of floor triangles.
    let t = tris_per_ray(&tree, Boxes::Tight);
    assert!(t < 2.0, "{t}");
    // k-d cells are cubes, not flat, and keep the floor triangles crossing their split planes
    // at inner nodes: with the cells as boxes a floor ray tests those; with tight boxes the
    // floor cells and those inner runs are flat and skipped as well (cells holding the foot of
    // an upright quad are not: measured 142.1 and 13.4 triangles per ray).
    let kdt = ClusterTree::build(&scene, Strategy::Kdt, &ClusterConfig::default());
    assert_eq!(check_against_brute(&scene, &kdt, &segs), occ);
    let (cells, tight) = (
        tris_per_ray(&kdt, Boxes::Cluster),
        tris_per_ray(&kdt, Boxes::Tight),
    );
    assert!(cells > 100.0 && tight < 20.0, "{cells} {tight}");
}

/// A floor (a 48×48 grid of quads at y = 0.25) under 40 quads floating above it: a segment
/// lying in the floor's plane touches the boxes of the cells holding floor and floating quads
/// along their bottom face, where everything lies in the floor's plane. The traversal skips
/// them (and the floor runs), visiting the root only; with the k-d cells as boxes it visits
/// every cell along the segment. Nothing is occluded, as brute force says.
#[test]
fn floor_rays_skip_cells_standing_on_the_floor() {
    let (scene, segs) = floor_with_quads(11, 40, 1.0, 1.0, 0.5, 1000);
    let kdt = ClusterTree::build(&scene, Strategy::Kdt, &ClusterConfig::default());
    assert_eq!(check_against_brute(&scene, &kdt, &segs), 0);
    let stats = |boxes: Boxes| {
        let st = occlusion_stats(&scene, &kdt, boxes, &segs);
        (st.nodes_per_ray(), st.tris_per_ray())
    };
    assert_eq!(stats(Boxes::Tight), (1.0, 0.0));
    let (nodes, _) = stats(Boxes::Cluster);
    assert!(nodes > 10.0, "{nodes}");
}
