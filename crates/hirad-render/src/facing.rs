//! Coincident faces: a ray meets them at the same distance and the closest hit may be any of
//! them. The path tracer and the gather take the one a viewer sees by one rule: the face
//! facing the ray (a double-sided lamp panel modelled as two one-sided emitters back to back
//! shows its emitter, not the back of the other), then the solver's order of coplanar
//! overlaps: an emitter (a lamp panel flush with a ceiling shines), then the smaller object
//! (a poster on a wall), then the smaller triangle, then the lower id (a duplicated face is
//! seen once). A light sample on a face counts only where that face is the one seen, so that
//! a duplicated lamp sends its light once, as a ray onto it sees it once.

use glam::Vec3;
use hirad_accel::cluster::ClusterTree;
use hirad_accel::ray::{Hit, RayCaster};
use hirad_core::geom::{drop_axis, longest_edge, project, triangles_overlap};
use hirad_scene::Scene;
use rayon::prelude::*;

/// Plane distance, relative to the larger triangle's longest edge, within which two parallel
/// triangles count as coincident.
const REL_TOL: f32 = 1e-4;

/// Normals within this of parallel or opposite (`|cos|` above `1 − PARALLEL`) make two
/// triangles parallel.
const PARALLEL: f32 = 1e-5;

/// The triangles with a coincident one (their planes within [`REL_TOL`], their interiors
/// overlapping in the plane by more than it: neighbours that only share an edge do not
/// count).
#[derive(Clone, Debug, Default)]
pub(crate) struct Facing {
    /// Sorted triangle ids.
    ids: Vec<u32>,
    /// Surface area of each object.
    object_area: Vec<f64>,
}

impl Facing {
    /// Find the triangles of `scene` with a coincident one, querying the boxes of `tree`.
    pub(crate) fn new(scene: &Scene, tree: &ClusterTree) -> Facing {
        let ids = (0..scene.num_triangles() as u32)
            .into_par_iter()
            .filter(|&i| has_coincident(scene, tree, i))
            .collect::<Vec<u32>>();
        tracing::debug!("{} triangles with a coincident one", ids.len());
        let object_area = if ids.is_empty() {
            Vec::new()
        } else {
            scene.object_areas()
        };
        Facing { ids, object_area }
    }

    /// The hit a ray from `o` along `d` sees: `hit`, or the coincident triangle at the same
    /// distance that comes first by facing the ray, then emitting, then the smaller object's
    /// area, then the smaller triangle's, then the lower id.
    #[inline]
    pub(crate) fn resolve(
        &self,
        scene: &Scene,
        caster: &RayCaster,
        (o, d): (Vec3, Vec3),
        hit: Hit,
    ) -> Hit {
        if self.ids.is_empty() || self.ids.binary_search(&hit.tri).is_err() {
            return hit;
        }
        let rank = |t: u32| {
            let i = t as usize;
            (
                scene.normals[i].dot(d) >= 0.0,
                !scene.material_of(i).is_emitter(),
                self.object_area[scene.tri_object[i] as usize],
                scene.areas[i],
                t,
            )
        };
        let span = (hit.t * (1.0 - 1e-4), hit.t * (1.0 + 1e-4));
        let mut best = hit.tri;
        // Each query finds one that comes before `best`, if any: a few queries at most.
        while let Some(t) = caster.occluder(o, d, span, &|t| rank(t) >= rank(best), None) {
            best = t;
        }
        Hit { tri: best, ..hit }
    }

    /// Whether a light sample at `x + to` on triangle `tri`, unoccluded up to it, is seen
    /// from `x` as `tri` and not as a coincident triangle that [`Facing::resolve`] puts first.
    #[inline]
    pub(crate) fn sees(
        &self,
        scene: &Scene,
        caster: &RayCaster,
        (x, to): (Vec3, Vec3),
        tri: u32,
    ) -> bool {
        if self.ids.is_empty() || self.ids.binary_search(&tri).is_err() {
            return true;
        }
        let hit = Hit {
            t: 1.0,
            tri,
            u: 0.0,
            v: 0.0,
        };
        self.resolve(scene, caster, (x, to), hit).tri == tri
    }
}

/// True when a triangle parallel to triangle `i` (facing either way) lies in its plane and
/// overlaps it there (both within the tolerance).
fn has_coincident(scene: &Scene, tree: &ClusterTree, i: u32) -> bool {
    if scene.areas[i as usize] <= 0.0 {
        return false;
    }
    let vi = scene.tri_vertices(i as usize);
    let ni = scene.normals[i as usize];
    let bb = scene.tri_bbox(i as usize);
    let grow = Vec3::splat(REL_TOL * longest_edge(&vi));
    let (lo, hi) = (bb.min - grow, bb.max + grow);
    let axis = drop_axis(ni);
    let pi = vi.map(|p| project(p, axis));
    tree.any_surface_near(lo, hi, |j| {
        if j == i
            || scene.areas[j as usize] <= 0.0
            || ni.dot(scene.normals[j as usize]).abs() < 1.0 - PARALLEL
        {
            return false;
        }
        let vj = scene.tri_vertices(j as usize);
        let tol = REL_TOL * longest_edge(&vi).max(longest_edge(&vj));
        let bj = scene.tri_bbox(j as usize);
        vj.iter().all(|p| ni.dot(*p - vi[0]).abs() <= tol)
            && bj.max.cmpge(lo).all()
            && bj.min.cmple(hi).all()
            && triangles_overlap(&pi, &vj.map(|p| project(p, axis)), tol)
    })
}
