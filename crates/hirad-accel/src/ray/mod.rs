//! Ray casting through a [`ClusterTree`] (paper §3.2.2: one structure for clustering and ray
//! casting): [`RayCaster::occluded`] (any hit) and [`RayCaster::closest`] (first hit) of
//! segments `origin + t·dir`, `t ∈ [tmin, tmax]`, `dir` not necessarily normalised.
//!
//! The result equals a brute-force loop over every triangle ([`RayCaster::occluded_brute`],
//! [`RayCaster::closest_brute`]) for any tree and any [`Boxes`]: the triangle test is
//! watertight, the box test conservative and the boxes contain their contents exactly, so
//! occluded counts are identical across strategies.
//!
//! Submodules: [`sample`] draws the random segments of the paper's ray-casting test exactly as
//! `experiments.md` §2 defines them; [`volume`] computes Sillion's volumetric transmittance
//! through the same tree; [`watertight`] is the triangle test; `layout` stores the tree for
//! traversal (its nodes and triangles on huge pages where the kernel gives them, `pages`);
//! `stack` is the traversal stack; [`turns`] times casters in turns, and [`embree`] puts
//! Embree 3 beside them for scale.

pub mod embree;
mod layout;
mod pages;
pub mod sample;
mod stack;
pub mod turns;
pub mod volume;
pub mod watertight;

use crate::cluster::ClusterTree;
use glam::Vec3;
use hirad_scene::Scene;
pub use layout::Boxes;
use layout::{is_leaf, Layout, Node8, Nodes8, Slab8, NONE};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
pub(crate) use stack::Stack;
use watertight::{intersect, RayPre};

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
    /// Origin (`t = 0`).
    pub origin: Vec3,
    /// Direction, not necessarily normalised (`t = 1` is at `origin + dir`).
    pub dir: Vec3,
    /// Lowest ray parameter tested.
    pub tmin: f32,
    /// Highest ray parameter tested.
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

/// Segments per parallel work item of the batch queries.
const BATCH_CHUNK: usize = 256;
/// Rays in flight in [`RayCaster::occluded_stream`].
pub const STREAM: usize = 8;
/// Stack depth of a ray in flight (deeper queries are redone by the single-ray traversal).
const LANE_STACK: usize = 62;

/// What one step of a ray in flight decided.
enum Step {
    Continue,
    Hit,
    Miss,
    Overflow,
}

/// A ray in flight of [`RayCaster::occluded_stream`].
#[derive(Clone, Copy)]
struct Lane {
    r: RayPre,
    slab: Slab8,
    tmin: f32,
    tmax: f32,
    seg: u32,
    len: u32,
    /// A query is in flight.
    busy: bool,
    stack: [u32; LANE_STACK],
}

impl Lane {
    /// Visit the next node of this ray (the same work as one iteration of
    /// `RayCaster::occluded_loop`, in the same order).
    #[inline(always)]
    fn step<const AVX: bool>(&mut self, n8: &Nodes8, l: &Layout) -> Step {
        if self.len == 0 {
            return Step::Miss;
        }
        self.len -= 1;
        let r = self.stack[self.len as usize];
        let run = if is_leaf(r) {
            n8.leaf(r)
        } else {
            let n = &n8.nodes[r as usize];
            let (mask, _) = self.slab.test::<AVX>(n, self.tmin, self.tmax);
            let mut len = self.len as usize;
            if len + 9 > LANE_STACK {
                if mask != 0 || n.more != NONE {
                    return Step::Overflow;
                }
            } else {
                if n.more != NONE {
                    self.stack[len] = n.more;
                    len += 1;
                }
                // Every lane is stored; the top moves past the hit ones (the highest on top).
                for (i, &c) in n.child.iter().enumerate() {
                    self.stack[len] = c;
                    len += (mask >> i & 1) as usize;
                }
                self.len = len as u32;
            }
            let own = n.num_tris > 0
                && n8.run_hit::<false>(
                    n,
                    &self.r,
                    (self.tmin, self.tmax),
                    &mut RayStats::default(),
                );
            (
                n.tri_start as usize,
                if own { n.num_tris as usize } else { 0 },
            )
        };
        if run.1 > 0
            && l.any_hit::<AVX, _>(&self.r, run, self.tmin, self.tmax, &mut 0, &|_| false)
                .is_some()
        {
            return Step::Hit;
        }
        if self.len > 0 {
            n8.prefetch(l, self.stack[self.len as usize - 1]);
        }
        Step::Continue
    }
}

