//! Eight-wide nodes ([`Nodes8`]): each node of the [`Layout`] as one 256-byte [`Node8`] whose
//! six planes are rows of eight lanes, so that a node's box test is one aligned load per plane
//! and the next child is read from the node itself. Built from the layout's groups (same
//! boxes, triangles and lanes) with the lanes in the order occlusion visits them; the queries
//! traverse these nodes, the groups are the build's intermediate form.

use super::super::volume::box6;
use super::super::watertight::RayPre;
use super::super::RayStats;
use super::encode::{leaf_run, CHUNK, FIRST, LEAF, NONE, RUN, SUB};
use super::packets::WIDE_MIN;
use super::run_tree::run_box;
use super::Layout;
use hirad_scene::Scene;

/// Up to eight child boxes of one node (a node of more lanes continues in [`Node8::more`]).
#[derive(Clone, Copy, Debug)]
#[repr(C, align(64))]
pub(in crate::ray) struct Node8 {
    /// `[min x, min y, min z, max x, max y, max z]`, one lane per child; empty lanes hold an
    /// inverted infinite box (never hit).
    pub b: [[f32; 8]; 6],
    /// Child references: a node index, a leaf ([`LEAF`], as in the layout) or a run
    /// ([`RUN`] | index in [`Nodes8::runs`]); [`NONE`] in empty lanes. Occlusion visits the
    /// highest hit lane first.
    pub child: [u32; 8],
    /// Face bits (`faces`), eight bits per lane.
    pub faces: u64,
    /// The node's own triangle run `(first packet, count)` when it has no lane of its own,
    /// tested when the node is visited (behind [`Node8::run_box`]).
    pub tri_start: u32,
    pub num_tris: u32,
    /// The node holding the lanes past this one's eighth ([`NONE`]: none), visited after
    /// this one's.
    pub more: u32,
    /// Index in [`Nodes8::run_boxes`] of the box of the node's own run, which is tested only
    /// when the ray hits that box; [`NONE`]: tested at every visit.
    pub run_box: u32,
    /// Number of lanes with a box.
    pub lanes: u8,
    /// Whether a visit counts as a node of the tree ([`RayStats::nodes`](crate::ray::RayStats):
    /// not a continuation, not a group of pieces of a node's run).
    pub counts: bool,
}

impl Node8 {
    /// A node without lanes: inverted infinite boxes, never hit.
    pub(in crate::ray) const EMPTY: Node8 = {
        let inf = f32::INFINITY;
        Node8 {
            b: [
                [inf; 8], [inf; 8], [inf; 8], [-inf; 8], [-inf; 8], [-inf; 8],
            ],
            child: [NONE; 8],
            faces: 0,
            tri_start: 0,
            num_tris: 0,
            more: NONE,
            run_box: NONE,
            lanes: 0,
            counts: false,
        }
    };
}

/// The laid-out tree as [`Node8`]s.
#[derive(Clone, Debug, Default)]
pub(in crate::ray) struct Nodes8 {
    pub nodes: Vec<Node8>,
    /// Runs of the [`RUN`] references: `(first packet, count)`.
    pub runs: Vec<(u32, u32)>,
    /// Boxes of the nodes' own runs ([`Node8::run_box`]), `[min x, min y, min z, max x, max
    /// y, max z]` of their triangles' vertices.
    pub run_boxes: Vec<[f32; 6]>,
    /// Reference of the root; `None` for a tree without nodes.
    pub root: Option<u32>,
}

/// One lane of a layout node on its way to a [`Node8`].
#[derive(Clone, Copy)]
struct Lane8 {
    b: [f32; 6],
    child: u32,
    faces: u8,
}

/// Whether reference `r` is a leaf or a run (not a [`Node8`]).
#[inline(always)]
pub(in crate::ray) fn is_leaf(r: u32) -> bool {
    r & (LEAF | RUN) != 0
}

