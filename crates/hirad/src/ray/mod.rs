//! Ray casting through a [`ClusterTree`](crate::cluster::ClusterTree) (paper §3.2.2: one
//! structure for clustering and ray casting).
//!
//! Interface used by the solver and the renderer: [`RayCaster::occluded`] (any hit) and
//! [`RayCaster::closest`] (first hit). Segments are `origin + t·dir`, `t ∈ [tmin, tmax]`, `dir`
//! not necessarily normalised.
//!
//! The current body is a brute-force loop over every triangle (correct, slow): the tree
//! traversal replaces it.

use crate::cluster::ClusterTree;
use crate::scene::Scene;
use glam::Vec3;

/// A ray hit.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    /// Ray parameter of the hit.
    pub t: f32,
    /// Triangle id.
    pub tri: u32,
    /// Barycentric coordinates (u for vertex 1, v for vertex 2).
    pub u: f32,
    pub v: f32,
}

/// Ray caster over a scene and one of its cluster trees.
pub struct RayCaster<'a> {
    pub scene: &'a Scene,
    pub tree: &'a ClusterTree,
}

impl<'a> RayCaster<'a> {
    /// Prepare the traversal data of `tree`.
    pub fn new(scene: &'a Scene, tree: &'a ClusterTree) -> Self {
        Self { scene, tree }
    }

    /// True when some triangle is hit for `t ∈ [tmin, tmax]`.
    pub fn occluded(&self, origin: Vec3, dir: Vec3, tmin: f32, tmax: f32) -> bool {
        (0..self.scene.num_triangles())
            .any(|i| intersect(self.scene.tri_vertices(i), origin, dir, tmin, tmax).is_some())
    }

    /// The closest hit for `t ∈ [tmin, tmax]`.
    pub fn closest(&self, origin: Vec3, dir: Vec3, tmin: f32, tmax: f32) -> Option<Hit> {
        let mut best: Option<Hit> = None;
        let mut tmax = tmax;
        for i in 0..self.scene.num_triangles() {
            if let Some((t, u, v)) = intersect(self.scene.tri_vertices(i), origin, dir, tmin, tmax)
            {
                tmax = t;
                best = Some(Hit {
                    t,
                    tri: i as u32,
                    u,
                    v,
                });
            }
        }
        best
    }
}

/// Möller–Trumbore (placeholder until the watertight test lands).
fn intersect(
    [p0, p1, p2]: [Vec3; 3],
    o: Vec3,
    d: Vec3,
    tmin: f32,
    tmax: f32,
) -> Option<(f32, f32, f32)> {
    let e1 = p1 - p0;
    let e2 = p2 - p0;
    let p = d.cross(e2);
    let det = e1.dot(p);
    if det == 0.0 {
        return None;
    }
    let inv = 1.0 / det;
    let s = o - p0;
    let u = s.dot(p) * inv;
    if !(0.0..=1.0).contains(&u) {
        return None;
    }
    let q = s.cross(e1);
    let v = d.dot(q) * inv;
    if v < 0.0 || u + v > 1.0 {
        return None;
    }
    let t = e2.dot(q) * inv;
    (t >= tmin && t <= tmax).then_some((t, u, v))
}
