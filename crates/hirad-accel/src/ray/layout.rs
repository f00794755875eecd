//! Traversal layout of a cluster tree: the tree's own nodes and children, stored for fast
//! box tests (the topology is kept: no node is added or merged, and every triangle is tested
//! at the node it is attached to; with tight boxes a node without triangles of its own and
//! with a single child, whose box is its child's, is passed through: its parent's lane refers
//! to the child).
//!
//! - A node with children (or with more triangles than a leaf reference can hold) owns
//!   `⌈children/4⌉` consecutive [`Group`]s of 128 bytes: the boxes of up to four children in
//!   structure-of-arrays form (one 4-wide SIMD slab test checks all four), the children's
//!   references, the node's own triangle run (surfaces attached at inner nodes) and, in the
//!   first group, its number of groups.
//! - A leaf is not stored as a node at all: its reference in the parent's group encodes its
//!   triangle run directly (bit 31 set, 5 bits of count, a chunk bit, 25 bits of first
//!   packet), so reaching a leaf reads only its triangles.
//! - Triangles are stored four to a [`Packet`] (structure of arrays, one SIMD edge test for
//!   four triangles); each node's run starts a new packet, unused lanes are masked out. Runs of
//!   [`WIDE_MIN`] triangles or more (surfaces attached at inner nodes of `kdt`, `obt`, `okdt`,
//!   large leaves) are stored sixteen to a [`Wide`] packet instead, tested in one AVX-512 pass
//!   where the CPU has it (four SSE passes otherwise). Which array a run lives in follows
//!   from its length alone.
//! - Groups and triangle runs are in depth-first pre-order, so a subtree is contiguous.
//!
//! Boxes ([`Boxes`]): by default every box is tight around what lies below its node (the
//! union of its own triangles' boxes and its children's boxes), whatever box the strategy
//! gave it — `kdt`/`obt` nodes keep their k-d cells, mostly empty space — and the triangles
//! of an inner node whose last group has a free lane get a box of their own in that lane: the
//! node's one SIMD test then decides them with its children, and they are tested only when
//! the ray hits their box (straddling surfaces of a k-d node, a strip of floor); occlusion
//! tests them at once or visits them in distance order like a leaf ([`EAGER_HITS_PER_TEST`]).
//! A run longer than [`CHUNK_MAX`] (the hundreds of surfaces a `kdt` node keeps because they
//! cross its split plane, a large leaf) is split into pieces behind boxes of their own
//! ([`RunTree`]) when a cost model says it pays: the pieces take the run's lanes, larger
//! pieces are groups of four smaller ones (marked [`SUB`]: not nodes of the tree, not counted
//! as nodes visited), and the smallest are chunks of at most 16 triangles (up to 31 where a
//! further split would not pay) referenced like leaves (with the [`CHUNK`] bit). The pieces
//! of a run tested at once are visited before the node's other lanes ([`FIRST`]).
//! [`Boxes::Nodes`] keeps every run whole. Every lane also carries six face bits
//! ([`face_bits`]) that let a ray lying in the plane of a face skip it
//! (`Ray4::flat_in_plane`). With
//! [`Boxes::Cluster`] the boxes are the strategy's boxes grown to contain their contents
//! exactly (strategies may leave an f32 slack that `validate` tolerates; a ray grazing such
//! a triangle must still reach it, so that the result equals brute force for any tree), and
//! a node's triangles are tested whenever it is visited, as the paper's traversal does.

use super::watertight::{
    candidates4, candidates4_at, intersect, tri_of, RayPre, Tri16, Tri4, BOX_SLACK,
};
use crate::cluster::ClusterTree;
use hirad_core::choice;
use hirad_core::geom::Aabb;
use hirad_scene::Scene;
use serde::{Deserialize, Serialize};

/// Reference flag of a leaf encoded in place.
pub(super) const LEAF: u32 = 1 << 31;
const LEAF_COUNT_SHIFT: u32 = 26;
/// Largest triangle count of an in-place leaf.
const LEAF_MAX_TRIS: usize = (1 << (31 - LEAF_COUNT_SHIFT)) - 1;
/// Flag of an in-place run that is a piece of a node's own triangles ([`CHUNK_MAX`]), not a
/// leaf of the tree.
const CHUNK: u32 = 1 << 25;
/// Largest first packet of an in-place leaf.
const LEAF_MAX_START: usize = CHUNK as usize - 1;
/// Reference flag of a node's own triangle run behind a box of its own (bit 31 clear): the
/// low bits are the index of the group holding the run.
pub(super) const RUN: u32 = 1 << 30;
/// Reference of an empty lane.
pub(super) const NONE: u32 = u32::MAX;

/// Decode the triangle run `(first packet, count)` of a leaf (or chunk) reference.
#[inline(always)]
pub(super) fn leaf_run(r: u32) -> (usize, usize) {
    (
        (r & LEAF_MAX_START as u32) as usize,
        ((r & !LEAF) >> LEAF_COUNT_SHIFT) as usize,
    )
}

fn leaf_ref(start: usize, count: usize) -> u32 {
    LEAF | ((count as u32) << LEAF_COUNT_SHIFT) | start as u32
}

/// Up to four children of one node: boxes in structure-of-arrays form and references.
#[derive(Clone, Copy, Debug)]
#[repr(C, align(64))]
pub(super) struct Group {
    /// `[min x, min y, min z, max x, max y, max z]`, one lane per child; empty lanes hold an
    /// inverted infinite box (never hit).
    pub b: [[f32; 4]; 6],
    /// Child references: a group index, a leaf ([`LEAF`] bit; with the [`CHUNK`] bit a chunk
    /// of a split run), the node's own run ([`RUN`] bit) or [`NONE`].
    pub child: [u32; 4],
    /// The node's own triangle run: first packet and number of triangles. Held by the first
    /// group of a node and tested whenever the node is visited, unless the run has a box of
    /// its own in a free lane ([`Group::run`]): then the group holding that lane holds the
    /// run, and the lane's reference ([`RUN`] | that group) is pushed and visited like a
    /// leaf's when the ray hits it.
    pub tri_start: u32,
    pub num_tris: u32,
    /// Number of consecutive groups of the node (first group only).
    pub num_groups: u32,
    /// Number of non-empty lanes in this group (the run's lane included).
    pub lanes: u8,
    /// Bit of the run's lane when occlusion queries test the run as soon as that lane is hit
    /// ([`EAGER_HITS_PER_TEST`]) instead of pushing its reference; bits 4–7: lanes holding
    /// pieces of such a run split into a [`RunTree`], which occlusion queries visit before the
    /// other lanes hit ([`FIRST`] shifted by the lane).
    pub eager: u8,
    /// Bit of the lane holding the box of the node's own triangle run (0: none in this group);
    /// [`SUB`] in a group of pieces of a split run.
    pub run: u16,
}

