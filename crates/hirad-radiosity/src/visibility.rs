//! Visibility between link ends (`--visibility rays|volume|none`).
//!
//! `rays` casts each shadow segment through the [`ClusterTree`] with the shared
//! [`RayCaster`] (paper §3.2.2: one structure for clustering and ray casting). `none` makes
//! everything mutually visible. `volume` is Sillion's transmittance `τ = exp(−Σ κ_c ℓ_c)`
//! computed by [`VolumeCaster`] through the same tree. Both leave out the same occluders: the
//! link's end elements (a cluster's whole subtree: it does not shadow its own exchanges; a
//! surface itself); every other surface occludes, also inside an end cluster's box.

use super::config::VisibilityMode;
use glam::Vec3;
use hirad_accel::cluster::ClusterTree;
use hirad_accel::ray::volume::{Endpoint, VolumeCaster};
use hirad_accel::ray::{RayCaster, Segment};
use hirad_core::Result;
use hirad_scene::Scene;
use std::hash::Hasher;
use std::sync::Mutex;

thread_local! {
    /// The triangle that blocked this thread's last blocked shadow ray: the first ray of a
    /// link tests it first (links are evaluated in receiver order, so consecutive links
    /// often share an occluder). Only the speed depends on it.
    static LAST_BLOCKER: std::cell::Cell<Option<u32>> = const { std::cell::Cell::new(None) };
}

/// Visibility oracle of a solve.
pub struct Visibility<'a> {
    mode: VisibilityMode,
    tree: &'a ClusterTree,
    caster: RayCaster<'a>,
    /// Per cluster node: its rank in depth-first pre-order and the rank just past its
    /// subtree, so that "surface in the subtree of an end" is two comparisons.
    order: Vec<(u32, u32)>,
    volume: Option<VolumeCaster<'a>>,
    /// Volume mode: clusters smaller than `vol_ratio × segment length` act as volumes.
    pub vol_ratio: f32,
    /// Rounding scale of the scene's coordinates ([`Visibility::eps`]).
    eps: f32,
    /// Shadow segments kept for benchmarks ([`Visibility::record`]): one in `.0`.
    record: Option<(u64, Mutex<Vec<Segment>>)>,
}

impl<'a> Visibility<'a> {
    /// Prepare visibility queries of `mode` over `scene` and its `tree`.
    pub fn new(
        scene: &'a Scene,
        tree: &'a ClusterTree,
        mode: VisibilityMode,
        vol_ratio: f32,
    ) -> Result<Self> {
        Ok(Self {
            mode,
            tree,
            caster: RayCaster::new(scene, tree),
            order: subtree_ranks(tree),
            volume: (mode == VisibilityMode::Volume).then(|| VolumeCaster::new(scene, tree)),
            vol_ratio,
            eps: {
                let c = scene.bbox.min.abs().max(scene.bbox.max.abs()).max_element();
                EPS_REL * if c.is_finite() { c.max(1e-6) } else { 1.0 }
            },
            record: None,
        })
    }

    /// Keep one in `every` of the segments cast by [`Visibility::between`] with rays,
    /// chosen by a hash of their end points (so the same ones whatever the thread count).
    pub fn record(&mut self, every: u32) {
        self.record = Some((every.max(1) as u64, Default::default()));
    }

    /// The segments kept ([`Visibility::record`]), sorted by their bits; taken out, so a second
    /// call returns none.
    pub fn recorded(&self) -> Vec<Segment> {
        let Some((_, m)) = &self.record else {
            return Vec::new();
        };
        let mut v = m
            .lock()
            .map(|mut v| std::mem::take(&mut *v))
            .unwrap_or_default();
        let key = |s: &Segment| [s.origin, s.dir].map(|p| p.to_array().map(f32::to_bits));
        v.sort_unstable_by_key(key);
        v
    }

    /// Keep segment `x + t (y − x)`, `t ∈ range`, when a hash of its end points is a multiple
    /// of `every`.
    #[cold]
    fn keep(&self, every: u64, m: &Mutex<Vec<Segment>>, x: Vec3, y: Vec3, range: (f32, f32)) {
        let mut h = hirad_core::hash::U64Hasher::default();
        for c in [x, y].iter().flat_map(|p| p.to_array()) {
            h.write_u64(c.to_bits() as u64);
        }
        if h.finish().is_multiple_of(every) {
            if let Ok(mut v) = m.lock() {
                v.push(Segment {
                    origin: x,
                    dir: y - x,
                    tmin: range.0,
                    tmax: range.1,
                });
            }
        }
    }

    /// Bytes of the ray layout, the subtree ranks and the volume data.
    pub fn memory_bytes(&self) -> usize {
        self.caster.memory_bytes()
            + self.order.capacity() * 8
            + self.volume.as_ref().map_or(0, |v| v.memory_bytes())
    }

    /// Rounding scale of the scene's coordinates (a length, 1e-6 of the largest coordinate):
    /// shadow rays leave this much out at each end, for the rounding of their end points.
    pub fn eps(&self) -> f32 {
        self.eps
    }

    /// How far from their triangle's edges sample points stay: well beyond what a shadow
    /// ray leaves out at its ends, so that a surface meeting the triangle at an edge is
    /// never inside that left-out stretch.
    pub fn margin(&self) -> f32 {
        4.0 * self.eps
    }

