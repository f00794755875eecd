//! Approximate volumetric visibility through a cluster tree (Sillion 1995; `--visibility
//! volume`): the transmittance of a segment is `exp(−Σ κ_c ℓ_c)` over the clusters used as
//! volumes, with `κ_c = ΣA_c / (4 V_c)` and `ℓ_c` the length of the segment inside the box of
//! `c`; clusters too large for the segment are descended into and their own surfaces tested
//! exactly (so `vol_ratio = 0` gives exact ray-cast visibility). [`VolumeCaster`] gives the
//! rules in full: which clusters are used as volumes, the end points, flat boxes.

use super::watertight::{intersect, tri_verts, RayPre, TriVerts};
use super::{Segment, Stack};
use crate::cluster::{objr, ClusterTree, Prims, NONE};
use glam::Vec3;
use hirad_core::geom::Aabb;
use hirad_core::hash::U64Map;
use hirad_scene::Scene;
use rayon::prelude::*;

/// Minimum edge of a padded cluster box, relative to its size.
pub const PAD_REL: f32 = 1e-3;

/// Default `vol_ratio` of `radiosity.md`.
pub const DEFAULT_VOL_RATIO: f32 = 0.1;

/// A cluster is a medium (may be a volume) only while the part of every object below it is
/// smaller than this fraction of its size.
pub const OBJECT_REL: f32 = 0.5;

/// An end point of a transmittance query, whose own cluster must not shadow it.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Endpoint {
    /// No exclusion.
    #[default]
    None,
    /// A cluster (tree node id): it and its subtree contribute nothing, its ancestors are not
    /// used as volumes.
    Cluster(u32),
    /// A surface (triangle id): it is not tested, the clusters containing it are not used as
    /// volumes.
    Surface(u32),
}

/// One query of [`VolumeCaster::transmittance_batch`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VolumeQuery {
    /// Start of the segment.
    pub p: Vec3,
    /// End of the segment.
    pub q: Vec3,
    /// What lies at `p`.
    pub a: Endpoint,
    /// What lies at `q`.
    pub b: Endpoint,
}

/// Volumetric transmittance through the clusters of a tree.
///
/// The transmittance of a segment `p → q` is `τ = exp(−Σ κ_c ℓ_c)`, where the sum runs over the
/// clusters used as volumes, `κ_c = ΣA_c / (4 V_c)` (ΣA_c = total area of every surface below
/// `c`, attached to it or to a descendant; `V_c` = volume of its box) and `ℓ_c` is the length of
/// the segment inside the box of `c`.
///
/// Rules, in traversal order from the root (only clusters whose box the segment crosses are
/// visited):
/// - a cluster is used as a volume when its size (longest box edge) is below
///   `vol_ratio × |q − p|`, it is a *medium*, it is not *excluded* and its box contains
///   neither end point; its subtree is then not visited;
/// - otherwise the traversal descends: the surfaces attached directly to that cluster are
///   tested exactly against the segment (watertight test, `t ∈ [1e-4, 1 − 1e-4]` as for the
///   ray-casting test); an exact hit makes `τ = 0`. With `vol_ratio = 0` the result is therefore
///   exact ray-cast visibility (0 or 1), and it changes continuously into the volumetric
///   estimate as `vol_ratio` grows;
/// - end points are given as [`Endpoint`]s. For [`Endpoint::Cluster`]`(c)` the cluster `c` and
///   its whole subtree contribute nothing (a cluster does not shadow its own emission), and the
///   ancestors of `c` are never used as volumes (their volume contains `c`; they are descended
///   into, so their other contents still count). For [`Endpoint::Surface`]`(s)` the surface `s`
///   is never tested and the cluster holding `s` and its ancestors are never used as volumes.
///   Nor is any cluster whose box contains an end point (within [`PAD_REL`] × its size and
///   the point's rounding): the segment starts among its surfaces, not across a random
///   medium (a lamp inside a closed box sees walls in every direction);
/// - the model stands for many small objects scattered in a cluster (foliage), not for a
///   surface through it: a cluster is a *medium* when the part of every object below it
///   (welded connected surfaces of one material, as `objr` finds them) is smaller than
///   [`OBJECT_REL`] × the size of what lies below it, and its surfaces do not all lie within
///   [`PAD_REL`] × its size of one plane. Through a piece of a wall or of a closed box, where
///   the model would let `exp(−κℓ)` through, the surfaces are tested exactly.
///
/// Zero volume: boxes with an edge shorter than [`PAD_REL`] × their size get every edge padded
/// to that, symmetrically, both for `V_c` and for `ℓ_c`. Boxes of size 0 (a point) have
/// `κ = 0`.
///
/// Note on the model: `ΣA/4` is the mean projected area of one-sided surfaces weighted by
/// `max(0, cos)`. The mean projected area of a randomly oriented polygon seen from both sides
/// (what blocks a ray) is `A/2`, so for a random, well-distributed set of small polygons the
/// ray-cast transmittance is close to `τ²`. The tests check that relation.
pub struct VolumeCaster<'a> {
    /// The scene whose triangles are tested.
    pub scene: &'a Scene,
    /// The cluster tree traversed (built for `scene`).
    pub tree: &'a ClusterTree,
    /// Extinction coefficient per node, `ΣA / (4 V)` with the padded box.
    kappa: Vec<f32>,
    /// Padded box per node (for `ℓ_c`).
    padded: Vec<[f32; 6]>,
    /// Box per node for the visit test (grown to contain its contents exactly).
    boxes: Vec<[f32; 6]>,
    /// Size (longest edge of the real box) per node.
    size: Vec<f32>,
    /// Per node: a medium (see the rules), which may be used as a volume.
    medium: Vec<bool>,
    /// Vertices of every entry of the tree's surface array (`ClusterTree::surfaces`), for
    /// the exact tests without going through the scene's index.
    verts: Vec<TriVerts>,
    /// Depth-first numbering: node `x` is an ancestor-or-self of `y` iff
    /// `pre[x] <= pre[y] < end[x]`.
    pre: Vec<u32>,
    end: Vec<u32>,
}