impl Group {
    /// Split the hit mask `all` of this group for occlusion: the lanes to push, and the
    /// node's own run `(first packet, count)` when `all` hits its lane and the run is tested
    /// at once ([`Group::eager`]).
    #[inline(always)]
    pub(super) fn split_eager(&self, all: u32) -> (u32, Option<(usize, usize)>) {
        let eager = (self.eager & 0xF) as u32;
        let run = (all & eager != 0).then_some((self.tri_start as usize, self.num_tris as usize));
        (all & !eager, run)
    }

    /// Rank the pieces visited first ([`FIRST`]) nearest: entry distance `-f32::MAX`.
    #[inline(always)]
    pub(super) fn rank_first(&self, tn: &mut [f32; 4]) {
        let mut m = self.eager >> 4;
        while m != 0 {
            tn[m.trailing_zeros() as usize] = -f32::MAX;
            m &= m - 1;
        }
    }

    /// Put `b` and reference `r` in `lane`.
    pub(super) fn set_lane(&mut self, lane: usize, b: &Aabb, r: u32) {
        for a in 0..3 {
            self.b[a][lane] = b.min[a];
            self.b[a + 3][lane] = b.max[a];
        }
        self.child[lane] = r;
        self.lanes += 1;
    }
}

impl Default for Group {
    fn default() -> Self {
        let inf = f32::INFINITY;
        Group {
            b: [
                [inf; 4], [inf; 4], [inf; 4], [-inf; 4], [-inf; 4], [-inf; 4],
            ],
            child: [NONE; 4],
            tri_start: 0,
            num_tris: 0,
            num_groups: 0,
            lanes: 0,
            eager: 0,
            run: 0,
        }
    }
}

/// A node's own run behind its box is tested as soon as that box is hit (occlusion queries;
/// before the children it was tested with are visited) when a random line through the box
/// crosses at least this many of its triangles per triangle tested; otherwise its reference is
/// pushed and visited in distance order with the children. Walls and floors straddling a k-d
/// plane are likely occluders and are best tested at once; hundreds of leaves straddling a
/// plane through a tree crown are best left until nearer children have been searched. Set
/// by measurement (`raybench`, 1 thread, kdt/obt/okdt on office, graz_office, soup,
/// copper_beech, bathroom): 0 (every run at once) is best on the two offices and worst on
/// copper_beech (kdt 0.27 of sah against 0.43), ∞ (none) the reverse (graz kdt 0.44 against
/// 0.53); 0.003 is within 0.05 of the better of the two everywhere (copper_beech obt and okdt
/// 0.51 and 0.54 against 0.56 and 0.59 with every run at once; elsewhere within 0.03).
const EAGER_HITS_PER_TEST: f64 = 0.003;

/// With tight boxes, a node's own run longer than this is split into pieces of nearby
/// triangles ([`RunTree`]); pieces of at most this many are tested like a leaf.
pub(super) const CHUNK_MAX: usize = 16;

/// Bit of [`Group::eager`] (shifted by the lane) of a piece visited first.
pub(super) const FIRST: u8 = 1 << 4;

/// Bit of [`Group::run`] marking a group that holds pieces of a node's own run ([`RunTree`])
/// rather than a node of the tree.
pub(super) const SUB: u16 = 1 << 15;

/// A piece of a node's own run: a range of the (reordered) run, a chunk tested like a leaf
/// (at most [`LEAF_MAX_TRIS`] triangles) or a group of up to four smaller pieces.
#[derive(Clone, Debug)]
struct Piece {
    range: std::ops::Range<usize>,
    /// Index in [`RunTree::subs`] of the pieces it is split into (`None`: a chunk).
    sub: Option<usize>,
    /// Surface area of its box.
    sa: f64,
    /// Expected cost of visiting it once its box is hit ([`test_cost`] units).
    cost: f64,
    /// Reference (set when the layout is allocated).
    r: u32,
}

/// The own triangles of a node split for traversal with tight boxes: the pieces that take the
/// free lanes of the node's last group and, behind them, groups of up to four pieces each,
/// down to chunks of at most [`CHUNK_MAX`] nearby triangles (or up to [`LEAF_MAX_TRIS`]
/// where splitting further would not pay for the steps). Only the boxes change: every
/// triangle is still reached through (and only through) the node it is attached to.
#[derive(Clone, Debug, Default)]
struct RunTree {
    top: Vec<Piece>,
    subs: Vec<Vec<Piece>>,
}

impl RunTree {
    /// Reorder `ids` into pieces, `fanout` of them at the top.
    fn new(scene: &Scene, ids: &mut [u32], fanout: usize) -> RunTree {
        let mut t = RunTree::default();
        t.top = t.pieces(scene, ids, 0..ids.len(), fanout);
        t
    }

    /// Expected cost of visiting `pieces` once their parent (of surface area `sa`) is hit:
    /// a piece is hit with probability (its surface area) / `sa`, and each hit costs a step
    /// and its own cost.
    fn cost(pieces: &[Piece], sa: f64) -> f64 {
        pieces
            .iter()
            .map(|p| (p.sa / sa).min(1.0) * (STEP_COST + p.cost))
            .sum()
    }

    /// Whether splitting a run of `n` triangles whose box has surface area `sa` pays: the
    /// expected cost of the pieces against testing the whole run when its box is hit
    /// (`pushed`: after a step of its own).
    fn pays(&self, n: usize, sa: f64, pushed: bool) -> bool {
        let whole = test_cost(n) + if pushed { STEP_COST } else { 0.0 };
        sa > 0.0 && RunTree::cost(&self.top, sa) < whole
    }

