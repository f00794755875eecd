//! Ray casting through a [`ClusterTree`](crate::cluster::ClusterTree) (paper §3.2.2: one
//! structure for clustering and ray casting).
//!
//! Interface used by the solver and the renderer: [`RayCaster::occluded`] (any hit) and
//! [`RayCaster::closest`] (first hit). Segments are `origin + t·dir`, `t ∈ [tmin, tmax]`, `dir`
//! not necessarily normalised.
//!
//! [`RayCaster::new`] lays the tree out for traversal without changing its topology: nodes in
//! depth-first pre-order, the boxes of a node's children stored contiguously with the node
//! (one slab test per child, done by the parent), the triangles attached to each node copied in
//! node order. Surfaces may hang at inner nodes as well as leaves, boxes may overlap and a node
//! may have any number of children. The triangle test is watertight ([`watertight`]) and
//! computes the hit distance accurately (f64 plane equation); the box test is conservative
//! (relative slack on the far distance, NaN-safe for rays lying in a box plane) and the boxes
//! are the strategy's boxes grown to contain their contents exactly, so the result equals a
//! brute-force loop over every triangle ([`RayCaster::occluded_brute`],
//! [`RayCaster::closest_brute`]) for any tree, and occluded counts are identical across
//! strategies.
//!
//! Binary nodes push the nearer child last (visited first) also for occlusion; closest-hit
//! queries sort the hit children of any node by entry distance and skip entries farther than
//! the current hit. Counters ([`RayStats`]) are compiled in only for the `*_stats` entry
//! points (const generic), so the plain queries carry no counting cost.
//!
//! Submodules: [`sample`] draws the random segments of the paper's ray-casting test exactly as
//! `experiments.md` §2 defines them; [`volume`] computes Sillion's volumetric transmittance
//! through the same tree.

pub mod sample;
pub mod volume;
pub mod watertight;

use crate::cluster::ClusterTree;
use crate::geom::Aabb;
use crate::scene::Scene;
use glam::Vec3;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::mem::MaybeUninit;
use watertight::{intersect, RayPre, TriVerts};

/// A ray hit.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    /// Ray parameter of the hit.
    pub t: f32,
    /// Triangle id.
    pub tri: u32,
    /// Barycentric coordinate of vertex 1.
    pub u: f32,
    /// Barycentric coordinate of vertex 2.
    pub v: f32,
}

/// A query segment `origin + t·dir`, `t ∈ [tmin, tmax]`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Segment {
    pub origin: Vec3,
    pub dir: Vec3,
    pub tmin: f32,
    pub tmax: f32,
}

impl Segment {
    /// Lower end of the parameter range of the paper's ray-casting test (`experiments.md` §2).
    pub const SPEC_TMIN: f32 = 1e-4;
    /// Upper end of the parameter range of the paper's ray-casting test.
    pub const SPEC_TMAX: f32 = 1.0 - 1e-4;

    /// Segment from `p` to `q` as the ray-casting test defines it: origin `p`, direction
    /// `q − p`, `t ∈ [1e-4, 1 − 1e-4]`.
    pub fn between(p: Vec3, q: Vec3) -> Segment {
        Segment {
            origin: p,
            dir: q - p,
            tmin: Self::SPEC_TMIN,
            tmax: Self::SPEC_TMAX,
        }
    }
}

/// Traversal counters of one or many queries.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct RayStats {
    /// Queries counted.
    pub rays: u64,
    /// Nodes popped and processed (the root included when its box is hit).
    pub nodes: u64,
    /// Slab tests (root box and child boxes).
    pub boxes: u64,
    /// Ray–triangle tests.
    pub tris: u64,
}

impl RayStats {
    /// Add another set of counters.
    pub fn add(&mut self, o: &RayStats) {
        self.rays += o.rays;
        self.nodes += o.nodes;
        self.boxes += o.boxes;
        self.tris += o.tris;
    }