/// Entry of the traversal stack: node reference and entry distance of its box.
#[derive(Clone, Copy)]
struct Entry {
    node: u32,
    t: f32,
}

/// Ray caster over a scene and one of its cluster trees.
///
/// [`RayCaster::new`] lays the tree out for traversal (`ray/layout/`; with tight boxes, inner
/// children pulled up into their parent's lanes, up to eight, as wide BVHs collapse binary
/// ones): each node as one `Node8` of up to eight child boxes with
/// contiguous planes (one 8-wide slab test per node; a node of more lanes continues in a
/// second one), leaves encoded in their parent's child reference, the triangles attached to
/// each node (inner nodes included) in packets of four for a SIMD edge-function test,
/// everything in depth-first order. Boxes may overlap and a node may have any number of
/// children. The triangle test is watertight ([`watertight`]; the packet test computes the
/// same f32 edge functions, and the scalar test with its f64 hit distance decides every
/// candidate); the box test is conservative (relative slack on the far distance, NaN-safe for
/// rays lying in a box plane) and the boxes contain their contents exactly: tight around them
/// by default (a node's own triangles behind boxes of their own, a long run of them split into
/// pieces, a node holding only one child passed through), or the strategy's boxes grown to
/// their contents ([`Boxes::Cluster`], the paper's traversal; `raybench --boxes cluster`); a
/// box flat along an axis in whose plane the ray lies is skipped, as its contents are coplanar
/// with the ray and the watertight test never reports them (`Slab8::flat_in_plane`: a segment
/// along a floor no longer visits every floor cell it passes).
///
/// Where the CPU has AVX2 the queries run a copy of the traversal compiled for it, which tests
/// a node's eight boxes in one AVX pass (the same f32 operations per lane, hence the same
/// masks) and decides a packet of four triangles at once, hit distances in 4-wide f64
/// (`watertight::hits4_avx`, the scalar test's operations), and a packet of sixteen in one
/// AVX-512 pass where the CPU has it (`watertight::hits16_avx512`). An occlusion query takes the hit
/// children of a node in lane order, not by distance (as Embree's occlusion rays do: the sort
/// cost more than the visits it saved, `docs/perf-log.md` 2026-12-05 (23)), the lanes having
/// been ordered by their chance of blocking a ray per cost (`occlusion_order` in
/// `ray/layout/build.rs`; a node's run tested as soon as its box is hit, and pieces of a run
/// marked to be visited first, come first); the highest hit lane is visited next without going
/// through the stack, and a node is tested together with the stack's next entry when that is
/// a node too. Closest-hit queries push every hit child, nearest on top, and skip
/// entries farther than the current hit. Batch occlusion ([`RayCaster::occluded_stream`],
/// used by [`RayCaster::count_occluded`] and [`RayCaster::occluded_batch`]) keeps [`STREAM`]
/// rays in flight per thread and visits one node of each in turn, in the single-ray order, so
/// that the memory latency of one ray's next node (prefetched at the end of the step before)
/// overlaps with work on the others. Counters ([`RayStats`]) are compiled in only for the
/// `*_stats` entry points (const generic), so the plain queries carry no counting cost.
pub struct RayCaster<'a> {
    /// The scene whose triangles are tested.
    pub scene: &'a Scene,
    /// The cluster tree traversed (built for `scene`).
    pub tree: &'a ClusterTree,
    layout: Layout,
    nodes: Nodes8,
}