    fn pieces(
        &mut self,
        scene: &Scene,
        ids: &mut [u32],
        range: std::ops::Range<usize>,
        fanout: usize,
    ) -> Vec<Piece> {
        let k = fanout.min(range.len().div_ceil(CHUNK_MAX));
        let mut ranges = Vec::with_capacity(k);
        split_into(scene, ids, range, k, &mut ranges);
        ranges
            .into_iter()
            .map(|range| {
                let sa = run_box(scene, &ids[range.clone()]).surface_area() as f64;
                let mut sub = None;
                if range.len() > CHUNK_MAX {
                    // Split further unless a chunk reference can hold the piece and its
                    // pieces would not pay for their steps.
                    let mut t = RunTree::default();
                    let top = t.pieces(scene, ids, range.clone(), 4);
                    let split = RunTree::cost(&top, sa);
                    if range.len() > LEAF_MAX_TRIS || (sa > 0.0 && split < test_cost(range.len())) {
                        let j = self.subs.len();
                        let shift = |mut v: Vec<Piece>| {
                            v.iter_mut().for_each(|p| p.sub = p.sub.map(|s| s + j + 1));
                            v
                        };
                        self.subs.push(shift(top));
                        self.subs.extend(t.subs.into_iter().map(shift));
                        sub = Some((j, split));
                    }
                }
                Piece {
                    cost: sub.map_or(test_cost(range.len()), |s| s.1),
                    sub: sub.map(|s| s.0),
                    range,
                    sa,
                    r: NONE,
                }
            })
            .collect()
    }
}

/// Cost of visiting a piece of a split run (a step of the traversal and its box test), in
/// sixteen-wide packet tests ([`test_cost`]). Set by measurement (`raybench`, 1 thread,
/// kdt/obt/okdt/tf-oct on office, soup, bathroom, graz_office, copper_beech; 0, 0.5, 1, 1.5,
/// 2 and 3): at 3 fewer runs are split and graz_office kdt runs at 0.55 of sah against 0.63
/// at 1 (0.53 unsplit); 0 to 1.5 are within the noise of each other.
const STEP_COST: f64 = 1.0;

/// Cost of testing a run of `n` triangles, in sixteen-wide packet tests.
fn test_cost(n: usize) -> f64 {
    if n >= WIDE_MIN {
        n.div_ceil(16) as f64
    } else {
        0.5 * n.div_ceil(4) as f64
    }
}

/// Box of the triangles `ids`.
fn run_box(scene: &Scene, ids: &[u32]) -> Aabb {
    ids.iter().fold(Aabb::EMPTY, |mut b, &s| {
        b.grow_box(&scene.tri_bbox(s as usize));
        b
    })
}

/// Split `ids[range]` into `k` ranges of nearby triangles, appended to `out`: sorted by box
/// centre along the axis, and cut at the rank, where the two sides' surface areas times their
/// triangle counts are least (surface area heuristic), recursively. Ties are broken by
/// triangle id, so the result does not depend on the input order.
fn split_into(
    scene: &Scene,
    ids: &mut [u32],
    range: std::ops::Range<usize>,
    k: usize,
    out: &mut Vec<std::ops::Range<usize>>,
) {
    if k <= 1 {
        out.push(range);
        return;
    }
    let part = &mut ids[range.clone()];
    let n = part.len();
    let k1 = k / 2;
    let boxes: Vec<Aabb> = part.iter().map(|&s| scene.tri_bbox(s as usize)).collect();
    // Positions in `part` sorted along axis `a` by box centre, ties by triangle id.
    let order = |a: usize| {
        let mut keyed: Vec<(f32, u32, u32)> = (0..n)
            .map(|i| (boxes[i].min[a] + boxes[i].max[a], part[i], i as u32))
            .collect();
        keyed.sort_unstable_by(|x, y| x.0.total_cmp(&y.0).then(x.1.cmp(&y.1)));
        keyed.into_iter().map(|k| k.2).collect::<Vec<u32>>()
    };
    // Cut where the two sides' surface areas times their triangle counts are least (each side
    // keeps at least one triangle per range it is split into), over the three axes.
    let (mut best, mut best_order) = ((f64::INFINITY, 0), Vec::new());
    let mut right = vec![0f64; n + 1];
    for a in 0..3 {
        let sorted = order(a);
        let mut b = Aabb::EMPTY;
        for i in (0..n).rev() {
            b.grow_box(&boxes[sorted[i] as usize]);
            right[i] = b.surface_area() as f64;
        }
        let mut b = Aabb::EMPTY;
        let mut improved = false;
        for i in 1..n {
            b.grow_box(&boxes[sorted[i - 1] as usize]);
            if i < k1 || n - i < k - k1 {
                continue;
            }
            let c = b.surface_area() as f64 * i as f64 + right[i] * (n - i) as f64;
            if c < best.0 {
                best = (c, i);
                improved = true;
            }
        }
        if improved || best_order.is_empty() {
            best_order = sorted;
        }
    }
    let mid = best.1.max(k1);
    let sorted: Vec<u32> = best_order.iter().map(|&i| part[i as usize]).collect();
    part.copy_from_slice(&sorted);
    let mid = range.start + mid;
    split_into(scene, ids, range.start..mid, k1, out);
    split_into(scene, ids, mid..range.end, k - k1, out);
}

/// Whether occlusion queries test the run `ids` (of box `b`) as soon as its box is hit
/// ([`EAGER_HITS_PER_TEST`]): the expected number of its triangles crossed by a random line
/// through its box, 2·(triangle area) / (box surface area), per triangle.
fn eager_run(scene: &Scene, ids: &[u32], b: &Aabb) -> bool {
    let area: f64 = ids
        .iter()
        .map(|&t| {
            let [p, q, r] = scene.tri_vertices(t as usize);
            hirad_core::geom::triangle_area_f64(p, q, r)
        })
        .sum();
    let sa = b.surface_area() as f64;
    let crossed = if sa > 0.0 { 2.0 * area / sa } else { 1.0 };
    crossed >= EAGER_HITS_PER_TEST * ids.len() as f64
}

/// Which boxes the traversal tests (`raybench --boxes`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Boxes {
    /// As [`Boxes::Nodes`], and a node's own run longer than 16 triangles is split into
    /// pieces of nearby triangles behind boxes of their own (`RunTree` in `layout.rs`: cut
    /// by the surface area heuristic, down to chunks of at most 16), where a cost model says
    /// the boxes pay for their box tests (`STEP_COST`). The pieces take the lanes the whole
    /// run would have taken, so every triangle is still reached through, and only through,
    /// the node it is attached to; a ray tests only the pieces whose boxes it hits (the many
    /// surfaces a `kdt` node keeps because they cross its split plane, a large leaf).
    #[default]
    Tight,
    /// Every node's box shrunk to what lies below it (the union of its own triangles' boxes
    /// and its children's boxes), and the triangles attached to an inner node bounded by a
    /// box of their own in a free lane of the node's last group, so that they are tested
    /// only when the ray hits that box. Same nodes, children and triangles as the tree: only
    /// the boxes are tighter, and a node without triangles and with one child (the empty half
    /// of a `kdt`/`obt` cell), whose tight box is its child's, is passed through. Differs from
    /// [`Boxes::Cluster`] only where the strategy's boxes are loose (`kdt` and `obt` cells),
    /// at such nodes and at inner nodes with triangles of their own.
    Nodes,
    /// The strategy's own boxes (grown to contain their contents exactly), and the triangles
    /// of a node tested whenever the node is visited: the traversal the paper describes (the
    /// face bits of `layout.rs` apply to every kind of boxes).
    Cluster,
}