    /// Mean nodes visited per ray.
    pub fn nodes_per_ray(&self) -> f64 {
        self.nodes as f64 / self.rays.max(1) as f64
    }

    /// Mean triangle tests per ray.
    pub fn tris_per_ray(&self) -> f64 {
        self.tris as f64 / self.rays.max(1) as f64
    }

    /// Mean box tests per ray.
    pub fn boxes_per_ray(&self) -> f64 {
        self.boxes as f64 / self.rays.max(1) as f64
    }
}

/// What the traversal needs to visit a node: where its child entries and its triangles are.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[repr(C)]
struct NodeRef {
    /// First entry of the node's children in [`Layout::children`].
    first_child: u32,
    num_children: u32,
    /// First of the node's triangles in [`Layout::tris`].
    tri_start: u32,
    num_tris: u32,
}

/// A child entry, stored in its parent's contiguous block: the child's box and how to visit
/// it (48 bytes), so that visiting a node reads one block of children and one run of
/// triangles.
#[derive(Clone, Copy, Debug, Default)]
#[repr(C, align(16))]
struct Child {
    /// `[minx, miny, minz, −∞]`.
    lo: [f32; 4],
    /// `[maxx, maxy, maxz, +∞]`.
    hi: [f32; 4],
    node: NodeRef,
}

impl Child {
    fn new(b: &Aabb, node: NodeRef) -> Child {
        Child {
            lo: [b.min.x, b.min.y, b.min.z, f32::NEG_INFINITY],
            hi: [b.max.x, b.max.y, b.max.z, f32::INFINITY],
            node,
        }
    }
}

/// Traversal layout of a cluster tree: nodes in depth-first pre-order (children in tree
/// order); the children blocks and triangle runs of the nodes are stored in that order.
#[derive(Clone, Debug, Default)]
struct Layout {
    /// The root as a child entry (its box is tested first); `None` for a tree without nodes.
    root: Option<Child>,
    children: Vec<Child>,
    /// Triangle corners in node order.
    tris: Vec<TriVerts>,
    /// Scene triangle id of each entry of `tris`.
    tri_id: Vec<u32>,
    /// Pre-order position → tree node id.
    tree_id: Vec<u32>,
}

impl Layout {
    fn new(scene: &Scene, tree: &ClusterTree) -> Layout {
        let n = tree.nodes.len();
        if n == 0 {
            return Layout::default();
        }
        let nt = scene.num_triangles() as u32;
        // Children of a node that the layout follows: valid ids greater than the parent's
        // (true of every laid-out tree; guarantees termination on malformed input).
        let kids = |id: u32| {
            tree.nodes[id as usize]
                .children()
                .filter(move |&c| (c as usize) < n && c > id)
        };
        let surfs = |id: u32| {
            let node = &tree.nodes[id as usize];
            let end =
                (node.first_surface as usize + node.num_surfaces as usize).min(tree.surfaces.len());
            let start = (node.first_surface as usize).min(end);
            tree.surfaces[start..end]
                .iter()
                .copied()
                .filter(|&s| s < nt)
        };
        // Depth-first pre-order.
        let mut order = Vec::with_capacity(n);
        let mut seen = vec![false; n];
        let mut stack = vec![0u32];
        while let Some(id) = stack.pop() {
            if std::mem::replace(&mut seen[id as usize], true) {
                continue;
            }
            order.push(id);
            let mut k: Vec<u32> = kids(id).collect();
            k.reverse();
            stack.extend(k);
        }
        // Pass 1: where each node's children block and triangle run start.
        let mut refs = vec![NodeRef::default(); n];
        let (mut nc, mut ntri) = (0u32, 0u32);
        for &id in &order {
            let c = kids(id).count() as u32;
            let t = surfs(id).count() as u32;
            refs[id as usize] = NodeRef {
                first_child: nc,
                num_children: c,
                tri_start: ntri,
                num_tris: t,
            };
            nc += c;
            ntri += t;
        }
        // Boxes: the strategy's box, grown to contain everything below exactly (strategies
        // may leave an f32 slack that `validate` tolerates; a ray grazing such a triangle must
        // still reach it, so that the result equals brute force for any tree).
        let mut bound = vec![Aabb::EMPTY; n];
        for &id in order.iter().rev() {
            let mut b = tree.nodes[id as usize].bbox;
            for s in surfs(id) {
                b.grow_box(&scene.tri_bbox(s as usize));
            }
            for c in kids(id) {
                let cb = bound[c as usize];
                b.grow_box(&cb);
            }
            bound[id as usize] = b;
        }
        // Pass 2: fill them in.
        let mut children = Vec::with_capacity(nc as usize);
        let mut tris = Vec::with_capacity(ntri as usize);
        let mut tri_id = Vec::with_capacity(ntri as usize);
        for &id in &order {
            for c in kids(id) {
                children.push(Child::new(&bound[c as usize], refs[c as usize]));
            }
            for s in surfs(id) {
                let [a, b, c] = scene.tri_vertices(s as usize);
                tris.push([a.x, a.y, a.z, b.x, b.y, b.z, c.x, c.y, c.z]);
                tri_id.push(s);
            }
        }
        Layout {
            root: Some(Child::new(&bound[0], refs[0])),
            children,
            tris,
            tri_id,
            tree_id: order,
        }
    }
}