impl Nodes8 {
    /// The nodes of layout `l` (laid out from `scene`), in depth-first order (the lane visited
    /// first right after its parent); `run_boxes`: the nodes' own runs behind boxes of their
    /// own (else tested at every visit, [`Boxes::Cluster`](super::Boxes::Cluster)).
    pub(in crate::ray) fn new(l: &Layout, scene: &Scene, run_boxes: bool) -> Nodes8 {
        let Some(root) = l.root else {
            return Nodes8::default();
        };
        // Group index of a layout node → index of its first Node8, and the nodes in order.
        let mut index = vec![NONE; l.groups.len()];
        let mut order: Vec<(usize, Vec<Lane8>)> = Vec::new();
        let mut count = 0usize;
        let mut stack = vec![root];
        while let Some(r) = stack.pop() {
            if is_leaf(r) || r as usize >= l.groups.len() || index[r as usize] != NONE {
                continue;
            }
            let lanes = node_lanes(l, r as usize);
            index[r as usize] = count as u32;
            count += lanes.len().div_ceil(8).max(1);
            stack.extend(lanes.iter().map(|x| x.child));
            order.push((r as usize, lanes));
        }
        let mut out = Nodes8 {
            nodes: super::super::pages::with_capacity(count),
            runs: Vec::new(),
            run_boxes: Vec::new(),
            root: None,
        };
        for (g0, lanes) in order {
            let at = out.nodes.len() as u32;
            let chunks = lanes.len().div_ceil(8).max(1);
            let (ts, nt, _, _) = l.node(g0 as u32);
            // The lanes visited first (the last ones) go to the first node.
            let mut rest = lanes.len();
            for c in 0..chunks {
                let take = rest.min(8);
                let mut node = Node8::EMPTY;
                for (i, x) in lanes[rest - take..rest].iter().enumerate() {
                    for p in 0..6 {
                        node.b[p][i] = x.b[p];
                    }
                    node.faces |= (x.faces as u64) << (8 * i);
                    node.child[i] = out.reference(l, x.child, &index);
                }
                rest -= take;
                node.lanes = take as u8;
                node.more = if c + 1 < chunks {
                    at + c as u32 + 1
                } else {
                    NONE
                };
                if c == 0 {
                    node.counts = l.groups[g0].run & SUB == 0;
                    node.tri_start = ts as u32;
                    node.num_tris = nt as u32;
                    if nt > 0 && run_boxes {
                        node.run_box = out.run_boxes.len() as u32;
                        let ids: Vec<u32> = run_ids(l, (ts, nt)).collect();
                        out.run_boxes.push(box6(&run_box(scene, &ids)));
                    }
                }
                out.nodes.push(node);
            }
        }
        out.root = Some(out.reference(l, root, &index));
        out
    }

    /// The reference of layout reference `r` (its node's index in `index`).
    fn reference(&mut self, l: &Layout, r: u32, index: &[u32]) -> u32 {
        if r & LEAF != 0 {
            r
        } else if r & RUN != 0 {
            let g = &l.groups[(r & !RUN) as usize];
            self.runs.push((g.tri_start, g.num_tris));
            RUN | (self.runs.len() - 1) as u32
        } else {
            index.get(r as usize).copied().unwrap_or(NONE)
        }
    }

    /// The triangle run `(first packet, count)` of a leaf or run reference.
    #[inline(always)]
    pub(in crate::ray) fn leaf(&self, r: u32) -> (usize, usize) {
        if r & LEAF != 0 {
            leaf_run(r)
        } else {
            let (s, n) = self.runs[(r & !RUN) as usize];
            (s as usize, n as usize)
        }
    }

    /// Whether visiting leaf or run reference `r` counts as a node of the tree (a leaf does, a
    /// piece of a split run or a node's own run behind its box does not).
    #[inline(always)]
    pub(in crate::ray) fn leaf_counts(r: u32) -> bool {
        r & LEAF != 0 && r & CHUNK == 0
    }

    /// Whether node `n`'s own run is to be tested: it has no box, or the ray hits its box
    /// within `[tmin, tmax]` (a box test, counted in `stats`).
    #[inline(always)]
    pub(in crate::ray) fn run_hit<const STATS: bool>(
        &self,
        n: &Node8,
        r: &RayPre,
        (tmin, tmax): (f32, f32),
        stats: &mut RayStats,
    ) -> bool {
        let Some(b) = self.run_boxes.get(n.run_box as usize) else {
            return true;
        };
        if STATS {
            stats.boxes += 1;
        }
        r.slab(b, tmin, tmax).is_some()
    }

    /// Bytes used by the nodes.
    pub(in crate::ray) fn memory_bytes(&self) -> usize {
        self.nodes.len() * std::mem::size_of::<Node8>()
            + self.runs.len() * std::mem::size_of::<(u32, u32)>()
            + self.run_boxes.len() * std::mem::size_of::<[f32; 6]>()
    }

    /// Hint the cache to load what visiting `r` reads first.
    #[inline(always)]
    pub(in crate::ray) fn prefetch(&self, l: &Layout, r: u32) {
        #[cfg(target_arch = "x86_64")]
        {
            use core::arch::x86_64::{_mm_prefetch, _MM_HINT_T0};
            // SAFETY: a prefetch is only a hint and never faults, whatever the address.
            #[allow(unused_unsafe)]
            unsafe {
                if is_leaf(r) {
                    // A packet spans three cache lines (160 bytes, at offset 0 or 32 of a
                    // line); of a wide packet, the first three.
                    let (s, n) = self.leaf(r);
                    let p = if n >= WIDE_MIN {
                        l.wide.as_ptr().wrapping_add(s) as *const i8
                    } else {
                        l.packets.as_ptr().wrapping_add(s) as *const i8
                    };
                    _mm_prefetch::<_MM_HINT_T0>(p);
                    _mm_prefetch::<_MM_HINT_T0>(p.wrapping_add(64));
                    _mm_prefetch::<_MM_HINT_T0>(p.wrapping_add(128));
                } else {
                    let p = self.nodes.as_ptr().wrapping_add(r as usize) as *const i8;
                    for k in 0..4 {
                        _mm_prefetch::<_MM_HINT_T0>(p.wrapping_add(64 * k));
                    }
                }
            }
        }
        #[cfg(not(target_arch = "x86_64"))]
        let _ = (l, r);
    }

