//! Traversal layout of a cluster tree ([`Layout`]): the tree's own nodes and triangles stored
//! for 8-wide SIMD box tests and packet triangle tests, in depth-first order. No node is
//! added (a node of more than eight lanes continues in a second eight-wide node), and every
//! triangle is tested behind the box of the node it is attached to (or of a piece of that
//! node's run); [`Boxes`] chooses which boxes are tested, and
//! with [`Boxes::Tight`] inner children are pulled up into their parent's lanes.
//!
//! - `encode`: child references (group, leaf or chunk in place, own run) and the [`Group`];
//! - `run_tree`: a node's long own run split into boxed pieces, and its cost model;
//! - `packets`: triangles four or sixteen to a packet, and the run tests;
//! - `faces`: face bits, which let a ray lying in a face's plane skip the lane;
//! - `node8`: the groups turned into eight-wide nodes, which the queries traverse;
//! - `slab8`: the 8-wide slab test of a node;
//! - `build`: `Layout::new`, which lays a tree out.

mod build;
mod encode;
mod faces;
mod node8;
mod packets;
mod run_tree;
mod slab8;

pub(in crate::ray) use encode::NONE;
#[cfg(test)]
pub(in crate::ray) use encode::SUB;
pub(in crate::ray) use encode::{leaf_run, LEAF, RUN};
pub(in crate::ray) use node8::{is_leaf, Node8, Nodes8};
#[cfg(test)]
pub(in crate::ray) use packets::has_avx512;
#[cfg(test)]
pub(in crate::ray) use packets::WIDE_MIN;
pub(in crate::ray) use packets::{Packet, Wide};
pub(in crate::ray) use slab8::Slab8;

use encode::Group;
use hirad_core::choice;
use serde::{Deserialize, Serialize};

/// Which boxes the traversal tests (`raybench --boxes`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Boxes {
    /// As [`Boxes::Nodes`], and a node's own run longer than 4 triangles is split into
    /// pieces of nearby triangles behind boxes of their own (`RunTree` in `ray/layout/run_tree.rs`: cut
    /// by the surface area heuristic, down to chunks of at most 4), where a cost model says
    /// the boxes pay for their box tests (`STEP_COST`). The pieces take the lanes the whole
    /// run would have taken, so every triangle is still reached only behind its node's box;
    /// a ray tests only the pieces whose boxes it hits (the many surfaces a `kdt` node keeps
    /// because they cross its split plane, a large leaf). Inner children are pulled up into
    /// their parent's lanes while the parent holds at most eight (one lane kept for its own
    /// run), the inner child of largest box first, as wide BVHs collapse binary ones: a child
    /// pulled up is not visited as a node, its children take its lane and its own triangles a
    /// lane of their own behind their box (at most 31), or the lanes of their top pieces when
    /// they were split. A ray visits half as many nodes of the binary `kdt`, `obt` and `okdt`
    /// trees or fewer, whose nodes held two lanes.
    #[default]
    Tight,
    /// Every node's box shrunk to what lies below it (the union of its own triangles' boxes
    /// and its children's boxes), and the triangles attached to an inner node bounded by a
    /// box of their own in a free lane of the node's eight-lane node, so that they are tested
    /// only when the ray hits that box. Same nodes, children and triangles as the tree: only
    /// the boxes are tighter, and a node without triangles and with one child (the empty half
    /// of a `kdt`/`obt` cell), whose tight box is its child's, is passed through. Differs from
    /// [`Boxes::Cluster`] only where the strategy's boxes are loose (`kdt` and `obt` cells),
    /// at such nodes and at inner nodes with triangles of their own.
    Nodes,
    /// The strategy's own boxes (grown to contain their contents exactly), and the triangles
    /// of a node tested whenever the node is visited: the traversal the paper describes (the
    /// face bits of the layout apply to every kind of boxes).
    Cluster,
}

impl Boxes {
    /// Every choice.
    pub const ALL: [Boxes; 3] = [Boxes::Tight, Boxes::Nodes, Boxes::Cluster];
}

choice!(Boxes, "traversal boxes", Tight => "tight", Nodes => "nodes", Cluster => "cluster");