/// Resolved exclusion of one end point.
#[derive(Clone, Copy)]
struct Excl {
    /// Cluster whose subtree is skipped (`NONE` when none).
    skip: u32,
    /// Cluster whose ancestors-or-self are not volumes (`NONE` when none).
    holder: u32,
    /// Surface not tested (`NONE` when none).
    surface: u32,
}

/// `b` as `[min x, min y, min z, max x, max y, max z]`, the form the box tests read.
pub(in crate::ray) fn box6(b: &Aabb) -> [f32; 6] {
    [b.min.x, b.min.y, b.min.z, b.max.x, b.max.y, b.max.z]
}

/// True when `p` lies in the box `b` grown by `t` (the caller adds the rounding of `p`'s
/// coordinates: an end point computed on a surface of the box may fall just outside it).
#[inline]
fn contains(b: &[f32; 6], p: Vec3, t: f32) -> bool {
    (0..3).all(|a| b[a] - t <= p[a] && p[a] <= b[a + 3] + t)
}

/// The children of node `id` that come after it (the bottom-up passes below visit them
/// first).
fn children_after(tree: &ClusterTree, id: usize) -> Vec<usize> {
    let n = tree.nodes.len();
    tree.nodes[id]
        .children()
        .map(|c| c as usize)
        .filter(|&c| c < n && c > id)
        .collect()
}

/// Per node: whether it is a medium (see [`VolumeCaster`]) as far as objects go: the size
/// (longest box edge) of the largest part of one object below it, objects as
/// [`objr::reconstruct`] finds them, is below [`OBJECT_REL`] × the size of the tight box of
/// everything below it. Bottom up, each node's map object → box is its largest child's, with
/// the others' entries and its own surfaces merged in (so every surface moves O(log n)
/// times; the order of a merge does not change its result); only entries that grow can
/// exceed the largest child's maximum.
fn small_objects(scene: &Scene, tree: &ClusterTree) -> Vec<bool> {
    let n = tree.nodes.len();
    let object = objr::reconstruct(&Prims::from_scene(scene)).object;
    let mut maps: Vec<U64Map<Aabb>> = (0..n).map(|_| U64Map::default()).collect();
    let mut piece = vec![0f32; n];
    let mut tight = vec![Aabb::EMPTY; n];
    let mut out = vec![false; n];
    for id in (0..n).rev() {
        let kids = children_after(tree, id);
        let big = kids.iter().copied().max_by_key(|&c| maps[c].len());
        let mut map = big
            .map(|c| std::mem::take(&mut maps[c]))
            .unwrap_or_default();
        let mut largest = big.map_or(0.0, |c| piece[c]);
        let mut all = Aabb::EMPTY;
        for &c in &kids {
            all.grow_box(&tight[c]);
        }
        let mut add = |map: &mut U64Map<Aabb>, obj: u32, b: &Aabb| {
            let e = map.entry(obj as u64).or_insert(Aabb::EMPTY);
            e.grow_box(b);
            largest = largest.max(e.size());
        };
        for &c in &kids {
            if Some(c) != big {
                for (k, b) in std::mem::take(&mut maps[c]) {
                    add(&mut map, k as u32, &b);
                }
            }
        }
        for &s in tree.node_surfaces(id as u32) {
            if let Some(&o) = object.get(s as usize) {
                let b = scene.tri_bbox(s as usize);
                all.grow_box(&b);
                add(&mut map, o, &b);
            }
        }
        piece[id] = largest;
        tight[id] = all;
        out[id] = !all.is_empty() && largest < OBJECT_REL * all.size();
        maps[id] = map;
    }
    out
}