    /// Check the references: from the root, every lane with a box refers to a node in range
    /// or a run whose packets are in range, each node's empty lanes come after its full ones,
    /// and every triangle of the scene (`num_tris`) is stored in a run some reference reaches.
    pub(in crate::ray) fn validate(&self, l: &Layout, num_tris: usize) -> Result<(), String> {
        let Some(root) = self.root else {
            return if num_tris == 0 {
                Ok(())
            } else {
                Err("no root".into())
            };
        };
        let mut seen = vec![false; num_tris];
        let mut visited = vec![false; self.nodes.len()];
        let mut stack = vec![root];
        let mut run = |(s, n): (usize, usize)| -> Result<(), String> {
            let (len, size) = if n >= WIDE_MIN {
                (l.wide.len(), 16)
            } else {
                (l.packets.len(), 4)
            };
            if n > 0 && s + n.div_ceil(size) > len {
                return Err(format!("run {s}+{n} past {len} packets"));
            }
            for id in run_ids(l, (s, n)) {
                match seen.get_mut(id as usize) {
                    Some(v) => *v = true,
                    None => return Err(format!("triangle {id} out of range")),
                }
            }
            Ok(())
        };
        while let Some(r) = stack.pop() {
            if r == NONE {
                return Err("a lane with a box refers to nothing".into());
            }
            if is_leaf(r) {
                if r & LEAF == 0 && (r & !RUN) as usize >= self.runs.len() {
                    return Err(format!("run reference {r:#x} past the runs"));
                }
                run(self.leaf(r))?;
                continue;
            }
            let Some(n) = self.nodes.get(r as usize) else {
                return Err(format!(
                    "reference {r:#x} past the {} nodes",
                    self.nodes.len()
                ));
            };
            if std::mem::replace(&mut visited[r as usize], true) {
                continue;
            }
            run((n.tri_start as usize, n.num_tris as usize))?;
            if n.num_tris > 0 && n.run_box != NONE && n.run_box as usize >= self.run_boxes.len() {
                return Err(format!("node {r}: run box {} past the boxes", n.run_box));
            }
            for lane in 0..8 {
                let full = n.b[0][lane] <= n.b[3][lane];
                if full != (lane < n.lanes as usize) {
                    return Err(format!("node {r}: lane {lane} and its count {}", n.lanes));
                }
                if full {
                    stack.push(n.child[lane]);
                }
            }
            if n.more != NONE {
                stack.push(n.more);
            }
        }
        match seen.iter().position(|&v| !v) {
            Some(t) => Err(format!("triangle {t} reached by no reference")),
            None => Ok(()),
        }
    }
}

/// The scene ids of the triangles of the run `(first packet, count)` of layout `l`.
fn run_ids(l: &Layout, (s, n): (usize, usize)) -> impl Iterator<Item = u32> + '_ {
    (0..n).map(move |k| {
        if n >= WIDE_MIN {
            l.wide[s + k / 16].id[k % 16]
        } else {
            l.packets[s + k / 4].id[k % 4]
        }
    })
}

/// The lanes of the layout node at group `g0`, lowest visit priority first (occlusion visits
/// the highest hit lane first): a run tested as soon as its box is hit (eager) last, then
/// pieces of a run marked to be visited first, then the others; ties keep the layout's lane
/// order.
fn node_lanes(l: &Layout, g0: usize) -> Vec<Lane8> {
    let (_, _, _, ng) = l.node(g0 as u32);
    let mut lanes = Vec::with_capacity(4 * ng);
    for (j, g) in l.groups[g0..g0 + ng].iter().enumerate() {
        let f = l.faces[g0 + j];
        for i in 0..4 {
            if g.b[0][i] > g.b[3][i] {
                continue;
            }
            let key = if g.eager & (1 << i) != 0 {
                2
            } else {
                (g.eager & (FIRST << i) != 0) as u8
            };
            lanes.push((
                key,
                Lane8 {
                    b: std::array::from_fn(|p| g.b[p][i]),
                    child: g.child[i],
                    faces: (f >> (8 * i)) as u8,
                },
            ));
        }
    }
    lanes.sort_by_key(|x| x.0);
    lanes.into_iter().map(|x| x.1).collect()
}