impl Boxes {
    /// Every choice.
    pub const ALL: [Boxes; 3] = [Boxes::Tight, Boxes::Nodes, Boxes::Cluster];
}

choice!(Boxes, "traversal boxes", Tight => "tight", Nodes => "nodes", Cluster => "cluster");

/// The laid-out tree.
#[derive(Clone, Debug, Default)]
pub(super) struct Layout {
    /// Box of the root, `[minx, miny, minz, maxx, maxy, maxz]`, tested first.
    pub root_box: [f32; 6],
    /// Reference of the root; `None` for a tree without nodes.
    pub root: Option<u32>,
    pub groups: Vec<Group>,
    /// Per group, 6 bits per lane ([`face_bits`]): bit `a` (`3 + a`) set when everything in
    /// the lane that touches the plane of the box's min (max) face along axis `a` lies in
    /// that plane.
    pub faces: Vec<u32>,
    /// Triangles of runs shorter than [`WIDE_MIN`], in node order, four to a packet.
    pub packets: Vec<Packet>,
    /// Triangles of runs of [`WIDE_MIN`] or more, in node order, sixteen to a packet.
    pub wide: Vec<Wide>,
}

/// Shortest triangle run stored in [`Wide`] packets.
pub(super) const WIDE_MIN: usize = 9;

/// Sixteen triangles (structure of arrays) and their scene ids (`u32::MAX` in unused lanes).
#[derive(Clone, Copy, Debug)]
#[repr(C, align(64))]
pub(super) struct Wide {
    pub v: Tri16,
    pub id: [u32; 16],
}

/// Whether the AVX-512 edge test can run here (checked once, then cached by std).
#[inline(always)]
fn has_avx512() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::arch::is_x86_feature_detected!("avx512f")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// Candidate mask of the lanes `valid` of a wide packet (see
/// [`candidates4`](super::watertight::candidates4)).
#[inline(always)]
fn wide_candidates(r: &RayPre, w: &Wide, valid: u32, avx512: bool) -> u32 {
    #[cfg(target_arch = "x86_64")]
    if avx512 {
        // SAFETY: `avx512` is true only when the CPU has AVX-512F (`has_avx512`).
        return unsafe { super::watertight::candidates16_avx512(r, &w.v) } & valid;
    }
    let _ = avx512;
    let mut m = 0;
    for q in 0..4 {
        if valid >> (4 * q) & 0xF != 0 {
            m |= candidates4_at(r, &w.v, 4 * q) << (4 * q);
        }
    }
    m & valid
}

/// Four triangles (structure of arrays) and their scene ids (`u32::MAX` in unused lanes).
#[derive(Clone, Copy, Debug)]
#[repr(C, align(16))]
pub(super) struct Packet {
    pub v: Tri4,
    pub id: [u32; 4],
}

/// Mask of the lanes used by packet `k` (of `W` lanes: 4 for a [`Packet`], 16 for a
/// [`Wide`]) of a run of `n` triangles.
#[inline(always)]
pub(super) fn lane_mask<const W: usize>(n: usize, k: usize) -> u32 {
    let rest = n - W * k;
    if rest >= W {
        u32::MAX >> (32 - W)
    } else {
        (1 << rest) - 1
    }
}