/// Per node: whether every surface below it lies within [`PAD_REL`] × its size (at least the
/// rounding of its coordinates) of one plane. Bottom up: a node's plane is that of its
/// largest own surface, else of its first child; a flat child of plane `(n_c, d_c)` and
/// deviation `δ_c` deviates from the plane `(n, d)` by at most
/// `δ_c + max over its box corners x of |(n − n_c)·x − (d − d_c)|` (`grown`: per node, a box
/// containing everything below it).
fn flat_nodes(scene: &Scene, tree: &ClusterTree, grown: &[Aabb]) -> Vec<bool> {
    let n = tree.nodes.len();
    // (unit normal, offset, deviation) of a flat node.
    let mut plane: Vec<Option<(glam::DVec3, f64, f64)>> = vec![None; n];
    for id in (0..n).rev() {
        let node = &tree.nodes[id];
        let b = node.bbox;
        let scale = b.min.abs().max(b.max.abs()).max_element() as f64;
        let tol = (PAD_REL as f64 * b.size() as f64).max(8.0 * f32::EPSILON as f64 * scale);
        let own = tree.node_surfaces(id as u32);
        let kids = children_after(tree, id);
        if kids.iter().any(|&c| plane[c].is_none()) {
            continue;
        }
        let reference = own
            .iter()
            .map(|&s| s as usize)
            .filter(|&s| s < scene.num_triangles())
            .max_by(|&x, &y| scene.areas[x].total_cmp(&scene.areas[y]))
            .map(|s| {
                let nrm = scene.normals[s].as_dvec3();
                (nrm, nrm.dot(scene.tri_vertices(s)[0].as_dvec3()))
            })
            .or_else(|| kids.first().and_then(|&c| plane[c].map(|(m, d, _)| (m, d))));
        let Some((nrm, d)) = reference else {
            continue;
        };
        let mut dev = 0f64;
        for &s in own {
            if (s as usize) < scene.num_triangles() {
                for v in scene.tri_vertices(s as usize) {
                    dev = dev.max((nrm.dot(v.as_dvec3()) - d).abs());
                }
            }
        }
        for &c in &kids {
            let Some((mut m, mut dc, dev_c)) = plane[c] else {
                continue;
            };
            if m.dot(nrm) < 0.0 {
                (m, dc) = (-m, -dc);
            }
            let cb = grown[c];
            let (lo, hi) = (cb.min.as_dvec3(), cb.max.as_dvec3());
            let dn = nrm - m;
            // The linear function's extreme over the box is at the corner its gradient picks.
            let far = glam::DVec3::select(dn.cmpge(glam::DVec3::ZERO), hi, lo);
            let near = glam::DVec3::select(dn.cmpge(glam::DVec3::ZERO), lo, hi);
            let spread = (dn.dot(far) - (d - dc))
                .abs()
                .max((dn.dot(near) - (d - dc)).abs());
            dev = dev.max(dev_c + spread);
        }
        if dev <= tol {
            plane[id] = Some((nrm, d, dev));
        }
    }
    plane.iter().map(Option::is_some).collect()
}

impl<'a> VolumeCaster<'a> {
    /// Bytes of the per-node arrays.
    pub fn memory_bytes(&self) -> usize {
        (self.kappa.capacity() + self.size.capacity() + self.pre.capacity() + self.end.capacity())
            * 4
            + self.medium.capacity()
            + self.verts.capacity() * std::mem::size_of::<TriVerts>()
            + (self.padded.capacity() + self.boxes.capacity()) * 24
    }