/// The laid-out tree.
///
/// - A node with children (or with more triangles than a leaf reference can hold) owns
///   `⌈lanes/4⌉` consecutive [`Group`]s of 128 bytes (its children's, or with tight boxes
///   those left after inner children were pulled up into it; a node pulled up owns none):
///   the boxes of up to four children in structure-of-arrays form (one 4-wide SIMD slab test
///   checks all four), the children's
///   references, the node's own triangle run (surfaces attached at inner nodes) and, in the
///   first group, its number of groups.
/// - A leaf is not stored as a node at all: its reference in the parent's group encodes its
///   triangle run directly (bit 31 set, 5 bits of count, a chunk bit, 25 bits of first
///   packet), so reaching a leaf reads only its triangles.
/// - Triangles are stored four to a [`Packet`] (structure of arrays, one SIMD edge test for
///   four triangles); each node's run starts a new packet, unused lanes are masked out. Runs of
///   [`WIDE_MIN`](packets::WIDE_MIN) triangles or more (surfaces attached at inner nodes of
///   `kdt`, `obt`, `okdt`, large leaves) are stored sixteen to a [`Wide`] packet instead,
///   tested in one AVX-512 pass where the CPU has it (four SSE passes otherwise). Which array
///   a run lives in follows from its length alone.
///
/// With tight boxes ([`Boxes::Tight`], [`Boxes::Nodes`]) every box is tight around what lies
/// below its node, whatever box the strategy gave it (`kdt`/`obt` nodes keep their k-d cells,
/// mostly empty space); the triangles of an inner node whose eight-lane node has a free lane
/// get a box of their own in that lane, so that the node's one SIMD test decides them with its
/// children (without a free lane, a box of their own is tested before them at each visit of
/// the node, `Node8::run_box`); a node without triangles of its own and with a single child,
/// whose box is its child's, is passed through (its parent's lane refers to the child). A run
/// longer than `CHUNK_MAX` is split into pieces behind boxes of their own (`RunTree`) when the
/// cost model says it pays ([`Boxes::Tight`] only). With [`Boxes::Cluster`] the boxes are the
/// strategy's boxes grown to contain their contents exactly (strategies may leave an f32 slack that
/// `validate` tolerates; a ray grazing such a triangle must still reach it, so that the result
/// equals brute force for any tree), and a node's triangles are tested whenever it is visited,
/// as the paper's traversal does. Every lane carries six face bits (`faces`).
#[derive(Clone, Debug, Default)]
pub(in crate::ray) struct Layout {
    /// Box of the root, `[minx, miny, minz, maxx, maxy, maxz]`, tested first.
    pub root_box: [f32; 6],
    /// Reference of the root; `None` for a tree without nodes.
    pub root: Option<u32>,
    /// The nodes' groups (the build's form of the nodes, turned into
    /// [`Nodes8`] for the queries).
    pub groups: Vec<Group>,
    /// Per group, 6 bits per lane ([`faces::face_bits`]): bit `a` (`3 + a`) set when everything in
    /// the lane that touches the plane of the box's min (max) face along axis `a` lies in
    /// that plane.
    pub faces: Vec<u32>,
    /// Triangles of runs shorter than [`WIDE_MIN`](packets::WIDE_MIN), in node order, four to
    /// a packet.
    pub packets: Vec<Packet>,
    /// Triangles of runs of [`WIDE_MIN`](packets::WIDE_MIN) or more, in node order, sixteen to
    /// a packet.
    pub wide: Vec<Wide>,
}

impl Layout {
    /// Bytes used by the layout.
    pub(in crate::ray) fn memory_bytes(&self) -> usize {
        self.packets.len() * std::mem::size_of::<Packet>()
            + self.wide.len() * std::mem::size_of::<Wide>()
    }

    /// The triangle run `(first packet, count)` to test on visiting a reference (a leaf's, a
    /// node's own run behind its box, or a node's own run without a box) and, for a node with
    /// groups, its first group and number of groups.
    #[inline(always)]
    pub(in crate::ray) fn node(&self, r: u32) -> (usize, usize, usize, usize) {
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
}
