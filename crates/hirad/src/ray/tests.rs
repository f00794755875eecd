//! Unit tests of the traversal layout.

use super::*;
use crate::cluster::{BuildNode, BuildTree, ClusterConfig, Strategy};
use crate::geom::Aabb;
use crate::scene::{Material, RawScene, SceneOptions};

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

/// Root holding triangle 1 with one leaf child holding triangle 0.
fn inner_surface_tree(scene: &Scene) -> ClusterTree {
    let mut b = BuildTree::default();
    let leaf = b.push(BuildNode {
        bbox: scene.tri_bbox(0),
        children: vec![],
        surfaces: vec![0],
    });
    b.root = b.push(BuildNode {
        bbox: scene.bbox,
        children: vec![leaf],
        surfaces: vec![1],
    });
    ClusterTree::from_build(b, 2, Strategy::Sah, ClusterConfig::default())
}

#[test]
fn layout_is_depth_first_with_inner_surfaces() {
    let s = two_tri_scene();
    let t = inner_surface_tree(&s);
    let rc = RayCaster::new(&s, &t);
    assert_eq!(rc.layout.tree_id, vec![0, 1]);
    assert_eq!(rc.layout.tri_id, vec![1, 0]);
    assert_eq!(rc.layout.children.len(), 1);
    let root = rc.layout.root.unwrap().node;
    assert_eq!(
        (
            root.first_child,
            root.num_children,
            root.tri_start,
            root.num_tris
        ),
        (0, 1, 0, 1)
    );
    let leaf = rc.layout.children[0].node;
    assert_eq!(
        (leaf.num_children, leaf.tri_start, leaf.num_tris),
        (0, 1, 1)
    );
    let _ = Aabb::EMPTY;
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
    let mut st = RayStats::default();
    assert!(rc
        .closest_stats(Vec3::new(0.2, 0.2, 2.0), -Vec3::Z, 0.0, 10.0, &mut st)
        .is_some());
    assert_eq!(st.rays, 1);
    // The hit at the root (t = 1) culls the child box (entry t = 2).
    assert_eq!(st.nodes, 1);
    assert_eq!(st.tris, 1);
    assert_eq!(st.boxes, 2);
    let mut st = RayStats::default();
    assert!(rc.occluded_stats(Vec3::new(0.2, 0.2, -1.0), Vec3::Z, 0.0, 10.0, &mut st));
    // Any hit stops the query: the root's own triangle (t = 2) is tested first and hit.
    assert_eq!((st.nodes, st.tris, st.boxes), (1, 1, 1));
    let mut st = RayStats::default();
    assert!(rc.occluded_stats(Vec3::new(0.2, 0.2, -1.0), Vec3::Z, 0.0, 1.5, &mut st));
    // With tmax = 1.5 the root triangle is missed and the leaf's is hit.
    assert_eq!((st.nodes, st.tris, st.boxes), (2, 2, 2));
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