    /// Precompute extinction coefficients and padded boxes of every cluster.
    pub fn new(scene: &'a Scene, tree: &'a ClusterTree) -> Self {
        let n = tree.nodes.len();
        // Total area below each node: children have larger ids than their parent.
        let mut area = vec![0f64; n];
        for id in (0..n).rev() {
            let mut a: f64 = tree
                .node_surfaces(id as u32)
                .iter()
                .filter_map(|&s| scene.areas.get(s as usize))
                .map(|&x| x as f64)
                .sum();
            for c in tree.nodes[id].children() {
                if (c as usize) < n && c as usize > id {
                    a += area[c as usize];
                }
            }
            area[id] = a;
        }
        // Visit boxes: the strategy's box grown to contain everything below exactly (as in the
        // ray caster), so that the exact tests agree with ray casting for any tree.
        let mut grown: Vec<Aabb> = tree.nodes.iter().map(|x| x.bbox).collect();
        for id in (0..n).rev() {
            let mut b = grown[id];
            for &s in tree.node_surfaces(id as u32) {
                if (s as usize) < scene.num_triangles() {
                    b.grow_box(&scene.tri_bbox(s as usize));
                }
            }
            for c in tree.nodes[id].children() {
                if (c as usize) < n && c as usize > id {
                    b.grow_box(&grown[c as usize]);
                }
            }
            grown[id] = b;
        }
        let flat = flat_nodes(scene, tree, &grown);
        let small = small_objects(scene, tree);
        let mut kappa = Vec::with_capacity(n);
        let mut padded = Vec::with_capacity(n);
        let mut boxes = Vec::with_capacity(n);
        let mut size = Vec::with_capacity(n);
        for (id, node) in tree.nodes.iter().enumerate() {
            let b = node.bbox;
            let s = b.size();
            let pb = if b.is_empty() {
                b
            } else {
                let e = b.extent().max(Vec3::splat(PAD_REL * s));
                let c = b.center();
                Aabb::new(b.min.min(c - e * 0.5), b.max.max(c + e * 0.5))
            };
            let v = pb.volume_f64();
            let k = if v > 0.0 && s > 0.0 {
                (area[id] / (4.0 * v)) as f32
            } else {
                0.0
            };
            kappa.push(k);
            padded.push(box6(&pb));
            boxes.push(box6(&grown[id]));
            size.push(s);
        }
        let medium = (0..n).map(|id| small[id] && !flat[id]).collect();
        // Depth-first numbering.
        let mut pre = vec![0u32; n];
        let mut end = vec![0u32; n];
        if n > 0 {
            let mut counter = 0u32;
            // (node, children pushed?)
            let mut stack = vec![(0u32, false)];
            while let Some((id, done)) = stack.pop() {
                if done {
                    end[id as usize] = counter;
                    continue;
                }
                pre[id as usize] = counter;
                counter += 1;
                stack.push((id, true));
                for c in tree.nodes[id as usize].children().rev() {
                    if (c as usize) < n && c > id {
                        stack.push((c, false));
                    }
                }
            }
        }
        VolumeCaster {
            scene,
            tree,
            kappa,
            padded,
            boxes,
            size,
            medium,
            verts: tree
                .surfaces
                .iter()
                .map(|&s| {
                    if (s as usize) < scene.num_triangles() {
                        tri_verts(scene, s as usize)
                    } else {
                        [0.0; 9]
                    }
                })
                .collect(),
            pre,
            end,
        }
    }

    /// Extinction coefficient `κ = ΣA / (4V)` of a cluster.
    pub fn kappa(&self, node: u32) -> f32 {
        self.kappa[node as usize]
    }

    #[inline]
    fn is_anc_or_self(&self, x: u32, y: u32) -> bool {
        if x == NONE || y == NONE {
            return false;
        }
        let (px, py) = (self.pre[x as usize], self.pre[y as usize]);
        px <= py && py < self.end[x as usize]
    }

    fn resolve(&self, e: Endpoint) -> Excl {
        let n = self.tree.nodes.len() as u32;
        match e {
            Endpoint::None => Excl {
                skip: NONE,
                holder: NONE,
                surface: NONE,
            },
            Endpoint::Cluster(c) if c < n => Excl {
                skip: c,
                holder: c,
                surface: NONE,
            },
            Endpoint::Surface(s) => {
                let holder = self
                    .tree
                    .surface_node
                    .get(s as usize)
                    .copied()
                    .filter(|&h| h < n)
                    .unwrap_or(NONE);
                Excl {
                    skip: NONE,
                    holder,
                    surface: s,
                }
            }
            Endpoint::Cluster(_) => Excl {
                skip: NONE,
                holder: NONE,
                surface: NONE,
            },
        }
    }

    /// Transmittance `τ ∈ [0, 1]` between `p` and `q` (see the module docs for the rules).
    pub fn transmittance(
        &self,
        p: Vec3,
        q: Vec3,
        vol_ratio: f32,
        exclude_a: Endpoint,
        exclude_b: Endpoint,
    ) -> f32 {
        self.transmittance_in(
            p,
            q,
            (Segment::SPEC_TMIN, Segment::SPEC_TMAX),
            vol_ratio,
            (exclude_a, exclude_b),
        )
    }