impl Layout {
    pub(super) fn new(scene: &Scene, tree: &ClusterTree, boxes: Boxes) -> Layout {
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
        // Each node's own triangles.
        let mut own: Vec<Vec<u32>> = (0..n as u32).map(|id| surfs(id).collect()).collect();
        // Boxes of the nodes' own runs and of the nodes (grown to, or tight around, their
        // contents), children first.
        let mut run_bound = vec![Aabb::EMPTY; n];
        let mut bound = vec![Aabb::EMPTY; n];
        let mut run_faces = vec![0u8; n];
        let mut node_faces = vec![0u8; n];
        for &id in order.iter().rev() {
            let rb = run_box(scene, &own[id as usize]);
            run_bound[id as usize] = rb;
            let mut b = match boxes {
                Boxes::Tight | Boxes::Nodes => rb,
                Boxes::Cluster => {
                    let mut b = tree.nodes[id as usize].bbox;
                    b.grow_box(&rb);
                    b
                }
            };
            for c in kids(id) {
                let cb = bound[c as usize];
                b.grow_box(&cb);
            }
            bound[id as usize] = b;
            let tris = || {
                own[id as usize]
                    .iter()
                    .map(|&s| scene.tri_bbox(s as usize))
                    .map(|t| (t, flat_bits(&t)))
            };
            run_faces[id as usize] = face_bits(&rb, tris());
            let below = kids(id).map(|c| (bound[c as usize], node_faces[c as usize]));
            node_faces[id as usize] = face_bits(&b, tris().chain(below));
        }
        // Whether occlusion tests a node's own triangles at once when their box is hit (in a
        // free lane of the node).
        let eager: Vec<bool> = (0..n)
            .map(|i| {
                boxes != Boxes::Cluster
                    && !own[i].is_empty()
                    && eager_run(scene, &own[i], &run_bound[i])
            })
            .collect();
        // With tight boxes, a run longer than CHUNK_MAX (that is not a leaf's run held in
        // place) is reordered into pieces behind boxes of their own where that pays.
        let mut runs: Vec<Option<RunTree>> = vec![None; n];
        if boxes == Boxes::Tight {
            use rayon::prelude::*;
            own.par_iter_mut()
                .zip(&mut runs)
                .enumerate()
                .for_each(|(id, (ids, run))| {
                    let c = kids(id as u32).count();
                    if ids.len() > CHUNK_MAX && (c > 0 || ids.len() > LEAF_MAX_TRIS) {
                        let mut split = ids.clone();
                        let rt = RunTree::new(scene, &mut split, 4 - c % 4);
                        let sa = run_bound[id].surface_area() as f64;
                        if rt.pays(ids.len(), sa, c % 4 != 0 && !eager[id]) {
                            *ids = split;
                            *run = Some(rt);
                        }
                    }
                });
        }
        // Nodes a ray passes through for free with tight boxes: no triangles of their own and
        // one child, whose box is theirs (an empty half of a k-d cell). Their parent's lane
        // refers to the child directly.
        let pass: Vec<bool> = (0..n)
            .map(|i| boxes != Boxes::Cluster && own[i].is_empty() && kids(i as u32).count() == 1)
            .collect();
        // Pass 1: references, group and triangle positions.
        let mut refs = vec![NONE; n];
        let mut tri_pos = vec![0usize; n];
        let mut sub_pos = vec![0usize; n];
        let mut ng = 0usize;
        // Packets and wide packets allocated so far.
        let mut np = [0usize; 2];
        // First packet of a run of `t` triangles, in the array its length selects.
        let alloc = |np: &mut [usize; 2], t: usize| {
            let (k, size) = if t >= WIDE_MIN { (1, 16) } else { (0, 4) };
            let start = np[k];
            np[k] += t.div_ceil(size);
            start
        };
        for &id in &order {
            let i = id as usize;
            if pass[i] {
                continue;
            }
            let c = kids(id).count();
            let t = own[i].len();
            // Every chunk starts at most `t` packets further on; the node's groups (its children
            // and top pieces, then fewer groups of pieces than triangles) stay below RUN.
            let fits =
                np[0].max(np[1]) + t <= LEAF_MAX_START && ng + c.div_ceil(4) + 1 + t < RUN as usize;
            if let Some(rt) = runs[i].as_mut().filter(|_| fits) {
                refs[i] = ng as u32;
                ng += (c + rt.top.len()).div_ceil(4);
                sub_pos[i] = ng;
                ng += rt.subs.len();
                let mut set = |p: &mut Piece| {
                    p.r = match p.sub {
                        Some(j) => (sub_pos[i] + j) as u32,
                        None => leaf_ref(alloc(&mut np, p.range.len()), p.range.len()) | CHUNK,
                    }
                };
                rt.top.iter_mut().for_each(&mut set);
                rt.subs.iter_mut().flatten().for_each(&mut set);
                continue;
            }
            runs[i] = None;
            let start = alloc(&mut np, t);
            tri_pos[i] = start;
            if c == 0 && t <= LEAF_MAX_TRIS && start <= LEAF_MAX_START {
                refs[i] = leaf_ref(start, t);
            } else {
                refs[i] = ng as u32;
                ng += c.div_ceil(4).max(1);
            }
        }
        // Pass 2: fill in.
        let mut groups = vec![Group::default(); ng];
        let mut faces = vec![0u32; ng];
        let empty = Packet {
            v: [[0.0; 4]; 9],
            id: [u32::MAX; 4],
        };
        let [npk, nw] = np;
        let mut packets = vec![empty; npk];
        let mut wide = vec![
            Wide {
                v: [[0.0; 16]; 9],
                id: [u32::MAX; 16],
            };
            nw
        ];
        // The reference a lane holding node `i` gets: its own, or that of the first node below
        // it that a ray does not pass through for free (children first).
        let mut link = refs.clone();
        for &id in order.iter().rev() {
            if pass[id as usize] {
                link[id as usize] = kids(id).map(|c| link[c as usize]).next().unwrap_or(NONE);
            }
        }
        for &id in &order {
            let i = id as usize;
            if pass[i] {
                continue;
            }
            let r = refs[i];
            let ids = &own[i];
            if r & LEAF == 0 {
                let g0 = r as usize;
                let k: Vec<u32> = kids(id).collect();
                let children = k
                    .iter()
                    .map(|&c| (bound[c as usize], link[c as usize], node_faces[c as usize]));
                // The box, reference and face bits of a piece of the node's own run.
                let lane_of = |p: &Piece| {
                    let tris = &ids[p.range.clone()];
                    let b = run_box(scene, tris);
                    let items = tris.iter().map(|&s| scene.tri_bbox(s as usize));
                    (b, p.r, face_bits(&b, items.map(|t| (t, flat_bits(&t)))))
                };
                let rt = runs[i].as_ref();
                let top = rt.into_iter().flat_map(|rt| rt.top.iter().map(lane_of));
                let first = rt.is_some() && eager[i];
                let mut lanes = 0usize;
                for (j, (b, cr, f)) in children.chain(top).enumerate() {
                    let g = &mut groups[g0 + j / 4];
                    g.set_lane(j % 4, &b, cr);
                    if first && j >= k.len() {
                        g.eager |= FIRST << (j % 4);
                    }
                    faces[g0 + j / 4] |= (f as u32) << (8 * (j % 4));
                    lanes += 1;
                }
                for (j, sub) in rt.iter().flat_map(|rt| rt.subs.iter().enumerate()) {
                    let at = sub_pos[i] + j;
                    for (lane, p) in sub.iter().enumerate() {
                        let (b, cr, f) = lane_of(p);
                        groups[at].set_lane(lane, &b, cr);
                        faces[at] |= (f as u32) << (8 * lane);
                    }
                    groups[at].num_groups = 1;
                    groups[at].run = SUB;
                }
                let num_groups = lanes.div_ceil(4).max(1);
                let nt = if runs[i].is_some() { 0 } else { ids.len() };
                // The run gets a lane of its own when the last group has one free (a node
                // without children has no box to spare: its run is its box).
                let run_lane = boxes != Boxes::Cluster
                    && nt > 0
                    && !k.len().is_multiple_of(4)
                    && ng < RUN as usize;
                let at = if run_lane { g0 + num_groups - 1 } else { g0 };
                let g = &mut groups[at];
                g.tri_start = tri_pos[i] as u32;
                g.num_tris = nt as u32;
                if run_lane {
                    let lane = k.len() % 4;
                    g.set_lane(lane, &run_bound[i], RUN | at as u32);
                    faces[at] |= (run_faces[i] as u32) << (8 * lane);
                    g.run = 1 << lane;
                    if eager[i] {
                        g.eager = 1 << lane;
                    }
                }
                groups[g0].num_groups = num_groups as u32;
            }
            let mut store = |ids: &[u32], at: usize| {
                for (i, &s) in ids.iter().enumerate() {
                    let tv = scene.tri_vertices(s as usize);
                    if ids.len() >= WIDE_MIN {
                        let w = &mut wide[at + i / 16];
                        put(&mut w.v, &mut w.id, i % 16, tv, s);
                    } else {
                        let p = &mut packets[at + i / 4];
                        put(&mut p.v, &mut p.id, i % 4, tv, s);
                    }
                }
            };
            match &runs[i] {
                None => store(ids, tri_pos[i]),
                Some(rt) => {
                    for p in rt.top.iter().chain(rt.subs.iter().flatten()) {
                        if p.sub.is_none() {
                            store(&ids[p.range.clone()], leaf_run(p.r).0);
                        }
                    }
                }
            }
        }
        let b = &bound[0];
        Layout {
            root_box: [b.min.x, b.min.y, b.min.z, b.max.x, b.max.y, b.max.z],
            root: Some(link[0]),
            groups,
            faces,
            packets,
            wide,
        }
    }

