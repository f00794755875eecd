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
//! traversal; `stack` is the traversal stack.

mod layout;
pub mod sample;
mod stack;
pub mod volume;
pub mod watertight;

use crate::cluster::ClusterTree;
use glam::Vec3;
use hirad_scene::Scene;
pub use layout::Boxes;
use layout::{Group, Layout, Ray4};
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
    r4: Ray4,
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
    /// `RayCaster::occluded_loop`).
    #[inline(always)]
    fn step<const WIDE: bool>(&mut self, l: &Layout) -> Step {
        if self.len == 0 {
            return Step::Miss;
        }
        self.len -= 1;
        let n = self.stack[self.len as usize];
        let (mut ts, mut nt, g0, ng) = l.node(n);
        let mut all8 = 0;
        #[cfg(target_arch = "x86_64")]
        if WIDE && ng == 2 {
            // SAFETY: `WIDE` is set only under AVX2 (`stream_avx2`).
            all8 = unsafe {
                self.r4.test8(
                    (&l.groups[g0], &l.groups[g0 + 1]),
                    (l.faces[g0], l.faces[g0 + 1]),
                    self.tmin,
                    self.tmax,
                )
            }
            .0;
        }
        for (j, (g, f)) in l.groups[g0..g0 + ng]
            .iter()
            .zip(&l.faces[g0..g0 + ng])
            .enumerate()
        {
            let all = if WIDE && ng == 2 {
                all8 >> (4 * j) & 0xF
            } else {
                self.r4.test(g, f, self.tmin, self.tmax).0
            };
            let (mask, run) = g.split_eager(all);
            let rank = PUSH_ORDER[(mask | (g.eager as u32 & 0xF0 & mask << 4)) as usize];
            if let Some(run) = run {
                (ts, nt) = run;
            }
            let len = self.len as usize;
            if len + 4 > LANE_STACK {
                if mask == 0 {
                    continue;
                }
                return Step::Overflow;
            }
            // Lanes not hit land above the new top, where they are overwritten later.
            for (&r, &c) in rank.iter().zip(&g.child) {
                self.stack[len + (r as usize & 3)] = c;
            }
            self.len += mask.count_ones();
        }
        if nt > 0
            && l.any_hit::<WIDE, _>(&self.r, (ts, nt), self.tmin, self.tmax, &mut 0, &|_| false)
                .is_some()
        {
            return Step::Hit;
        }
        if self.len > 0 {
            l.prefetch(self.stack[self.len as usize - 1]);
        }
        Step::Continue
    }
}