    /// [`VolumeCaster::transmittance`] of the part `t ∈ [tmin, tmax]` of the segment
    /// `p + t (q − p)` (the solver's shadow segments leave out less than the spec's test).
    pub fn transmittance_in(
        &self,
        p: Vec3,
        q: Vec3,
        range: (f32, f32),
        vol_ratio: f32,
        (exclude_a, exclude_b): (Endpoint, Endpoint),
    ) -> f32 {
        self.optical_depth(p, q, range, vol_ratio, (exclude_a, exclude_b))
            .map_or(0.0, |d| (-d).exp() as f32)
    }

    /// Optical depth `Σ κ_c ℓ_c` of the part `t ∈ [tmin, tmax]` of the segment, or `None`
    /// when an exactly tested surface blocks it.
    pub fn optical_depth(
        &self,
        p: Vec3,
        q: Vec3,
        (tmin, tmax): (f32, f32),
        vol_ratio: f32,
        (exclude_a, exclude_b): (Endpoint, Endpoint),
    ) -> Option<f64> {
        if self.tree.nodes.is_empty() {
            return Some(0.0);
        }
        let dir = q - p;
        let len = dir.length();
        let Some(r) = RayPre::new(p, dir) else {
            return Some(0.0);
        };
        let ea = self.resolve(exclude_a);
        let eb = self.resolve(exclude_b);
        let limit = vol_ratio * len;
        let mut depth = 0f64;
        if r.slab(&self.boxes[0], tmin, tmax).is_none() {
            return Some(0.0);
        }
        // Tolerances of the end points' containment tests, without the cluster's part.
        let (tp, tq) = (
            8.0 * f32::EPSILON * p.abs().max_element(),
            8.0 * f32::EPSILON * q.abs().max_element(),
        );
        let mut stack: Stack<u32, 128> = Stack::new();
        stack.push(0);
        while let Some(c) = stack.pop() {
            if c == ea.skip || c == eb.skip {
                continue;
            }
            let ci = c as usize;
            if self.medium[ci] && self.size[ci] < limit {
                let b = &self.boxes[ci];
                let t = PAD_REL * self.size[ci];
                let holds_end = self.is_anc_or_self(c, ea.holder)
                    || self.is_anc_or_self(c, eb.holder)
                    || contains(b, p, t + tp)
                    || contains(b, q, t + tq);
                if !holds_end {
                    depth +=
                        self.kappa[ci] as f64 * self.inside_length(p, dir, (tmin, tmax), ci, len);
                    continue;
                }
            }
            let node = &self.tree.nodes[ci];
            let first = node.first_surface as usize;
            for (k, &s) in self.tree.node_surfaces(c).iter().enumerate() {
                if s == ea.surface || s == eb.surface {
                    continue;
                }
                if intersect(&r, &self.verts[first + k], tmin, tmax).is_some() {
                    return None;
                }
            }
            for ch in node.children() {
                if r.slab(&self.boxes[ch as usize], tmin, tmax).is_some() {
                    stack.push(ch);
                }
            }
        }
        Some(depth)
    }

    /// Length of the segment's parameter range `[tmin, tmax]` inside the padded box of node
    /// `ci`.
    fn inside_length(&self, p: Vec3, dir: Vec3, range: (f32, f32), ci: usize, len: f32) -> f64 {
        // In f64: ℓ of a thin (padded) box is a small difference of parameters.
        let b = &self.padded[ci];
        let mut tn = range.0 as f64;
        let mut tf = range.1 as f64;
        for a in 0..3 {
            let o = p[a] as f64;
            let d = dir[a] as f64;
            let (lo, hi) = (b[a] as f64, b[a + 3] as f64);
            if d == 0.0 {
                if o < lo || o > hi {
                    return 0.0;
                }
                continue;
            }
            let (t0, t1) = if d > 0.0 {
                ((lo - o) / d, (hi - o) / d)
            } else {
                ((hi - o) / d, (lo - o) / d)
            };
            tn = tn.max(t0);
            tf = tf.min(t1);
        }
        (tf - tn).max(0.0) * len as f64
    }

    /// Transmittances of many queries in parallel (input order, independent of the thread
    /// count).
    pub fn transmittance_batch(&self, queries: &[VolumeQuery], vol_ratio: f32) -> Vec<f32> {
        queries
            .par_iter()
            .with_min_len(64)
            .map(|x| self.transmittance(x.p, x.q, vol_ratio, x.a, x.b))
            .collect()
    }
}