/// The next node of an occlusion query below `n`, whose lanes `mask` are hit: the highest hit
/// lane, the others pushed; `None` when no lane is hit. The reference is read before the
/// push, so that the next node's load waits only for the lane (docs/perf-log.md 2026-12-07
/// (59)).
#[inline(always)]
fn descend(n: &Node8, mask: u32, stack: &mut Stack<u32, STACK>) -> Option<u32> {
    if mask == 0 {
        return None;
    }
    let hi = 31 - mask.leading_zeros() as usize;
    let next = n.child[hi];
    stack.push8(&n.child, mask & !(1 << hi));
    Some(next)
}

/// Stack size kept on the machine stack.
const STACK: usize = 128;

impl<'a> RayCaster<'a> {
    /// Prepare the traversal data of `tree`.
    pub fn new(scene: &'a Scene, tree: &'a ClusterTree) -> Self {
        Self::with_boxes(scene, tree, Boxes::default())
    }

    /// Prepare the traversal data of `tree`, testing the boxes `boxes` (same results either
    /// way; [`Boxes::Cluster`] measures the strategy's own boxes).
    pub fn with_boxes(scene: &'a Scene, tree: &'a ClusterTree, boxes: Boxes) -> Self {
        let mut layout = Layout::new(scene, tree, boxes);
        let nodes = Nodes8::new(&layout, scene, boxes != Boxes::Cluster);
        // The groups were the build's form of the nodes; the queries read `nodes`.
        layout.groups = Vec::new();
        layout.faces = Vec::new();
        Self {
            scene,
            tree,
            layout,
            nodes,
        }
    }

    /// Bytes used by the traversal layout.
    pub fn memory_bytes(&self) -> usize {
        self.layout.memory_bytes() + self.nodes.memory_bytes()
    }

    /// Check the laid-out tree's references (tests): every lane with a box reaches a node or
    /// a triangle run in range, and every triangle is reached.
    pub fn validate(&self) -> std::result::Result<(), String> {
        self.nodes
            .validate(&self.layout, self.scene.num_triangles())
    }

    /// True when some triangle is hit for `t ∈ [tmin, tmax]`.
    #[inline]
    pub fn occluded(&self, origin: Vec3, dir: Vec3, tmin: f32, tmax: f32) -> bool {
        let none = &|_| false;
        self.occluded_impl::<false, _>(
            origin,
            dir,
            tmin,
            tmax,
            &mut RayStats::default(),
            none,
            None,
        )
        .is_some()
    }

    /// True when some triangle `t` with `!skip(t)` is hit for `t ∈ [tmin, tmax]` (the
    /// solver's shadow rays leave out the surfaces of a link's own ends).
    #[inline]
    pub fn occluded_except<F: Fn(u32) -> bool>(
        &self,
        origin: Vec3,
        dir: Vec3,
        (tmin, tmax): (f32, f32),
        skip: &F,
    ) -> bool {
        self.occluder(origin, dir, (tmin, tmax), skip, None)
            .is_some()
    }

    /// [`RayCaster::occluded_except`] that returns the triangle found (its id) and tests
    /// triangle `hint` first: the several rays of one link are often blocked by the same
    /// triangle (a shadow cache, Haines & Greenberg 1986). The answer does not depend on the
    /// hint.
    #[inline]
    pub fn occluder<F: Fn(u32) -> bool>(
        &self,
        origin: Vec3,
        dir: Vec3,
        (tmin, tmax): (f32, f32),
        skip: &F,
        hint: Option<u32>,
    ) -> Option<u32> {
        let st = &mut RayStats::default();
        self.occluded_impl::<false, F>(origin, dir, tmin, tmax, st, skip, hint)
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
        self.occluded_impl::<true, _>(origin, dir, tmin, tmax, stats, &|_| false, None)
            .is_some()
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
        let mut out = vec![false; segs.len()];
        out.par_chunks_mut(BATCH_CHUNK)
            .zip(segs.par_chunks(BATCH_CHUNK))
            .for_each(|(o, s)| self.occluded_stream(s, o));
        out
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
        segs.par_chunks(BATCH_CHUNK)
            .map(|s| {
                let mut o = [false; BATCH_CHUNK];
                self.occluded_stream(s, &mut o[..s.len()]);
                o.iter().filter(|&&x| x).count() as u64
            })
            .sum()
    }

