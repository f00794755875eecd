//! The split of a node's long triangle run into pieces behind boxes of their own
//! ([`RunTree`]) and the cost model that decides it, and the choice of runs that occlusion
//! queries test as soon as their box is hit ([`eager_run`]).

use super::encode::{LEAF_MAX_TRIS, NONE};
use super::packets::WIDE_MIN;
use hirad_core::geom::Aabb;
use hirad_scene::Scene;

/// A node's own run behind its box is tested as soon as that box is hit (occlusion queries;
/// before the children it was tested with are visited) when a random line through the box
/// crosses at least this many of its triangles per triangle tested; otherwise its reference is
/// pushed and visited in distance order with the children. Walls and floors straddling a k-d
/// plane are likely occluders and are best tested at once; hundreds of leaves straddling a
/// plane through a tree crown are best left until nearer children have been searched. Set
/// by `raybench` measurement (`docs/perf-log.md`): a compromise between 0 (every run at
/// once, best on the offices) and ∞ (none, best on copper_beech).
pub(super) const EAGER_HITS_PER_TEST: f64 = 0.003;

/// With tight boxes, a node's own run longer than this is split into pieces of nearby
/// triangles ([`RunTree`]) where the cost model says so; pieces of at most this many (one
/// packet) are tested like a leaf. Pieces of up to sixteen are split further where their
/// parts pay for their box tests: a piece of a few large triangles (walls and floors that
/// cross a k-d plane) has a box as large as the run's, its parts flat boxes most segments miss.
pub(in crate::ray) const CHUNK_MAX: usize = 4;

/// A piece of a node's own run: a range of the (reordered) run, a chunk tested like a leaf
/// (at most [`LEAF_MAX_TRIS`] triangles) or a group of up to four smaller pieces.
#[derive(Clone, Debug)]
pub(super) struct Piece {
    pub(super) range: std::ops::Range<usize>,
    /// Index in [`RunTree::subs`] of the pieces it is split into (`None`: a chunk).
    pub(super) sub: Option<usize>,
    /// Surface area of its box.
    pub(super) sa: f64,
    /// Expected cost of visiting it once its box is hit ([`test_cost`] units).
    pub(super) cost: f64,
    /// Reference (set when the layout is allocated).
    pub(super) r: u32,
}

/// The own triangles of a node split for traversal with tight boxes: the pieces that take the
/// free lanes of the node ([`top_fanout`]) and, behind them, groups of up to four pieces
/// each, down to chunks of at most [`CHUNK_MAX`] nearby triangles (or up to [`LEAF_MAX_TRIS`]
/// where splitting further would not pay for the steps). Only the boxes change: every
/// triangle is still reached through (and only through) the node it is attached to.
#[derive(Clone, Debug, Default)]
pub(super) struct RunTree {
    pub(super) top: Vec<Piece>,
    pub(super) subs: Vec<Vec<Piece>>,
}

impl RunTree {
    /// Reorder `ids` into pieces, `fanout` of them at the top.
    pub(super) fn new(scene: &Scene, ids: &mut [u32], fanout: usize) -> RunTree {
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
    pub(super) fn pays(&self, n: usize, sa: f64, pushed: bool) -> bool {
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

/// How many pieces of a node's own run take lanes beside its `children`: the free lanes of
/// its last group of four, or when the children fill whole eight-lane nodes, a node of eight
/// pieces (the lanes of a partly full eight-lane node are left for inner children pulled up).
pub(super) fn top_fanout(children: usize) -> usize {
    if children.is_multiple_of(8) {
        8
    } else {
        4 - children % 4
    }
}

/// Whether a node's own run beside its `children` lanes gets a lane of its own, so that it is
/// tested only when a ray hits its box: when their eight-lane node has one free (a second
/// group of four costs nothing more there). A node without children has no box to spare: its
/// run is its box.
pub(super) fn run_lane(children: usize) -> bool {
    !children.is_multiple_of(8)
}

/// Cost of visiting a piece of a split run (a step of the traversal and its box test), in
/// sixteen-wide packet tests ([`test_cost`]). Set by `raybench` measurement
/// (`docs/perf-log.md`).
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
pub(super) fn run_box(scene: &Scene, ids: &[u32]) -> Aabb {
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
pub(super) fn eager_run(scene: &Scene, ids: &[u32], b: &Aabb) -> bool {
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