/// Hint the cache to load what visiting `n` reads first (its children block and triangles).
#[inline(always)]
fn prefetch_node(l: &Layout, n: &NodeRef) {
    #[cfg(target_arch = "x86_64")]
    {
        use core::arch::x86_64::{_mm_prefetch, _MM_HINT_T0};
        let c = l.children.as_ptr().wrapping_add(n.first_child as usize) as *const i8;
        let t = l.tris.as_ptr().wrapping_add(n.tri_start as usize) as *const i8;
        // SAFETY: a prefetch is only a hint and never faults, whatever the address.
        #[allow(unused_unsafe)]
        unsafe {
            _mm_prefetch::<_MM_HINT_T0>(c);
            _mm_prefetch::<_MM_HINT_T0>(t);
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = (l, n);
}

/// Traversal stack kept in a fixed array on the machine stack (not initialised), spilling to
/// the heap only for very deep or very wide trees.
pub(crate) struct Stack<T: Copy, const N: usize> {
    buf: [MaybeUninit<T>; N],
    len: usize,
    heap: Vec<T>,
    spilled: bool,
}

impl<T: Copy, const N: usize> Stack<T, N> {
    #[inline(always)]
    pub(crate) fn new() -> Self {
        Self {
            buf: [const { MaybeUninit::uninit() }; N],
            len: 0,
            heap: Vec::new(),
            spilled: false,
        }
    }

    #[inline(always)]
    pub(crate) fn push(&mut self, x: T) {
        if !self.spilled {
            if self.len < N {
                self.buf[self.len].write(x);
                self.len += 1;
                return;
            }
            self.heap.reserve(2 * N);
            // SAFETY: the first `len` entries were written by `push`.
            self.heap.extend(
                self.buf[..self.len]
                    .iter()
                    .map(|x| unsafe { x.assume_init() }),
            );
            self.spilled = true;
        }
        self.heap.push(x);
    }

    #[inline(always)]
    pub(crate) fn pop(&mut self) -> Option<T> {
        if self.spilled {
            return self.heap.pop();
        }
        if self.len == 0 {
            return None;
        }
        self.len -= 1;
        // SAFETY: entries below the old `len` were written by `push`.
        Some(unsafe { self.buf[self.len].assume_init() })
    }

    #[inline(always)]
    fn size(&self) -> usize {
        if self.spilled {
            self.heap.len()
        } else {
            self.len
        }
    }

    /// The `k` topmost entries.
    #[inline(always)]
    fn top_mut(&mut self, k: usize) -> &mut [T] {
        if self.spilled {
            let l = self.heap.len();
            &mut self.heap[l - k..]
        } else {
            let s = &mut self.buf[self.len - k..self.len];
            // SAFETY: these entries were written by `push`; MaybeUninit<T> has T's layout.
            unsafe { &mut *(s as *mut [MaybeUninit<T>] as *mut [T]) }
        }
    }
}

/// Entry of the closest-hit stack: node and entry distance of its box.
#[derive(Clone, Copy)]
struct Entry {
    node: NodeRef,
    t: f32,
}

/// Ray caster over a scene and one of its cluster trees.
pub struct RayCaster<'a> {
    pub scene: &'a Scene,
    pub tree: &'a ClusterTree,
    layout: Layout,
}

/// Stack size kept on the machine stack.
const STACK: usize = 128;

impl<'a> RayCaster<'a> {
    /// Prepare the traversal data of `tree`.
    pub fn new(scene: &'a Scene, tree: &'a ClusterTree) -> Self {
        Self {
            scene,
            tree,
            layout: Layout::new(scene, tree),
        }
    }

    /// Bytes used by the traversal layout.
    pub fn memory_bytes(&self) -> usize {
        let l = &self.layout;
        l.children.len() * std::mem::size_of::<Child>()
            + l.tris.len() * (std::mem::size_of::<TriVerts>() + 4)
            + l.tree_id.len() * 4
    }

    /// True when some triangle is hit for `t ∈ [tmin, tmax]`.
    #[inline]
    pub fn occluded(&self, origin: Vec3, dir: Vec3, tmin: f32, tmax: f32) -> bool {
        self.occluded_impl::<false>(origin, dir, tmin, tmax, &mut RayStats::default())
    }

    /// The closest hit for `t ∈ [tmin, tmax]`.
    #[inline]
    pub fn closest(&self, origin: Vec3, dir: Vec3, tmin: f32, tmax: f32) -> Option<Hit> {
        self.closest_impl::<false>(origin, dir, tmin, tmax, &mut RayStats::default())
    }

    /// [`RayCaster::occluded`] that also adds its traversal counters to `stats`.
    pub fn occluded_stats(
        &self,
        origin: Vec3,
        dir: Vec3,
        tmin: f32,
        tmax: f32,
        stats: &mut RayStats,
    ) -> bool {
        stats.rays += 1;
        self.occluded_impl::<true>(origin, dir, tmin, tmax, stats)
    }

    /// [`RayCaster::closest`] that also adds its traversal counters to `stats`.
    pub fn closest_stats(
        &self,
        origin: Vec3,
        dir: Vec3,
        tmin: f32,
        tmax: f32,
        stats: &mut RayStats,
    ) -> Option<Hit> {
        stats.rays += 1;
        self.closest_impl::<true>(origin, dir, tmin, tmax, stats)
    }

    /// Occlusion of many segments, in parallel; the result is in input order and does not
    /// depend on the number of threads.
    pub fn occluded_batch(&self, segs: &[Segment]) -> Vec<bool> {
        segs.par_iter()
            .with_min_len(256)
            .map(|s| self.occluded(s.origin, s.dir, s.tmin, s.tmax))
            .collect()
    }

    /// Closest hits of many segments, in parallel, in input order.
    pub fn closest_batch(&self, segs: &[Segment]) -> Vec<Option<Hit>> {
        segs.par_iter()
            .with_min_len(256)
            .map(|s| self.closest(s.origin, s.dir, s.tmin, s.tmax))
            .collect()
    }

    /// Number of occluded segments (parallel, deterministic).
    pub fn count_occluded(&self, segs: &[Segment]) -> u64 {
        segs.par_iter()
            .with_min_len(256)
            .filter(|s| self.occluded(s.origin, s.dir, s.tmin, s.tmax))
            .count() as u64
    }

    /// Traversal counters of occlusion queries over `segs` (parallel; counts are sums, hence
    /// independent of the thread count).
    pub fn occluded_batch_stats(&self, segs: &[Segment]) -> (u64, RayStats) {
        segs.par_chunks(1024)
            .map(|ch| {
                let mut st = RayStats::default();
                let mut hits = 0u64;
                for s in ch {
                    hits += self.occluded_stats(s.origin, s.dir, s.tmin, s.tmax, &mut st) as u64;
                }
                (hits, st)
            })
            .reduce(
                || (0, RayStats::default()),
                |mut a, b| {
                    a.0 += b.0;
                    a.1.add(&b.1);
                    a
                },
            )
    }

    /// Traversal counters of closest-hit queries over `segs`; also returns the number of hits.
    pub fn closest_batch_stats(&self, segs: &[Segment]) -> (u64, RayStats) {
        segs.par_chunks(1024)
            .map(|ch| {
                let mut st = RayStats::default();
                let mut hits = 0u64;
                for s in ch {
                    hits += self
                        .closest_stats(s.origin, s.dir, s.tmin, s.tmax, &mut st)
                        .is_some() as u64;
                }
                (hits, st)
            })
            .reduce(
                || (0, RayStats::default()),
                |mut a, b| {
                    a.0 += b.0;
                    a.1.add(&b.1);
                    a
                },
            )
    }

    /// Brute-force occlusion: every triangle of the scene, same triangle test.
    pub fn occluded_brute(&self, origin: Vec3, dir: Vec3, tmin: f32, tmax: f32) -> bool {
        let Some(r) = RayPre::new(origin, dir) else {
            return false;
        };
        (0..self.scene.num_triangles()).any(|i| {
            let [a, b, c] = self.scene.tri_vertices(i);
            let v = [a.x, a.y, a.z, b.x, b.y, b.z, c.x, c.y, c.z];
            intersect(&r, &v, tmin, tmax).is_some()
        })
    }

    /// Brute-force closest hit: every triangle of the scene, same triangle test. Ties in `t`
    /// go to the lowest triangle id.
    pub fn closest_brute(&self, origin: Vec3, dir: Vec3, tmin: f32, tmax: f32) -> Option<Hit> {
        let r = RayPre::new(origin, dir)?;
        let mut best: Option<Hit> = None;
        let mut tmax = tmax;
        for i in 0..self.scene.num_triangles() {
            let [a, b, c] = self.scene.tri_vertices(i);
            let v = [a.x, a.y, a.z, b.x, b.y, b.z, c.x, c.y, c.z];
            if let Some((t, u, v)) = intersect(&r, &v, tmin, tmax) {
                if best.is_none_or(|h| t < h.t) {
                    tmax = t;
                    best = Some(Hit {
                        t,
                        tri: i as u32,
                        u,
                        v,
                    });
                }
            }
        }
        best
    }

    #[inline(always)]
    fn occluded_impl<const STATS: bool>(
        &self,
        origin: Vec3,
        dir: Vec3,
        tmin: f32,
        tmax: f32,
        stats: &mut RayStats,
    ) -> bool {
        let l = &self.layout;
        let Some(root) = &l.root else {
            return false;
        };
        let Some(r) = RayPre::new(origin, dir) else {
            return false;
        };
        if tmin.is_nan() || tmax.is_nan() || tmin > tmax {
            return false;
        }
        if STATS {
            stats.boxes += 1;
        }
        if r.slab4(&root.lo, &root.hi, tmin, tmax).is_none() {
            return false;
        }
        let mut stack: Stack<NodeRef, STACK> = Stack::new();
        stack.push(root.node);
        while let Some(n) = stack.pop() {
            if STATS {
                stats.nodes += 1;
            }
            let ts = n.tri_start as usize;
            for tri in &l.tris[ts..ts + n.num_tris as usize] {
                if STATS {
                    stats.tris += 1;
                }
                if intersect(&r, tri, tmin, tmax).is_some() {
                    return true;
                }
            }
            let cs = n.first_child as usize;
            let ch = &l.children[cs..cs + n.num_children as usize];
            if STATS {
                stats.boxes += ch.len() as u64;
            }
            if let [c0, c1] = ch {
                // Binary node: nearer child on top.
                let h0 = r.slab4(&c0.lo, &c0.hi, tmin, tmax);
                let h1 = r.slab4(&c1.lo, &c1.hi, tmin, tmax);
                match (h0, h1) {
                    (Some(t0), Some(t1)) => {
                        prefetch_node(l, &c0.node);
                        prefetch_node(l, &c1.node);
                        if t0 <= t1 {
                            stack.push(c1.node);
                            stack.push(c0.node);
                        } else {
                            stack.push(c0.node);
                            stack.push(c1.node);
                        }
                    }
                    (Some(_), None) => {
                        prefetch_node(l, &c0.node);
                        stack.push(c0.node)
                    }
                    (None, Some(_)) => {
                        prefetch_node(l, &c1.node);
                        stack.push(c1.node)
                    }
                    (None, None) => {}
                }
                continue;
            }
            for c in ch.iter().rev() {
                if r.slab4(&c.lo, &c.hi, tmin, tmax).is_some() {
                    prefetch_node(l, &c.node);
                    stack.push(c.node);
                }
            }
        }
        false
    }

    #[inline(always)]
    fn closest_impl<const STATS: bool>(
        &self,
        origin: Vec3,
        dir: Vec3,
        tmin: f32,
        tmax: f32,
        stats: &mut RayStats,
    ) -> Option<Hit> {
        let l = &self.layout;
        let root = l.root.as_ref()?;
        let r = RayPre::new(origin, dir)?;
        if tmin.is_nan() || tmax.is_nan() || tmin > tmax {
            return None;
        }
        if STATS {
            stats.boxes += 1;
        }
        let t0 = r.slab4(&root.lo, &root.hi, tmin, tmax)?;
        let mut best_t = tmax;
        let mut best: Option<(u32, f32, f32)> = None;
        let mut stack: Stack<Entry, STACK> = Stack::new();
        stack.push(Entry {
            node: root.node,
            t: t0,
        });
        while let Some(e) = stack.pop() {
            if e.t > best_t * watertight::BOX_SLACK {
                continue;
            }
            let n = e.node;
            if STATS {
                stats.nodes += 1;
                stats.tris += n.num_tris as u64;
                stats.boxes += n.num_children as u64;
            }
            for k in n.tri_start..n.tri_start + n.num_tris {
                if let Some((t, u, v)) = intersect(&r, &l.tris[k as usize], tmin, best_t) {
                    // Equal t: keep the lowest triangle id, as the brute-force loop does.
                    let better = match best {
                        None => true,
                        Some(_) if t < best_t => true,
                        Some((bk, _, _)) => l.tri_id[k as usize] < l.tri_id[bk as usize],
                    };
                    if better {
                        best_t = t;
                        best = Some((k, u, v));
                    }
                }
            }
            let cs = n.first_child as usize;
            let before = stack.size();
            for c in &l.children[cs..cs + n.num_children as usize] {
                if let Some(t) = r.slab4(&c.lo, &c.hi, tmin, best_t) {
                    prefetch_node(l, &c.node);
                    stack.push(Entry { node: c.node, t });
                }
            }
            let k = stack.size() - before;
            if k > 1 {
                // Nearest on top: sort the new entries by decreasing entry distance.
                let s = stack.top_mut(k);
                if k <= 16 {
                    for i in 1..k {
                        let x = s[i];
                        let mut j = i;
                        while j > 0 && s[j - 1].t < x.t {
                            s[j] = s[j - 1];
                            j -= 1;
                        }
                        s[j] = x;
                    }
                } else {
                    s.sort_by(|a, b| b.t.total_cmp(&a.t));
                }
            }
        }
        best.map(|(k, u, v)| Hit {
            t: best_t,
            tri: l.tri_id[k as usize],
            u,
            v,
        })
    }
}

#[cfg(test)]
mod tests;