    /// Bytes used by the layout.
    pub(super) fn memory_bytes(&self) -> usize {
        self.groups.len() * std::mem::size_of::<Group>()
            + self.faces.len() * std::mem::size_of::<u32>()
            + self.packets.len() * std::mem::size_of::<Packet>()
            + self.wide.len() * std::mem::size_of::<Wide>()
    }

    /// The triangle run `(first packet, count)` to test on visiting a reference (a leaf's, a
    /// node's own run behind its box, or a node's own run without a box) and, for a node with
    /// groups, its first group and number of groups.
    #[inline(always)]
    pub(super) fn node(&self, r: u32) -> (usize, usize, usize, usize) {
        if r & LEAF != 0 {
            let (s, c) = leaf_run(r);
            (s, c, 0, 0)
        } else if r & RUN != 0 {
            let g = &self.groups[(r & !RUN) as usize];
            (g.tri_start as usize, g.num_tris as usize, 0, 0)
        } else {
            let g = &self.groups[r as usize];
            let nt = if g.run != 0 { 0 } else { g.num_tris as usize };
            (g.tri_start as usize, nt, r as usize, g.num_groups as usize)
        }
    }

    /// True when a triangle of the run `(ps, n)` that `skip` does not leave out is hit in
    /// `[tmin, tmax]`. Adds the triangles tested to `*tested`.
    #[inline(always)]
    pub(super) fn any_hit<F: Fn(u32) -> bool>(
        &self,
        r: &RayPre,
        (ps, n): (usize, usize),
        tmin: f32,
        tmax: f32,
        tested: &mut u64,
        skip: &F,
    ) -> bool {
        if n >= WIDE_MIN {
            return self.any_hit_wide(r, ps, n, tmin, tmax, tested, skip);
        }
        for k in 0..n.div_ceil(4) {
            let p = &self.packets[ps + k];
            let valid = lane_mask::<4>(n, k);
            *tested += valid.count_ones() as u64;
            if any_of(
                r,
                &p.v,
                &p.id,
                candidates4(r, &p.v) & valid,
                (tmin, tmax),
                skip,
            ) {
                return true;
            }
        }
        false
    }

    /// Closest hit among the triangles of the run `(ps, n)` nearer than `*best_t`: updates
    /// `*best_t` and `*best = (triangle id, u, v)`; equal distances keep the lowest id.
    #[inline(always)]
    pub(super) fn closest_hit(
        &self,
        r: &RayPre,
        ps: usize,
        n: usize,
        tmin: f32,
        best_t: &mut f32,
        best: &mut Option<(u32, f32, f32)>,
    ) {
        if n >= WIDE_MIN {
            let avx512 = has_avx512();
            for k in 0..n.div_ceil(16) {
                let w = &self.wide[ps + k];
                let m = wide_candidates(r, w, lane_mask::<16>(n, k), avx512);
                closest_of(r, &w.v, &w.id, m, tmin, best_t, best);
            }
            return;
        }
        for k in 0..n.div_ceil(4) {
            let p = &self.packets[ps + k];
            let m = candidates4(r, &p.v) & lane_mask::<4>(n, k);
            closest_of(r, &p.v, &p.id, m, tmin, best_t, best);
        }
    }

    /// [`Layout::any_hit`] of a run stored in wide packets.
    #[inline(never)]
    #[allow(clippy::too_many_arguments)]
    fn any_hit_wide<F: Fn(u32) -> bool>(
        &self,
        r: &RayPre,
        ps: usize,
        n: usize,
        tmin: f32,
        tmax: f32,
        tested: &mut u64,
        skip: &F,
    ) -> bool {
        let avx512 = has_avx512();
        for k in 0..n.div_ceil(16) {
            let w = &self.wide[ps + k];
            let valid = lane_mask::<16>(n, k);
            *tested += valid.count_ones() as u64;
            let m = wide_candidates(r, w, valid, avx512);
            if any_of(r, &w.v, &w.id, m, (tmin, tmax), skip) {
                return true;
            }
        }
        false
    }

    /// Whether visiting reference `r` visits a node of the tree (a node's own run behind its
    /// box does not: its node was visited when the box was tested).
    #[inline(always)]
    pub(super) fn is_node(&self, r: u32) -> bool {
        if r & LEAF != 0 {
            r & CHUNK == 0
        } else {
            r & RUN == 0 && self.groups[r as usize].run & SUB == 0
        }
    }

    /// Hint the cache to load what visiting `r` reads first.
    #[inline(always)]
    pub(super) fn prefetch(&self, r: u32) {
        #[cfg(target_arch = "x86_64")]
        {
            use core::arch::x86_64::{_mm_prefetch, _MM_HINT_T0};
            // SAFETY: a prefetch is only a hint and never faults, whatever the address.
            #[allow(unused_unsafe)]
            unsafe {
                if r & (LEAF | RUN) != 0 {
                    // A packet spans three cache lines (160 bytes, at offset 0 or 32 of a line);
                    // of a wide packet, the first three.
                    let (s, n, _, _) = self.node(r);
                    let p = if n >= WIDE_MIN {
                        self.wide.as_ptr().wrapping_add(s) as *const i8
                    } else {
                        self.packets.as_ptr().wrapping_add(s) as *const i8
                    };
                    _mm_prefetch::<_MM_HINT_T0>(p);
                    _mm_prefetch::<_MM_HINT_T0>(p.wrapping_add(64));
                    _mm_prefetch::<_MM_HINT_T0>(p.wrapping_add(128));
                } else {
                    let p = self.groups.as_ptr().wrapping_add(r as usize) as *const i8;
                    _mm_prefetch::<_MM_HINT_T0>(p);
                    _mm_prefetch::<_MM_HINT_T0>(p.wrapping_add(64));
                }
            }
        }
        #[cfg(not(target_arch = "x86_64"))]
        let _ = r;
    }
}

/// Face bits of a triangle's box: bits `a` and `3 + a` when it is flat along axis `a` (it
/// lies in the plane of both faces).
fn flat_bits(t: &Aabb) -> u8 {
    (0..3)
        .filter(|&a| t.min[a] == t.max[a])
        .fold(0, |m, a| m | 1 << a | 1 << (a + 3))
}