    /// Occlusion of `segs` on the calling thread, written to `out` (same length), with
    /// [`STREAM`] rays in flight at once: each step visits one node of each ray in turn, so
    /// the memory loads of one ray's next node (prefetched when it was pushed) overlap with
    /// the work on the others. Same results as [`RayCaster::occluded`] for every segment.
    pub fn occluded_stream(&self, segs: &[Segment], out: &mut [bool]) {
        assert_eq!(segs.len(), out.len(), "one output per segment");
        #[cfg(target_arch = "x86_64")]
        if has_avx2() {
            // SAFETY: the CPU has AVX2 (checked above).
            return unsafe { self.stream_avx2(segs, out) };
        }
        self.stream_impl::<false>(segs, out)
    }

    /// [`RayCaster::stream_impl`] compiled for AVX2, with 8-wide box tests.
    ///
    /// # Safety
    /// The CPU must support AVX2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,popcnt,bmi1,bmi2,lzcnt")]
    unsafe fn stream_avx2(&self, segs: &[Segment], out: &mut [bool]) {
        self.stream_impl::<true>(segs, out)
    }

    /// [`RayCaster::occluded_stream`]; `AVX` as in [`RayCaster::occluded_loop`].
    #[inline(always)]
    fn stream_impl<const AVX: bool>(&self, segs: &[Segment], out: &mut [bool]) {
        let l = &self.layout;
        let n8 = &self.nodes;
        let Some(root) = n8.root else {
            out.fill(false);
            return;
        };
        let idle = Lane {
            r: RayPre::new(Vec3::ZERO, Vec3::X).expect("a valid ray"),
            slab: Slab8::default(),
            tmin: 0.0,
            tmax: 0.0,
            seg: 0,
            len: 0,
            busy: false,
            stack: [0; LANE_STACK],
        };
        let mut lanes = [idle; STREAM];
        let mut next = 0usize;
        // Start the next segment that is not decided at once in `lane`; false when none is
        // left.
        let start = |lane: &mut Lane, next: &mut usize, out: &mut [bool]| -> bool {
            while *next < segs.len() {
                let i = *next;
                *next += 1;
                out[i] = false;
                let s = &segs[i];
                let Some(r) = RayPre::new(s.origin, s.dir) else {
                    continue;
                };
                if s.tmin.is_nan() || s.tmax.is_nan() || s.tmin > s.tmax {
                    continue;
                }
                if r.slab(&l.root_box, s.tmin, s.tmax).is_none() {
                    continue;
                }
                n8.prefetch(l, root);
                lane.slab = Slab8::new(&r);
                lane.r = r;
                lane.tmin = s.tmin;
                lane.tmax = s.tmax;
                lane.seg = i as u32;
                lane.stack[0] = root;
                lane.len = 1;
                lane.busy = true;
                return true;
            }
            lane.busy = false;
            false
        };
        let mut active = 0usize;
        for lane in lanes.iter_mut() {
            active += start(lane, &mut next, out) as usize;
        }
        while active > 0 {
            for lane in lanes.iter_mut() {
                if !lane.busy {
                    continue;
                }
                match lane.step::<AVX>(n8, l) {
                    Step::Continue => continue,
                    Step::Hit => out[lane.seg as usize] = true,
                    Step::Miss => {}
                    Step::Overflow => {
                        let s = &segs[lane.seg as usize];
                        out[lane.seg as usize] = self.occluded(s.origin, s.dir, s.tmin, s.tmax);
                    }
                }
                if !start(lane, &mut next, out) {
                    active -= 1;
                }
            }
        }
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

    /// Corners of scene triangle `i` as the triangle test takes them.
    #[inline]
    fn tri_verts(&self, i: u32) -> watertight::TriVerts {
        watertight::tri_verts(self.scene, i as usize)
    }

    /// Brute-force occlusion: every triangle of the scene, same triangle test.
    pub fn occluded_brute(&self, origin: Vec3, dir: Vec3, tmin: f32, tmax: f32) -> bool {
        let Some(r) = RayPre::new(origin, dir) else {
            return false;
        };
        (0..self.scene.num_triangles())
            .any(|i| intersect(&r, &self.tri_verts(i as u32), tmin, tmax).is_some())
    }

    /// Brute-force closest hit: every triangle of the scene, same triangle test. Ties in `t`
    /// go to the lowest triangle id.
    pub fn closest_brute(&self, origin: Vec3, dir: Vec3, tmin: f32, tmax: f32) -> Option<Hit> {
        let r = RayPre::new(origin, dir)?;
        let mut best: Option<Hit> = None;
        let mut tmax = tmax;
        for i in 0..self.scene.num_triangles() {
            if let Some((t, u, v)) = intersect(&r, &self.tri_verts(i as u32), tmin, tmax) {
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

    /// The occlusion query: a triangle hit (its id) or `None`. With a `hint`, that triangle
    /// is tested first (unless `skip` leaves it out).
    #[inline(always)]
    #[allow(clippy::too_many_arguments)]
    fn occluded_impl<const STATS: bool, F: Fn(u32) -> bool>(
        &self,
        origin: Vec3,
        dir: Vec3,
        tmin: f32,
        tmax: f32,
        stats: &mut RayStats,
        skip: &F,
        hint: Option<u32>,
    ) -> Option<u32> {
        let root = self.nodes.root?;
        let r = RayPre::new(origin, dir)?;
        if tmin.is_nan() || tmax.is_nan() || tmin > tmax {
            return None;
        }
        if let Some(h) = hint {
            let valid = (h as usize) < self.scene.num_triangles() && !skip(h);
            if valid && intersect(&r, &self.tri_verts(h), tmin, tmax).is_some() {
                return Some(h);
            }
        }
        if STATS {
            stats.boxes += 1;
        }
        r.slab(&self.layout.root_box, tmin, tmax)?;
        #[cfg(target_arch = "x86_64")]
        if has_avx2() {
            // SAFETY: the CPU has AVX2 (checked above).
            return unsafe { self.occluded_avx2::<STATS, F>(&r, root, tmin, tmax, stats, skip) };
        }
        self.occluded_loop::<STATS, false, F>(&r, root, tmin, tmax, stats, skip)
    }

    /// [`RayCaster::occluded_loop`] compiled for AVX2, with the 8-wide box test in one pass and
    /// the packet test of `watertight::hits4_avx`.
    ///
    /// # Safety
    /// The CPU must support AVX2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,popcnt,bmi1,bmi2,lzcnt")]
    unsafe fn occluded_avx2<const STATS: bool, F: Fn(u32) -> bool>(
        &self,
        r: &RayPre,
        root: u32,
        tmin: f32,
        tmax: f32,
        stats: &mut RayStats,
        skip: &F,
    ) -> Option<u32> {
        self.occluded_loop::<STATS, true, F>(r, root, tmin, tmax, stats, skip)
    }

    /// The traversal of an occlusion query from `root`, whose box the ray hits: the highest
    /// hit lane of a node is visited next, the others are pushed without a branch per lane
    /// (`Stack::push8`); a node and the stack's next entry, when that is a node, are tested in
    /// one pass. `AVX`: the box test in one AVX pass and packets of four triangles
    /// decided at once (only in [`RayCaster::occluded_avx2`]).
    #[inline(always)]
    fn occluded_loop<const STATS: bool, const AVX: bool, F: Fn(u32) -> bool>(
        &self,
        r: &RayPre,
        root: u32,
        tmin: f32,
        tmax: f32,
        stats: &mut RayStats,
        skip: &F,
    ) -> Option<u32> {
        let (l, n8) = (&self.layout, &self.nodes);
        let slab = Slab8::new(r);
        let mut stack: Stack<u32, STACK> = Stack::new();
        let mut cur = root;
        loop {
            let run = if is_leaf(cur) {
                if STATS {
                    stats.nodes += Nodes8::leaf_counts(cur) as u64;
                }
                n8.leaf(cur)
            } else {
                let n = &n8.nodes[cur as usize];
                // The stack's next entry, when it is a node, is tested in the same pass: its
                // test does not wait for this one's, so the two overlap (docs/perf-log.md
                // 2026-12-08 (60)). Its lanes go below this node's, where it was: nodes are
                // visited in the same order, but its box and its own run are tested early
                // (for nothing when the ray is blocked in this node's subtree).
                if let Some(b) = stack.pop_if(|&r| !is_leaf(r)) {
                    let m = &n8.nodes[b as usize];
                    let (ma, _) = slab.test::<AVX>(n, tmin, tmax);
                    let (mb, _) = slab.test::<AVX>(m, tmin, tmax);
                    if m.more != NONE {
                        stack.push(m.more);
                    }
                    stack.push8(&m.child, mb);
                    if n.more != NONE {
                        stack.push(n.more);
                    }
                    for x in [n, m] {
                        if let Some(hit) =
                            self.node_run::<STATS, AVX, F>(x, r, tmin, tmax, stats, skip)
                        {
                            return Some(hit);
                        }
                    }
                    cur = match descend(n, ma, &mut stack) {
                        Some(c) => c,
                        None => stack.pop()?,
                    };
                    continue;
                }
                let (mask, _) = slab.test::<AVX>(n, tmin, tmax);
                if n.more != NONE {
                    stack.push(n.more);
                }
                if let Some(hit) = self.node_run::<STATS, AVX, F>(n, r, tmin, tmax, stats, skip) {
                    return Some(hit);
                }
                if let Some(c) = descend(n, mask, &mut stack) {
                    cur = c;
                    continue;
                }
                (0, 0)
            };
            if run.1 > 0 {
                let hit = l.any_hit::<AVX, _>(r, run, tmin, tmax, &mut stats.tris, skip);
                if hit.is_some() {
                    return hit;
                }
            }
            cur = stack.pop()?;
        }
    }

    /// A visit of inner node `n` in an occlusion query: counted in `stats`, and its own run
    /// tested when the ray hits the run's box; the run's blocking triangle, if any.
    #[inline(always)]
    fn node_run<const STATS: bool, const AVX: bool, F: Fn(u32) -> bool>(
        &self,
        n: &Node8,
        r: &RayPre,
        tmin: f32,
        tmax: f32,
        stats: &mut RayStats,
        skip: &F,
    ) -> Option<u32> {
        if STATS {
            stats.nodes += n.counts as u64;
            stats.boxes += n.lanes as u64;
        }
        if n.num_tris > 0 && self.nodes.run_hit::<STATS>(n, r, (tmin, tmax), stats) {
            let run = (n.tri_start as usize, n.num_tris as usize);
            return self
                .layout
                .any_hit::<AVX, _>(r, run, tmin, tmax, &mut stats.tris, skip);
        }
        None
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
        let root = self.nodes.root?;
        let r = RayPre::new(origin, dir)?;
        if tmin.is_nan() || tmax.is_nan() || tmin > tmax {
            return None;
        }
        if STATS {
            stats.boxes += 1;
        }
        let t0 = r.slab(&self.layout.root_box, tmin, tmax)?;
        #[cfg(target_arch = "x86_64")]
        if has_avx2() {
            // SAFETY: the CPU has AVX2 (checked above).
            return unsafe { self.closest_avx2::<STATS>(&r, (root, t0), tmin, tmax, stats) };
        }
        self.closest_loop::<STATS, false>(&r, (root, t0), tmin, tmax, stats)
    }

    /// [`RayCaster::closest_loop`] compiled for AVX2, as [`RayCaster::occluded_avx2`].
    ///
    /// # Safety
    /// The CPU must support AVX2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,popcnt,bmi1,bmi2,lzcnt")]
    unsafe fn closest_avx2<const STATS: bool>(
        &self,
        r: &RayPre,
        root: (u32, f32),
        tmin: f32,
        tmax: f32,
        stats: &mut RayStats,
    ) -> Option<Hit> {
        self.closest_loop::<STATS, true>(r, root, tmin, tmax, stats)
    }

    /// The traversal of a closest-hit query from the root (its reference and entry distance):
    /// the nearest hit lane of a node is visited next, the others are pushed, nearest on top
    /// (ties: the later lane first), and popped entries farther than the current hit are
    /// skipped. A single hit lane is visited without the stack, and of two only the farther
    /// is pushed, as in Embree's traversal. `AVX`: as in [`RayCaster::occluded_loop`].
    #[inline(always)]
    fn closest_loop<const STATS: bool, const AVX: bool>(
        &self,
        r: &RayPre,
        (root, t0): (u32, f32),
        tmin: f32,
        tmax: f32,
        stats: &mut RayStats,
    ) -> Option<Hit> {
        let (l, n8) = (&self.layout, &self.nodes);
        let slab = Slab8::new(r);
        let mut best_t = tmax;
        let mut best: Option<(u32, f32, f32)> = None;
        let mut stack: Stack<Entry, STACK> = Stack::new();
        let mut cur = Entry { node: root, t: t0 };
        'visit: loop {
            // Down from `cur` to a leaf or a node without a hit lane.
            loop {
                if is_leaf(cur.node) {
                    let (ts, nt) = n8.leaf(cur.node);
                    if STATS {
                        stats.nodes += Nodes8::leaf_counts(cur.node) as u64;
                        stats.tris += nt as u64;
                    }
                    l.closest_hit::<AVX>(r, ts, nt, tmin, &mut best_t, &mut best);
                    break;
                }
                let n = &n8.nodes[cur.node as usize];
                if STATS {
                    stats.nodes += n.counts as u64;
                    stats.boxes += n.lanes as u64;
                }
                if n.num_tris > 0 && n8.run_hit::<STATS>(n, r, (tmin, best_t), stats) {
                    if STATS {
                        stats.tris += n.num_tris as u64;
                    }
                    let (ts, nt) = (n.tri_start as usize, n.num_tris as usize);
                    l.closest_hit::<AVX>(r, ts, nt, tmin, &mut best_t, &mut best);
                }
                if n.more != NONE {
                    stack.push(Entry {
                        node: n.more,
                        t: cur.t,
                    });
                }
                // Lanes hit within `[tmin, best_t]`: their entry is at most `best_t` (with the
                // slack), so the pop's test below would keep them.
                let (mut mask, tn) = slab.test::<AVX>(n, tmin, best_t);
                let lane = |i: usize| Entry {
                    node: n.child[i],
                    t: tn[i],
                };
                if mask == 0 {
                    break;
                }
                let a = lane(mask.trailing_zeros() as usize);
                mask &= mask - 1;
                if mask == 0 {
                    cur = a;
                    continue;
                }
                let b = lane(mask.trailing_zeros() as usize);
                mask &= mask - 1;
                if mask == 0 {
                    let (near, far) = if b.t.total_cmp(&a.t).is_le() {
                        (b, a)
                    } else {
                        (a, b)
                    };
                    n8.prefetch(l, far.node);
                    stack.push(far);
                    cur = near;
                    continue;
                }
                let before = stack.size();
                for e in [a, b] {
                    n8.prefetch(l, e.node);
                    stack.push(e);
                }
                while mask != 0 {
                    let e = lane(mask.trailing_zeros() as usize);
                    mask &= mask - 1;
                    n8.prefetch(l, e.node);
                    stack.push(e);
                }
                // Nearest on top: an insertion sort by decreasing entry distance, stable (ties
                // keep the lane order, the later lane on top).
                let top = stack.top_mut(stack.size() - before);
                for i in 1..top.len() {
                    let x = top[i];
                    let mut j = i;
                    while j > 0 && top[j - 1].t.total_cmp(&x.t).is_lt() {
                        top[j] = top[j - 1];
                        j -= 1;
                    }
                    top[j] = x;
                }
                cur = stack.pop().expect("three or more entries were pushed");
            }
            while let Some(e) = stack.pop() {
                if e.t > best_t * watertight::BOX_SLACK {
                    continue;
                }
                cur = e;
                continue 'visit;
            }
            break;
        }
        best.map(|(tri, u, v)| Hit {
            t: best_t,
            tri,
            u,
            v,
        })
    }
}

/// Whether the CPU has AVX2 (checked once, then cached by std).
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn has_avx2() -> bool {
    std::arch::is_x86_feature_detected!("avx2")
}

#[cfg(test)]
mod tests;