    /// Fraction of light passing between two sample points, along all of the segment but
    /// [`Visibility::eps`] at each end: for rays 0 or 1, where any surface but those of the
    /// ends `a` and `b` (a surface, or every surface in a cluster's subtree) occludes; for
    /// volumes the transmittance with the same ends excluded; 1 for `none`.
    ///
    /// A shadow cache for the several rays between the same ends: `last` holds the triangle
    /// that blocked an earlier ray, which this ray tests first (without one, the triangle
    /// that blocked this thread's last blocked ray), and takes the one that blocks it
    /// (`None` to start); the answer does not depend on it.
    #[inline]
    pub fn between(
        &self,
        x: Vec3,
        y: Vec3,
        a: Endpoint,
        b: Endpoint,
        last: &mut Option<u32>,
    ) -> f64 {
        let t = (self.eps / (y - x).length().max(f32::MIN_POSITIVE)).min(0.25);
        self.transmittance(x, y, (t, 1.0 - t), (a, b), last)
    }

    /// The mode in use.
    pub fn mode(&self) -> VisibilityMode {
        self.mode
    }

    /// True when surface `tri` belongs to end `e` (the surface itself, or a surface in the
    /// subtree of the cluster).
    #[inline]
    fn in_end(&self, e: Endpoint, tri: u32) -> bool {
        match e {
            Endpoint::None => false,
            Endpoint::Surface(s) => s == tri,
            Endpoint::Cluster(c) => {
                let (lo, hi) = self.order[c as usize];
                let r = self.order[self.tree.surface_node[tri as usize] as usize].0;
                lo <= r && r < hi
            }
        }
    }

    /// Fraction of light passing from `x` to `y`: for rays, 0 or 1 from the segment
    /// `x + t (y − x)`, `t ∈ [t0, t1]`, where any surface but those of the ends `a` and `b`
    /// (a surface, or every surface in a cluster's subtree) occludes; for volumes, the
    /// transmittance of the whole segment with the same ends excluded; 1 for `none`. `last`:
    /// the shadow cache of [`Visibility::between`].
    #[inline]
    fn transmittance(
        &self,
        x: Vec3,
        y: Vec3,
        (t0, t1): (f32, f32),
        (a, b): (Endpoint, Endpoint),
        last: &mut Option<u32>,
    ) -> f64 {
        match (self.mode, &self.volume) {
            (VisibilityMode::None, _) => 1.0,
            (VisibilityMode::Volume, Some(v)) => {
                v.transmittance_in(x, y, (t0, t1), self.vol_ratio, (a, b)) as f64
            }
            _ => {
                let skip = |t: u32| self.in_end(a, t) || self.in_end(b, t);
                if t0 >= t1 {
                    return 1.0;
                }
                if let Some((every, m)) = &self.record {
                    self.keep(*every, m, x, y, (t0, t1));
                }
                let hint = last.or_else(|| LAST_BLOCKER.get());
                match self.caster.occluder(x, y - x, (t0, t1), &skip, hint) {
                    Some(tri) => {
                        *last = Some(tri);
                        LAST_BLOCKER.set(Some(tri));
                        0.0
                    }
                    None => 1.0,
                }
            }
        }
    }

    /// Fraction of a distant light (sun, sky direction `dir`, unit length) reaching `origin` on
    /// surface `tri`: 0 or 1 with rays; with volumes, the transmittance of the segment from
    /// `origin` to where it leaves the scene (twice the scene's diagonal away), the surface
    /// itself excluded — so that sun shadows, too, are volumetric (paper Fig. 5). The ray
    /// leaves out [`Visibility::eps`] at its start.
    #[inline]
    pub fn open_to_infinity(&self, origin: Vec3, dir: Vec3, tri: u32) -> f64 {
        match (self.mode, &self.volume) {
            (VisibilityMode::None, _) => 1.0,
            (VisibilityMode::Volume, Some(v)) => {
                let root = v.tree.nodes.first().map(|n| n.bbox.size()).unwrap_or(0.0);
                let far = origin + dir * (2.0 * root * 3f32.sqrt() + 1.0);
                let start = origin + dir * self.eps;
                v.transmittance_in(
                    start,
                    far,
                    (0.0, 1.0),
                    self.vol_ratio,
                    (Endpoint::Surface(tri), Endpoint::None),
                ) as f64
            }
            _ => {
                if self
                    .caster
                    .occluded_except(origin, dir, (self.eps, f32::MAX), &|t| t == tri)
                {
                    0.0
                } else {
                    1.0
                }
            }
        }
    }
}

/// [`Visibility::eps`] over the largest coordinate: 8 units in the last place of an `f32`.
const EPS_REL: f32 = 1e-6;

/// Depth-first pre-order rank of every node and the rank just past its subtree.
fn subtree_ranks(tree: &ClusterTree) -> Vec<(u32, u32)> {
    let mut out = vec![(0u32, 0u32); tree.nodes.len()];
    if tree.nodes.is_empty() {
        return out;
    }
    let mut next = 0u32;
    // (node, children done)
    let mut stack = vec![(0u32, false)];
    while let Some((n, done)) = stack.pop() {
        if done {
            out[n as usize].1 = next;
            continue;
        }
        out[n as usize].0 = next;
        next += 1;
        stack.push((n, true));
        for c in tree.nodes[n as usize].children().rev() {
            stack.push((c, false));
        }
    }
    out
}
