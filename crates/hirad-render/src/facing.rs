//! Coincident faces that face opposite ways (a double-sided lamp panel modelled as two
//! one-sided emitters back to back): a ray meets both at the same distance, and the closest
//! hit may be either. The path tracer and the gather take the one facing the ray, as the
//! solver does (its coplanar overlaps give that side to the face that looks out of it), so a
//! ray onto such a panel sees the emitter facing it instead of the back of the other (which
//! absorbs, or reflects, and loses the panel's emission).

use glam::Vec3;
use hirad_accel::cluster::ClusterTree;
use hirad_accel::ray::{Hit, RayCaster};
use hirad_core::geom::longest_edge;
use hirad_scene::Scene;
use rayon::prelude::*;

/// Plane distance, relative to the larger triangle's longest edge, within which two parallel
/// triangles facing opposite ways count as coincident.
const REL_TOL: f32 = 1e-4;

/// Normals within this of opposite (`cos` below `−1 + PARALLEL`) make two triangles face
/// opposite ways.
const PARALLEL: f32 = 1e-5;

/// The triangles with a coincident one facing the other way (their planes within
/// [`REL_TOL`], their boxes overlapping: a superset of those that overlap it; the ray query of
/// [`Facing::resolve`] decides).
#[derive(Clone, Debug, Default)]
pub(crate) struct Facing {
    /// Sorted triangle ids.
    ids: Vec<u32>,
}

impl Facing {
    /// Find the triangles of `scene` with a coincident opposite one, querying the boxes of
    /// `tree`.
    pub(crate) fn new(scene: &Scene, tree: &ClusterTree) -> Facing {
        let ids = (0..scene.num_triangles() as u32)
            .into_par_iter()
            .filter(|&i| has_opposite(scene, tree, i))
            .collect::<Vec<u32>>();
        tracing::debug!("{} triangles with a coincident one facing away", ids.len());
        Facing { ids }
    }

    /// The hit a ray from `o` along `d` sees: `hit`, or when `hit` shows its back and a
    /// coincident triangle faces the ray at the same distance, that one.
    #[inline]
    pub(crate) fn resolve(
        &self,
        scene: &Scene,
        caster: &RayCaster,
        (o, d): (Vec3, Vec3),
        hit: Hit,
    ) -> Hit {
        if self.ids.is_empty()
            || scene.normals[hit.tri as usize].dot(d) < 0.0
            || self.ids.binary_search(&hit.tri).is_err()
        {
            return hit;
        }
        let span = (hit.t * (1.0 - 1e-4), hit.t * (1.0 + 1e-4));
        let away = |t: u32| scene.normals[t as usize].dot(d) >= 0.0;
        match caster.occluder(o, d, span, &away, None) {
            Some(tri) => Hit { tri, ..hit },
            None => hit,
        }
    }
}

/// True when a triangle facing away from triangle `i` lies in its plane (within the
/// tolerance) with a box overlapping its box.
fn has_opposite(scene: &Scene, tree: &ClusterTree, i: u32) -> bool {
    if scene.areas[i as usize] <= 0.0 {
        return false;
    }
    let vi = scene.tri_vertices(i as usize);
    let ni = scene.normals[i as usize];
    let bb = scene.tri_bbox(i as usize);
    let grow = Vec3::splat(REL_TOL * longest_edge(&vi));
    let (lo, hi) = (bb.min - grow, bb.max + grow);
    tree.any_surface_near(lo, hi, |j| {
        if j == i
            || scene.areas[j as usize] <= 0.0
            || ni.dot(scene.normals[j as usize]) > -1.0 + PARALLEL
        {
            return false;
        }
        let vj = scene.tri_vertices(j as usize);
        let tol = REL_TOL * longest_edge(&vi).max(longest_edge(&vj));
        let bj = scene.tri_bbox(j as usize);
        vj.iter().all(|p| ni.dot(*p - vi[0]).abs() <= tol)
            && bj.max.cmpge(lo).all()
            && bj.min.cmple(hi).all()
    })
}
