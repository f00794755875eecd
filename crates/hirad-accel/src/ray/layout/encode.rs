//! Child references of the laid-out tree (a group, a leaf or a chunk encoded in place, a
//! node's own run behind its box) and the [`Group`] of up to four child boxes.

use hirad_core::geom::Aabb;

/// Reference flag of a leaf encoded in place.
pub(in crate::ray) const LEAF: u32 = 1 << 31;
pub(super) const LEAF_COUNT_SHIFT: u32 = 26;
/// Largest triangle count of an in-place leaf.
pub(super) const LEAF_MAX_TRIS: usize = (1 << (31 - LEAF_COUNT_SHIFT)) - 1;
/// Flag of an in-place run that is a piece of a node's own triangles ([`CHUNK_MAX`](super::run_tree::CHUNK_MAX)), not a
/// leaf of the tree.
pub(super) const CHUNK: u32 = 1 << 25;
/// Largest first packet of an in-place leaf.
pub(super) const LEAF_MAX_START: usize = CHUNK as usize - 1;
/// Reference flag of a node's own triangle run behind a box of its own (bit 31 clear): the
/// low bits are the index of the group holding the run.
pub(in crate::ray) const RUN: u32 = 1 << 30;
/// Reference of an empty lane.
pub(in crate::ray) const NONE: u32 = u32::MAX;

/// Decode the triangle run `(first packet, count)` of a leaf (or chunk) reference.
#[inline(always)]
pub(in crate::ray) fn leaf_run(r: u32) -> (usize, usize) {
    (
        (r & LEAF_MAX_START as u32) as usize,
        ((r & !LEAF) >> LEAF_COUNT_SHIFT) as usize,
    )
}

pub(super) fn leaf_ref(start: usize, count: usize) -> u32 {
    LEAF | ((count as u32) << LEAF_COUNT_SHIFT) | start as u32
}

/// Up to four children of one node: boxes in structure-of-arrays form and references.
#[derive(Clone, Copy, Debug)]
#[repr(C, align(64))]
pub(in crate::ray) struct Group {
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
    /// Bit of the run's lane when occlusion queries test the run before any other lane hit
    /// ([`EAGER_HITS_PER_TEST`](super::run_tree::EAGER_HITS_PER_TEST)); bits 4–7: lanes
    /// holding pieces of such a run split into a [`RunTree`](super::run_tree::RunTree), which
    /// occlusion queries visit before the other lanes hit ([`FIRST`] shifted by the lane).
    /// The [`Node8`](super::node8::Node8)s put these lanes last, where occlusion starts.
    pub eager: u8,
    /// Bit of the lane holding the box of the node's own triangle run (0: none in this group);
    /// [`SUB`] in a group of pieces of a split run.
    pub run: u16,
}

impl Group {
    /// Put `b` and reference `r` in `lane`.
    pub(in crate::ray) fn set_lane(&mut self, lane: usize, b: &Aabb, r: u32) {
        for a in 0..3 {
            self.b[a][lane] = b.min[a];
            self.b[a + 3][lane] = b.max[a];
        }
        self.child[lane] = r;
        self.lanes += 1;
    }
}

impl Group {
    /// A group without lanes: inverted infinite boxes, never hit.
    pub(in crate::ray) const EMPTY: Group = {
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
    };
}

impl Default for Group {
    fn default() -> Self {
        Group::EMPTY
    }
}

/// Bit of [`Group::eager`] (shifted by the lane) of a piece visited first.
pub(in crate::ray) const FIRST: u8 = 1 << 4;

/// Bit of [`Group::run`] marking a group that holds pieces of a node's own run ([`RunTree`](super::run_tree::RunTree))
/// rather than a node of the tree.
pub(in crate::ray) const SUB: u16 = 1 << 15;