/// Face bits of box `b` holding `items` (boxes and their own face bits): bit `a` (`3 + a`)
/// stays set when every item that touches the plane of `b`'s min (max) face along axis `a`
/// has that bit, i.e. lies in that plane. A ray lying in such a face's plane meets only
/// triangles lying in the plane (coplanar with the ray: never hit, see
/// [`Ray4::flat_in_plane`]) and triangles whose boxes it misses (strictly on one side).
fn face_bits(b: &Aabb, items: impl Iterator<Item = (Aabb, u8)>) -> u8 {
    let mut m = 0b11_1111u8;
    for (x, f) in items {
        for a in 0..3 {
            if x.min[a] == b.min[a] && f & (1 << a) == 0 {
                m &= !(1 << a);
            }
            if x.max[a] == b.max[a] && f & (1 << (a + 3)) == 0 {
                m &= !(1 << (a + 3));
            }
        }
    }
    m
}

/// Store triangle `id` with corners `tv` in `lane` of a packet.
fn put<const N: usize>(
    v: &mut [[f32; N]; 9],
    ids: &mut [u32; N],
    lane: usize,
    tv: [glam::Vec3; 3],
    id: u32,
) {
    for (k, p) in tv.iter().enumerate() {
        for a in 0..3 {
            v[3 * k + a][lane] = p[a];
        }
    }
    ids[lane] = id;
}

/// True when one of the candidate lanes `m` of a packet (four or sixteen wide) whose triangle
/// `skip` does not leave out is hit in `[tmin, tmax]`.
#[inline(always)]
fn any_of<const N: usize, F: Fn(u32) -> bool>(
    r: &RayPre,
    v: &[[f32; N]; 9],
    ids: &[u32; N],
    mut m: u32,
    (tmin, tmax): (f32, f32),
    skip: &F,
) -> bool {
    while m != 0 {
        let i = m.trailing_zeros() as usize;
        m &= m - 1;
        if !skip(ids[i]) && intersect(r, &tri_of(v, i), tmin, tmax).is_some() {
            return true;
        }
    }
    false
}

/// Closest hit among the candidate lanes `m` of a packet (four or sixteen wide) nearer than
/// `*best_t` (see [`Layout::closest_hit`]).
#[inline(always)]
fn closest_of<const N: usize>(
    r: &RayPre,
    v: &[[f32; N]; 9],
    ids: &[u32; N],
    mut m: u32,
    tmin: f32,
    best_t: &mut f32,
    best: &mut Option<(u32, f32, f32)>,
) {
    while m != 0 {
        let i = m.trailing_zeros() as usize;
        m &= m - 1;
        if let Some((t, u, w)) = intersect(r, &tri_of(v, i), tmin, *best_t) {
            let id = ids[i];
            let better = match *best {
                None => true,
                Some(_) if t < *best_t => true,
                Some((bid, _, _)) => id < bid,
            };
            if better {
                *best_t = t;
                *best = Some((id, u, w));
            }
        }
    }
}

/// Per-ray data of the 4-wide box test: origin and reciprocal direction broadcast to four
/// lanes, and for each axis the index of the near and far plane in [`Group::b`] (chosen by
/// the sign of the direction, so that `0·∞ = NaN` can only come from an origin lying exactly
/// in a box plane, which the comparisons then ignore, as the scalar [`RayPre::slab`] does).
#[derive(Clone, Copy, Debug, Default)]
#[repr(C, align(16))]
pub(super) struct Ray4 {
    o: [[f32; 4]; 3],
    inv: [[f32; 4]; 3],
    near: [usize; 3],
    far: [usize; 3],
    /// Bit `a` set when the direction's component `a` is zero (the ray lies in a plane of
    /// constant coordinate `a`).
    in_plane: u32,
}

impl Ray4 {
    pub(super) fn new(r: &RayPre) -> Ray4 {
        let mut x = Ray4::default();
        x.set(r);
        x
    }

    /// Take the data of `r`.
    #[inline(always)]
    pub(super) fn set(&mut self, r: &RayPre) {
        for a in 0..3 {
            self.o[a] = [r.o[a]; 4];
            self.inv[a] = [r.inv[a]; 4];
            // Plane indices are in 0..6 (RayPre's contract); keep that invariant for the
            // unchecked loads of `test`.
            self.near[a] = r.near[a] % 6;
            self.far[a] = r.far[a] % 6;
        }
        self.in_plane = (0..3).filter(|&a| r.d[a] == 0.0).fold(0, |m, a| m | 1 << a);
    }

    /// Lanes of `g` that the ray only touches along a face: it lies in the plane of a face of
    /// the lane's box (direction component zero, origin on the face) and everything in the
    /// lane that touches that plane lies in it (`faces`, from [`face_bits`]; a box flat in
    /// the plane is one case). Triangles in the plane are coplanar with the ray: the
    /// watertight test computes all three sheared edge functions as exactly zero (the in-plane
    /// coordinate is one of the two sheared axes and its shear constant is zero) and reports
    /// no hit. The others lie strictly on one side of the plane, and the ray misses their
    /// boxes as it would in a leaf of their own. Skipping these lanes changes no result; it
    /// keeps a ray running along a floor from visiting every cell standing on the floor that
    /// it passes (the slab test itself must accept them: the ray touches them).
    #[inline(always)]
    fn flat_in_plane(&self, g: &Group, faces: u32) -> u32 {
        let mut m = 0;
        for a in 0..3 {
            if self.in_plane & (1 << a) != 0 {
                let o = self.o[a][0];
                for lane in 0..4 {
                    let f = faces >> (8 * lane);
                    if (g.b[a][lane] == o && f & (1 << a) != 0)
                        || (g.b[a + 3][lane] == o && f & (1 << (a + 3)) != 0)
                    {
                        m |= 1 << lane;
                    }
                }
            }
        }
        m
    }

