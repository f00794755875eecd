//! Strategy `objr` (object reconstruction): the objects, welded vertices and tree it builds on
//! soups whose construction is known.

use glam::{Affine3A, Quat, Vec3};
use hirad::cluster::{objr, ClusterConfig, ClusterTree, Prims, Strategy};
use hirad::rng::SplitMix64;
use hirad::scene::builtin::mesh::MeshBuilder;
use hirad::scene::builtin::objsoup;
use hirad::scene::{Scene, SceneOptions};
use std::collections::BTreeSet;

/// The soup of a builder: every triangle with its own three vertices, each corner moved by up
/// to `jitter` per coordinate.
fn soup_of(b: &MeshBuilder, jitter: f32, seed: u64) -> Vec<[Vec3; 3]> {
    let mut r = SplitMix64::new(seed);
    let mut j = || (r.next_f32() * 2.0 - 1.0) * jitter;
    b.triangles
        .iter()
        .map(|t| t.map(|v| b.positions[v as usize] + Vec3::new(j(), j(), j())))
        .collect()
}

/// Two tessellated objects share a partition iff the labels map one-to-one.
fn same_partition(a: &[u32], b: &[u32]) -> bool {
    use std::collections::HashMap;
    let (mut ab, mut ba) = (HashMap::new(), HashMap::new());
    a.iter()
        .zip(b)
        .all(|(x, y)| *ab.entry(*x).or_insert(*y) == *y && *ba.entry(*y).or_insert(*x) == *x)
}

#[test]
fn objsoup_objects_are_found_exactly() {
    for (n, seed) in [(5_000u64, 1u64), (40_000, 7)] {
        let (raw, truth) = objsoup::objsoup_truth(n, seed);
        let scene = Scene::from_raw(raw, &SceneOptions::default()).unwrap();
        assert_eq!(scene.num_triangles(), truth.len(), "no triangle dropped");
        let prims = Prims::from_scene(&scene);
        let rec = objr::reconstruct(&prims);
        assert_eq!(rec.num_objects, objsoup::NUM_OBJECTS, "objsoup:{n}@{seed}");
        assert!(same_partition(&rec.object, &truth));
        // Without welding every triangle would be its own object.
        assert_eq!(prims.positions.len(), 3 * prims.len());
    }
}

/// Vertices of closed surfaces from Euler's formula: E = 3F/2, V = χ + E − F.
fn euler_vertices(faces: usize, chi: i64) -> usize {
    assert_eq!(faces % 2, 0);
    (chi + faces as i64 / 2) as usize
}

#[test]
fn welding_merges_duplicated_vertices() {
    // Separate closed solids far apart: a UV sphere (χ = 2), a rotated subdivided box whose
    // faces are separate grids (χ = 2 once welded) and a capped cylinder (χ = 2).
    let mut b = MeshBuilder::new();
    b.sphere(Vec3::ZERO, 1.0, 24, 12, false);
    let f_sphere = b.num_triangles();
    let xf = Affine3A::from_rotation_translation(Quat::from_rotation_y(0.7), Vec3::X * 5.0);
    b.cuboid_subdiv(
        &xf,
        Vec3::ZERO,
        Vec3::new(1.0, 2.0, 0.5),
        false,
        0,
        [4, 7, 3],
    );
    let f_box = b.num_triangles() - f_sphere;
    b.cylinder(Vec3::Z * 4.0, Vec3::new(0.0, 1.5, 4.0), 0.4, 16, 5, true);
    let f_cyl = b.num_triangles() - f_sphere - f_box;
    let expected =
        euler_vertices(f_sphere, 2) + euler_vertices(f_box, 2) + euler_vertices(f_cyl, 2);
    // The sphere's own count: two poles and 24 per inner ring.
    assert_eq!(euler_vertices(f_sphere, 2), 2 + 24 * 11);
    for (jitter, seed) in [(0.0f32, 1u64), (2e-6, 2)] {
        let tris = soup_of(&b, jitter, seed);
        let p = Prims::from_triangles(&tris);
        let rec = objr::reconstruct(&p);
        assert_eq!(rec.num_vertices, expected, "jitter {jitter}");
        assert_eq!(rec.num_objects, 3);
        // Patches: the sphere, six box faces, the cylinder's side and two caps.
        assert_eq!(rec.num_patches, 1 + 6 + 3);
        // The same soup scaled and moved far from the origin welds the same way.
        let far: Vec<[Vec3; 3]> = tris
            .iter()
            .map(|t| t.map(|v| v * 250.0 + Vec3::new(1e4, -3e3, 2e3)))
            .collect();
        assert_eq!(
            objr::reconstruct(&Prims::from_triangles(&far)).num_vertices,
            expected
        );
    }
    // Corners moved by a fifth of the finest edge are distinct vertices: nothing welds
    // across a triangle.
    let coarse = soup_of(&b, 0.0, 3);
    let spread: Vec<[Vec3; 3]> = coarse
        .iter()
        .enumerate()
        .map(|(i, t)| t.map(|v| v + Vec3::splat(0.01 * (i % 7) as f32)))
        .collect();
    let rec = objr::reconstruct(&Prims::from_triangles(&spread));
    assert!(rec.num_vertices > expected, "{}", rec.num_vertices);
}

#[test]
fn tree_follows_the_objects_and_ignores_thread_count() {
    let (raw, truth) = objsoup::objsoup_truth(8_000, 3);
    let scene = Scene::from_raw(raw, &SceneOptions::default()).unwrap();
    let prims = Prims::from_scene(&scene);
    let cfg = ClusterConfig::default();
    let build = |threads: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| ClusterTree::build_prims(&prims, Strategy::Objr, &cfg))
    };
    let t = build(2);
    assert_eq!(t.validate(&prims), Ok(()));
    assert_eq!(t, build(1));
    // Surfaces below every node, children first (they have larger ids). The walls (object 1,
    // an open box around the whole room: its box holds more of the other objects' leaf
    // clusters than of its own) give way to their parts. Every node lies inside one object or
    // holds the other objects whole, and each other object is exactly one node's.
    const WALLS: u32 = 1;
    let size = |o: u32| truth.iter().filter(|&&x| x == o).count();
    let mut whole = vec![false; objsoup::NUM_OBJECTS];
    let mut below: Vec<Vec<u32>> = vec![Vec::new(); t.nodes.len()];
    for id in (0..t.nodes.len()).rev() {
        let mut s = t.node_surfaces(id as u32).to_vec();
        for c in t.nodes[id].children() {
            s.extend(std::mem::take(&mut below[c as usize]));
        }
        let objs: BTreeSet<u32> = s.iter().map(|&x| truth[x as usize]).collect();
        let cover: usize = objs.iter().map(|&o| size(o)).sum();
        if objs.len() > 1 {
            let others = s.iter().filter(|&&x| truth[x as usize] != WALLS).count();
            let whole_others: usize = objs.iter().filter(|&&o| o != WALLS).map(|&o| size(o)).sum();
            assert_eq!(whole_others, others, "node {id} cuts an object");
        } else if cover == s.len() {
            whole[truth[s[0] as usize] as usize] = true;
        }
        below[id] = s;
    }
    assert_eq!(below[0].len(), prims.len());
    let cut: Vec<usize> = (0..whole.len()).filter(|&o| !whole[o]).collect();
    assert_eq!(cut, vec![WALLS as usize], "{whole:?}");
}