/// Stack positions of the four lanes of a group for occlusion, by `mask | first << 4`
/// (`mask`: lanes hit, `first`: those of them visited first): the hit lanes in lane order, those
/// of `first` after the others (so that the highest of `first` ends on top, as
/// [`descend`] orders them), then the lanes not hit, which land above the new top.
const PUSH_ORDER: [[u8; 4]; 256] = {
    let mut t = [[0u8; 4]; 256];
    let mut k = 0;
    while k < 256 {
        let (mask, first) = (k as u32 & 0xF, k as u32 >> 4);
        let mut pos = 0u8;
        let sets = [mask & !first, mask & first, !mask & 0xF];
        let mut s = 0;
        while s < 3 {
            let mut lane = 0;
            while lane < 4 {
                if sets[s] >> lane & 1 == 1 {
                    t[k][lane] = pos;
                    pos += 1;
                }
                lane += 1;
            }
            s += 1;
        }
        k += 1;
    }
    t
};

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
/// ones): the children of a node in groups of four boxes in structure-of-arrays form
/// (one 4-wide SIMD slab test per group, done by the parent), leaves encoded in their parent's
/// child reference, the triangles attached to each node (inner nodes included) in packets of
/// four for a SIMD edge-function test, everything in depth-first pre-order. Boxes may overlap
/// and a node may have any number of children. The triangle test is watertight
/// ([`watertight`]; the packet test computes the same f32 edge functions, and the scalar test
/// with its f64 hit distance decides every candidate); the box test is conservative
/// (relative slack on the far distance, NaN-safe for rays lying in a box plane) and the boxes
/// contain their contents exactly: tight around them by default (a node's own triangles
/// behind boxes of their own, a long run of them split into pieces, a node holding only one
/// child passed through), or the strategy's boxes grown to their contents
/// ([`Boxes::Cluster`], the paper's traversal; `raybench --boxes cluster`); a box flat along
/// an axis in whose plane the ray lies is skipped, as its contents are coplanar with the ray
/// and the watertight test never reports them (`Ray4::flat_in_plane`: a segment along a
/// floor no longer visits every floor cell it passes).
///
/// Where the CPU has AVX2 the queries run a copy of the traversal compiled for it, which tests
/// the two groups of a node in one 8-wide pass (the same f32 operations per lane, hence the
/// same masks) and decides a packet of four triangles at once, hit distances in 4-wide f64
/// (`watertight::hits4_avx`, the scalar test's operations). An occlusion
/// query takes the hit children of a node in lane order, not by distance (as Embree's
/// occlusion rays do: the sort cost more than the visits it saved, `docs/perf-log.md`
/// 2026-12-05 (23)), the layout having ordered each node's lanes by their chance of blocking a
/// ray per cost (`occlusion_order` in `ray/layout/build.rs`); the last is visited next without
/// going through the stack; pieces of a
/// node's run marked to be visited first are taken before the other lanes. Closest-hit
/// queries push every hit child, nearest on top, and skip entries farther than the current
/// hit. Batch occlusion ([`RayCaster::occluded_stream`], used by
/// [`RayCaster::count_occluded`] and [`RayCaster::occluded_batch`]) keeps [`STREAM`] rays in
/// flight per thread and visits one node of each in turn, so that the memory latency of one
/// ray's next node (prefetched at the end of the step before) overlaps with work on the
/// others; it places the hit children on its stack at positions looked up without branches
/// (`PUSH_ORDER`: the order of the single-ray traversal). Counters ([`RayStats`]) are
/// compiled in only for the `*_stats` entry points (const generic), so the plain queries carry
/// no counting cost.
pub struct RayCaster<'a> {
    /// The scene whose triangles are tested.
    pub scene: &'a Scene,
    /// The cluster tree traversed (built for `scene`).
    pub tree: &'a ClusterTree,
    layout: Layout,
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
        Self {
            scene,
            tree,
            layout: Layout::new(scene, tree, boxes),
        }
    }

    /// Bytes used by the traversal layout.
    pub fn memory_bytes(&self) -> usize {
        self.layout.memory_bytes()
    }

    /// Check the laid-out tree's references (tests): every lane with a box reaches a group or
    /// a triangle run in range, and every triangle is reached.
    pub fn validate(&self) -> std::result::Result<(), String> {
        self.layout.validate(self.scene.num_triangles())
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

    /// [`RayCaster::occluded_stream`]; `WIDE` as in [`RayCaster::occluded_loop`].
    #[inline(always)]
    fn stream_impl<const WIDE: bool>(&self, segs: &[Segment], out: &mut [bool]) {
        let l = &self.layout;
        let Some(root) = l.root else {
            out.fill(false);
            return;
        };
        let idle = Lane {
            r: RayPre::new(Vec3::ZERO, Vec3::X).expect("a valid ray"),
            r4: Ray4::default(),
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
                l.prefetch(root);
                lane.r4.set(&r);
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
                match lane.step::<WIDE>(l) {
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
        let l = &self.layout;
        let root = l.root?;
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
        r.slab(&l.root_box, tmin, tmax)?;
        #[cfg(target_arch = "x86_64")]
        if has_avx2() {
            // SAFETY: the CPU has AVX2 (checked above).
            return unsafe { self.occluded_avx2::<STATS, F>(&r, root, tmin, tmax, stats, skip) };
        }
        self.occluded_loop::<STATS, false, F>(&r, root, tmin, tmax, stats, skip)
    }

    /// [`RayCaster::occluded_loop`] compiled for AVX2, with 8-wide box tests and the packet
    /// test of `watertight::hits4_avx`.
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

    /// The traversal of an occlusion query from `root`, whose box the ray hits. `WIDE`: the
    /// two groups of a node are tested in one AVX pass and packets of four triangles decided
    /// at once (only in [`RayCaster::occluded_avx2`]).
    #[inline(always)]
    fn occluded_loop<const STATS: bool, const WIDE: bool, F: Fn(u32) -> bool>(
        &self,
        r: &RayPre,
        root: u32,
        tmin: f32,
        tmax: f32,
        stats: &mut RayStats,
        skip: &F,
    ) -> Option<u32> {
        let l = &self.layout;
        let r4 = Ray4::new(r);
        let mut stack: Stack<u32, STACK> = Stack::new();
        let mut cur = root;
        loop {
            if STATS {
                stats.nodes += l.is_node(cur) as u64;
            }
            let (mut ts, mut nt, g0, ng) = l.node(cur);
            let mut next = None;
            if ng == 0 {
                // A leaf or a run: only triangles.
            } else if ng <= 2 {
                // One decision over the node's (up to eight) lanes, in lane order.
                let mut mask = 0u32;
                let mut first = 0u32;
                let gs = &l.groups[g0..g0 + ng];
                let ga = &gs[0];
                // The group after the first (the layout ends with an empty group) is tested
                // whatever node it belongs to, so that its loads do not wait for the group
                // count; its lanes count only for a node of two groups (a node of one is tested
                // as two, the second masked out).
                let two = ng == 2;
                let (g1, f1) = (&l.groups[g0 + 1], l.faces[g0 + 1]);
                let gb = std::hint::select_unpredictable(two, g1, &Group::EMPTY);
                let lanes = std::hint::select_unpredictable(two, 0xFF, 0xF);
                let all = lanes
                    & if WIDE {
                        #[cfg(target_arch = "x86_64")]
                        // SAFETY: `WIDE` is set only under AVX2 (`occluded_avx2`).
                        let m = unsafe { r4.test8((ga, g1), (l.faces[g0], f1), tmin, tmax) }.0;
                        #[cfg(not(target_arch = "x86_64"))]
                        let m = unreachable!("the AVX2 copy exists only on x86_64");
                        m
                    } else {
                        r4.test(ga, &l.faces[g0], tmin, tmax).0
                            | r4.test(g1, &f1, tmin, tmax).0 << 4
                    };
                if STATS {
                    stats.boxes += (ga.lanes + gb.lanes) as u64;
                }
                let eager = ga.eager | gb.eager != 0;
                if !eager {
                    mask = all;
                } else {
                    for (j, g) in [ga, gb].into_iter().enumerate() {
                        let (m, run) = g.split_eager(all >> (4 * j) & 0xF);
                        if let Some(run) = run {
                            (ts, nt) = run;
                        }
                        mask |= m << (4 * j);
                        first |= ((g.eager >> 4) as u32) << (4 * j);
                    }
                }
                if !eager {
                    if mask != 0 {
                        // The highest lane is visited next, read straight from its group; the
                        // others are pushed without a branch per lane (in lane order, the
                        // highest on top, as `descend` orders them) beside that read, off its
                        // path (perf-log 29).
                        let hi = 31 - mask.leading_zeros() as usize;
                        stack.push8([&ga.child, &g1.child], mask & !(1 << hi));
                        next = Some([ga, g1][hi >> 2].child[hi & 3]);
                    }
                } else {
                    next = descend(&mut stack, l, mask, first, |i| gs[i >> 2].child[i & 3]);
                }
            } else {
                for (g, f) in l.groups[g0..g0 + ng].iter().zip(&l.faces[g0..g0 + ng]) {
                    if STATS {
                        stats.boxes += g.lanes as u64;
                    }
                    let (all, _) = r4.test(g, f, tmin, tmax);
                    let (mask, run) = g.split_eager(all);
                    if let Some(run) = run {
                        (ts, nt) = run;
                    }
                    if let Some(c) =
                        descend(&mut stack, l, mask, (g.eager >> 4) as u32, |i| g.child[i])
                    {
                        stack.push(c);
                    }
                }
            }
            if nt > 0 {
                let hit = l.any_hit::<WIDE, _>(r, (ts, nt), tmin, tmax, &mut stats.tris, skip);
                if hit.is_some() {
                    return hit;
                }
            }
            cur = match next {
                Some(c) => c,
                None => stack.pop()?,
            };
        }
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
        let root = l.root?;
        let r = RayPre::new(origin, dir)?;
        if tmin.is_nan() || tmax.is_nan() || tmin > tmax {
            return None;
        }
        if STATS {
            stats.boxes += 1;
        }
        let t0 = r.slab(&l.root_box, tmin, tmax)?;
        #[cfg(target_arch = "x86_64")]
        if has_avx2() {
            // SAFETY: the CPU has AVX2 (checked above).
            return unsafe { self.closest_avx2::<STATS>(&r, (root, t0), tmin, tmax, stats) };
        }
        self.closest_loop::<STATS, false>(&r, (root, t0), tmin, tmax, stats)
    }

    /// [`RayCaster::closest_loop`] compiled for AVX2, with 8-wide box tests and the packet
    /// test of `watertight::hits4_avx`.
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

    /// The traversal of a closest-hit query from the root (its reference and entry distance).
    /// `WIDE`: as in [`RayCaster::occluded_loop`].
    #[inline(always)]
    fn closest_loop<const STATS: bool, const WIDE: bool>(
        &self,
        r: &RayPre,
        (root, t0): (u32, f32),
        tmin: f32,
        tmax: f32,
        stats: &mut RayStats,
    ) -> Option<Hit> {
        let l = &self.layout;
        let r4 = Ray4::new(r);
        let mut best_t = tmax;
        let mut best: Option<(u32, f32, f32)> = None;
        let mut stack: Stack<Entry, STACK> = Stack::new();
        stack.push(Entry { node: root, t: t0 });
        while let Some(e) = stack.pop() {
            if e.t > best_t * watertight::BOX_SLACK {
                continue;
            }
            let (ts, nt, g0, ng) = l.node(e.node);
            if STATS {
                stats.nodes += l.is_node(e.node) as u64;
                stats.tris += nt as u64;
            }
            if nt > 0 {
                l.closest_hit::<WIDE>(r, ts, nt, tmin, &mut best_t, &mut best);
            }
            if ng == 1 {
                let g = &l.groups[g0];
                if STATS {
                    stats.boxes += g.lanes as u64;
                }
                let (mask, tn) = r4.test(g, &l.faces[g0], tmin, best_t);
                push_sorted(&mut stack, l, mask, &tn, &g.child, |c, t| Entry {
                    node: c,
                    t,
                });
                continue;
            }
            // More than four children: push every hit, then sort the new entries.
            let before = stack.size();
            #[cfg(target_arch = "x86_64")]
            if WIDE && ng == 2 {
                let gs = &l.groups[g0..g0 + 2];
                if STATS {
                    stats.boxes += (gs[0].lanes + gs[1].lanes) as u64;
                }
                // SAFETY: `WIDE` is set only under AVX2 (`closest_avx2`).
                let (mut mask, tn) = unsafe {
                    r4.test8(
                        (&gs[0], &gs[1]),
                        (l.faces[g0], l.faces[g0 + 1]),
                        tmin,
                        best_t,
                    )
                };
                while mask != 0 {
                    let i = mask.trailing_zeros() as usize;
                    mask &= mask - 1;
                    let c = gs[i >> 2].child[i & 3];
                    l.prefetch(c);
                    stack.push(Entry { node: c, t: tn[i] });
                }
            }
            if !(WIDE && ng == 2) {
                for (g, f) in l.groups[g0..g0 + ng].iter().zip(&l.faces[g0..g0 + ng]) {
                    if STATS {
                        stats.boxes += g.lanes as u64;
                    }
                    let (mut mask, tn) = r4.test(g, f, tmin, best_t);
                    while mask != 0 {
                        let i = mask.trailing_zeros() as usize;
                        mask &= mask - 1;
                        l.prefetch(g.child[i]);
                        stack.push(Entry {
                            node: g.child[i],
                            t: tn[i],
                        });
                    }
                }
            }
            let k = stack.size() - before;
            if k > 1 {
                // Nearest on top: decreasing entry distance.
                stack.top_mut(k).sort_by(|a, b| b.t.total_cmp(&a.t));
            }
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

/// The hit lanes (`mask`) of a node for occlusion, in lane order: the lanes of `first` (pieces
/// visited first) after the others, the highest of each set first. The lane to visit next is
/// returned, the others are pushed so that they are popped in that order.
#[inline(always)]
fn descend<const N: usize>(
    stack: &mut Stack<u32, N>,
    l: &Layout,
    mask: u32,
    first: u32,
    child: impl Fn(usize) -> u32,
) -> Option<u32> {
    let (mut rest, mut last) = (mask & !first, mask & first);
    if last == 0 {
        (rest, last) = (0, rest);
    }
    while rest != 0 {
        let i = rest.trailing_zeros() as usize;
        rest &= rest - 1;
        l.prefetch(child(i));
        stack.push(child(i));
    }
    if last == 0 {
        return None;
    }
    loop {
        let i = last.trailing_zeros() as usize;
        last &= last - 1;
        if last == 0 {
            return Some(child(i));
        }
        l.prefetch(child(i));
        stack.push(child(i));
    }
}

/// Push the hit lanes (`mask`) of one group so that the nearest entry distance is on top
/// (visited first); ties keep the tree's child order.
#[inline(always)]
fn push_sorted<T: Copy, const N: usize>(
    stack: &mut Stack<T, N>,
    l: &Layout,
    mask: u32,
    tn: &[f32; 4],
    child: &[u32; 4],
    entry: impl Fn(u32, f32) -> T,
) {
    match mask.count_ones() {
        0 => {}
        1 => {
            let i = mask.trailing_zeros() as usize;
            l.prefetch(child[i]);
            stack.push(entry(child[i], tn[i]));
        }
        2 => {
            let i = mask.trailing_zeros() as usize;
            let j = (mask & (mask - 1)).trailing_zeros() as usize;
            // Farthest first; on a tie the higher lane first, as below.
            let (a, b) = if tn[i] <= tn[j] { (j, i) } else { (i, j) };
            l.prefetch(child[a]);
            stack.push(entry(child[a], tn[a]));
            l.prefetch(child[b]);
            stack.push(entry(child[b], tn[b]));
        }
        _ => {
            // Lanes sorted by decreasing distance (farthest pushed first).
            let mut idx = [0usize; 4];
            let mut k = 0;
            let mut m = mask;
            while m != 0 {
                let i = m.trailing_zeros() as usize;
                m &= m - 1;
                // Insertion: keep idx[..k] by decreasing tn, ties in decreasing lane order.
                let mut j = k;
                while j > 0 && tn[idx[j - 1]] <= tn[i] {
                    idx[j] = idx[j - 1];
                    j -= 1;
                }
                idx[j] = i;
                k += 1;
            }
            for &i in &idx[..k] {
                l.prefetch(child[i]);
                stack.push(entry(child[i], tn[i]));
            }
        }
    }
}

#[cfg(test)]
mod tests;