    /// Slab test of the four boxes of `g` clipped to `[tmin, tmax]`: bit `i` of the mask is
    /// set when lane `i` is (conservatively, like [`RayPre::slab`]) hit and not ruled out by
    /// [`Ray4::flat_in_plane`]; `tn` its entry distance.
    #[inline(always)]
    pub(super) fn test(&self, g: &Group, faces: &u32, tmin: f32, tmax: f32) -> (u32, [f32; 4]) {
        #[cfg(target_arch = "x86_64")]
        {
            use core::arch::x86_64::*;
            // SAFETY: SSE and SSE2 are part of the x86_64 baseline; `o`/`inv` are 16-byte
            // aligned (repr align 16, arrays of four f32 at offsets multiple of 16), the other
            // loads are unaligned; plane indices are below 6 by construction (`set`).
            #[allow(unused_unsafe)]
            unsafe {
                let mut tn = _mm_set1_ps(tmin);
                let mut tf = _mm_set1_ps(tmax);
                for a in 0..3 {
                    let o = _mm_load_ps(self.o[a].as_ptr());
                    let inv = _mm_load_ps(self.inv[a].as_ptr());
                    // `near`/`far` are below 6 (`set`), the length of `g.b`.
                    let n = _mm_loadu_ps(g.b.get_unchecked(self.near[a]).as_ptr());
                    let f = _mm_loadu_ps(g.b.get_unchecked(self.far[a]).as_ptr());
                    let t0 = _mm_mul_ps(_mm_sub_ps(n, o), inv);
                    let t1 = _mm_mul_ps(_mm_sub_ps(f, o), inv);
                    // max/min return the second operand when either is NaN: a NaN plane
                    // distance leaves the running bound unchanged.
                    tn = _mm_max_ps(t0, tn);
                    tf = _mm_min_ps(t1, tf);
                }
                let hit = _mm_cmple_ps(tn, _mm_mul_ps(tf, _mm_set1_ps(BOX_SLACK)));
                let mut mask = _mm_movemask_ps(hit) as u32;
                if self.in_plane != 0 {
                    mask &= !self.flat_in_plane(g, *faces);
                }
                let mut out = [0f32; 4];
                _mm_storeu_ps(out.as_mut_ptr(), tn);
                (mask, out)
            }
        }
        #[cfg(not(target_arch = "x86_64"))]
        {
            let mut mask = 0;
            let mut out = [0f32; 4];
            for lane in 0..4 {
                let mut tn = tmin;
                let mut tf = tmax;
                for a in 0..3 {
                    let t0 = (g.b[self.near[a]][lane] - self.o[a][0]) * self.inv[a][0];
                    let t1 = (g.b[self.far[a]][lane] - self.o[a][0]) * self.inv[a][0];
                    tn = if t0 > tn { t0 } else { tn };
                    tf = if t1 < tf { t1 } else { tf };
                }
                if tn <= tf * BOX_SLACK {
                    mask |= 1 << lane;
                }
                out[lane] = tn;
            }
            if self.in_plane != 0 {
                mask &= !self.flat_in_plane(g, *faces);
            }
            (mask, out)
        }
    }

    /// [`Ray4::test`] for occlusion: the hit mask and, for every lane, its position among the
    /// hit lanes in push order (farthest entry first, ties: higher lane first), so that the
    /// nearest ends on top. Lanes that are not hit get positions after the hit ones. Computed
    /// without data-dependent branches (random rays make them unpredictable).
    #[inline(always)]
    pub(super) fn test_ranked(
        &self,
        g: &Group,
        faces: &u32,
        tmin: f32,
        tmax: f32,
    ) -> (u32, [u32; 4]) {
        let (all, tn) = self.test(g, faces, tmin, tmax);
        let mask = g.split_eager(all).0;
        #[cfg(target_arch = "x86_64")]
        {
            use core::arch::x86_64::*;
            // SAFETY: SSE2 is part of the x86_64 baseline.
            #[allow(unused_unsafe)]
            unsafe {
                let bits = _mm_setr_epi32(1, 2, 4, 8);
                let lanes = |m: u32| {
                    _mm_castsi128_ps(_mm_cmpeq_epi32(
                        _mm_and_si128(_mm_set1_epi32(m as i32), bits),
                        bits,
                    ))
                };
                let hit = lanes(mask);
                // Pieces visited first rank nearest of the lanes hit.
                let mut tn = _mm_loadu_ps(tn.as_ptr());
                if g.eager >= FIRST {
                    tn = _mm_blendv_ps_sse2(
                        tn,
                        _mm_set1_ps(-f32::MAX),
                        lanes((g.eager >> 4) as u32),
                    );
                }
                let t = _mm_blendv_ps_sse2(_mm_set1_ps(f32::NEG_INFINITY), tn, hit);
                // Rotation k compares lane i with lane (i + k) mod 4, which is a higher lane
                // exactly for i < 4 - k.
                let r1 = _mm_shuffle_ps::<0b00_11_10_01>(t, t);
                let r2 = _mm_shuffle_ps::<0b01_00_11_10>(t, t);
                let r3 = _mm_shuffle_ps::<0b10_01_00_11>(t, t);
                let hi1 = _mm_castsi128_ps(_mm_setr_epi32(-1, -1, -1, 0));
                let hi2 = _mm_castsi128_ps(_mm_setr_epi32(-1, -1, 0, 0));
                let hi3 = _mm_castsi128_ps(_mm_setr_epi32(-1, 0, 0, 0));
                let before = |r: __m128, hi: __m128| {
                    _mm_castps_si128(_mm_or_ps(
                        _mm_cmpgt_ps(r, t),
                        _mm_and_ps(_mm_cmpeq_ps(r, t), hi),
                    ))
                };
                let n = _mm_add_epi32(
                    _mm_add_epi32(before(r1, hi1), before(r2, hi2)),
                    before(r3, hi3),
                );
                let mut out = [0u32; 4];
                _mm_storeu_si128(
                    out.as_mut_ptr() as *mut __m128i,
                    _mm_sub_epi32(_mm_setzero_si128(), n),
                );
                (all, out)
            }
        }
        #[cfg(not(target_arch = "x86_64"))]
        {
            let t: [f32; 4] = std::array::from_fn(|i| {
                if mask >> i & 1 == 1 {
                    if g.eager >> (4 + i) & 1 == 1 {
                        -f32::MAX
                    } else {
                        tn[i]
                    }
                } else {
                    f32::NEG_INFINITY
                }
            });
            let out = std::array::from_fn(|i| {
                (0..4)
                    .filter(|&j| j != i && (t[j] > t[i] || (t[j] == t[i] && j > i)))
                    .count() as u32
            });
            (all, out)
        }
    }
}

/// `blendv` with SSE2 only: lanes of `b` where `m` is set, of `a` elsewhere.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
unsafe fn _mm_blendv_ps_sse2(
    a: core::arch::x86_64::__m128,
    b: core::arch::x86_64::__m128,
    m: core::arch::x86_64::__m128,
) -> core::arch::x86_64::__m128 {
    use core::arch::x86_64::*;
    _mm_or_ps(_mm_and_ps(m, b), _mm_andnot_ps(m, a))
}
