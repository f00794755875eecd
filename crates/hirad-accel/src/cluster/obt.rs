//! Strategy `obt(λ)`: the overlapping binary tree (paper §2.3), and the binary cell
//! subdivision shared with `kdt` (λ = 0) and `okdt` (tight boxes, chains collapsed): cells
//! are halved top-down, and a surface crossing the split plane is pushed into a half when it
//! is small against that half (`size ≤ λ·size(child)/2`), attached to the cell otherwise.
//! [`build`] gives the construction, the boxes and the consequences of the push rule.

use super::topdown::{self, Item, Out, PAR_MIN};
use super::{BuildNode, BuildTree, ClusterConfig, Prims};
use hirad_core::geom::Aabb;

/// Parameters of the binary cell subdivision.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Binary {
    /// Overlap parameter; 0 gives `kdt`.
    pub lambda: f32,
    /// Split a cell only while it holds more than this many surfaces.
    pub leaf: usize,
    /// Depth limit.
    pub max_depth: usize,
    /// `okdt`: tight boxes, cells without surfaces and with one child collapsed.
    pub tight: bool,
}

impl Binary {
    /// The parameters of `obt` with overlap `lambda`.
    pub fn obt(cfg: &ClusterConfig, lambda: f32) -> Binary {
        Binary {
            lambda,
            leaf: cfg.kdt_leaf_size.max(1),
            max_depth: cfg.max_depth,
            tight: false,
        }
    }
}

/// Build the tree.
///
/// Construction, top-down from the scene's bounding cube: a cell holding more than
/// `kdt_leaf_size` surfaces is split at the middle of its longest axis (ties: lowest axis index).
/// A surface whose box lies entirely on one side of the split plane (`max ≤ p` goes left — this
/// is also where a flat surface lying in the plane goes — `min ≥ p` goes right) descends into
/// that half; a surface crossing the plane is pushed into the half containing its centroid
/// (centroid `≤ p` means left) when `size(surface) ≤ λ·size(child)/2`, otherwise it is attached
/// to the cell. Empty cells are not stored. Recursion stops at `max_depth` or when the cell is
/// too small for f32 to place a plane strictly inside it.
///
/// Boxes: a `kdt`/`obt` node's box is its cell grown to contain every surface below it (for
/// `kdt` that is exactly the cell: every surface lies inside the cell it is attached to), so
/// empty space inside a cell is part of the cluster. An `okdt` node's box is tight around its
/// contents instead.
///
/// Consequences of the push rule (checked by the property tests): a surface of size S attached
/// to a cell that was split crosses its plane with S > λ·size(child)/2, so the halves of that
/// cell are smaller than 2S/λ (the cell itself is < 2S/λ unless its longest edge is unique, then
/// < 4S/λ); and a child box extends at most λ·size(child)/2 beyond the split plane, so two
/// sibling boxes of (cell) size d overlap along the split axis by at most λ·d ≤ (8/3)·λ·d.
pub fn build(prims: &Prims, cfg: &ClusterConfig) -> BuildTree {
    build_with_cells(prims, cfg).0
}

/// Build the tree and return, for every node of the [`BuildTree`], the (ungrown) cell it was
/// built from.
pub fn build_with_cells(prims: &Prims, cfg: &ClusterConfig) -> (BuildTree, Vec<Aabb>) {
    build_binary(prims, Binary::obt(cfg, cfg.lambda))
}

/// The root cell: the bounding cube of the scene, centred on its bounding box.
pub fn root_cube(prims: &Prims) -> Aabb {
    let mut b = Aabb::EMPTY;
    for x in &prims.bbox {
        b.grow_box(x);
    }
    if b.is_empty() {
        return b;
    }
    // Union with the box itself so rounding never leaves a surface outside the cube.
    b.cube().union(&b)
}

/// Run the binary subdivision with parameters `p`.
pub(crate) fn build_binary(prims: &Prims, p: Binary) -> (BuildTree, Vec<Aabb>) {
    let mut items = topdown::items(prims);
    let cell = root_cube(prims);
    let (out, root) = node_par(&p, &mut items, cell, 0);
    out.into_build(root, p.max_depth)
}

/// Split plane of a cell: axis, position and the two child cells; `None` when the cell cannot
/// be split (degenerate or below f32 resolution).
#[inline]
fn plane(cell: &Aabb) -> Option<(usize, f32, Aabb, Aabb)> {
    let a = cell.longest_axis();
    let (lo, hi) = (cell.min[a], cell.max[a]);
    let p = 0.5 * (lo + hi);
    if !(p > lo && p < hi) {
        return None;
    }
    let mut l = *cell;
    l.max[a] = p;
    let mut r = *cell;
    r.min[a] = p;
    Some((a, p, l, r))
}

/// Partition `items` in place into stay | left | right; returns the tight box and the group
/// sizes, or only the box (`None`) when the cell is a leaf.
#[inline]
fn split(
    p: &Binary,
    items: &mut [Item],
    cell: &Aabb,
    depth: usize,
) -> (Aabb, Option<(usize, usize, Aabb, Aabb)>) {
    let sp = if items.len() > p.leaf && depth < p.max_depth {
        plane(cell)
    } else {
        None
    };
    let Some((a, pos, lcell, rcell)) = sp else {
        return (topdown::union(items), None);
    };
    let tl = p.lambda * lcell.size() * 0.5;
    let tr = p.lambda * rcell.size() * 0.5;
    let (bbox, ns, nl) = topdown::partition3(items, |it| {
        if it.hi[a] <= pos {
            1
        } else if it.lo[a] >= pos {
            2
        } else if it.c[a] <= pos {
            // Crossing: pushed to the centroid's half when small enough.
            (it.size() <= tl) as u8
        } else {
            2 * (it.size() <= tr) as u8
        }
    });
    (bbox, Some((ns, nl, lcell, rcell)))
}

/// Emit the node of a cell whose children are built; returns its id (or, for `okdt`, the
/// child replacing it).
#[inline]
fn finish(
    p: &Binary,
    stay: &[Item],
    children: Vec<u32>,
    bbox: Aabb,
    cell: Aabb,
    out: &mut Out,
) -> u32 {
    if p.tight && stay.is_empty() && children.len() == 1 {
        return children[0];
    }
    let bbox = if p.tight { bbox } else { bbox.union(&cell) };
    out.push(
        BuildNode {
            bbox,
            children,
            surfaces: topdown::ids(stay),
        },
        cell,
    )
}

/// Sequential build of the subtree of `cell` into `out`.
fn node(p: &Binary, items: &mut [Item], cell: Aabb, depth: usize, out: &mut Out) -> Option<u32> {
    if items.is_empty() {
        return None;
    }
    let (bbox, sp) = split(p, items, &cell, depth);
    let Some((ns, nl, lcell, rcell)) = sp else {
        out.capped += (depth >= p.max_depth && items.len() > p.leaf) as usize;
        return Some(finish(p, items, Vec::new(), bbox, cell, out));
    };
    let (stay, rest) = items.split_at_mut(ns);
    let (left, right) = rest.split_at_mut(nl);
    let mut children = Vec::with_capacity(2);
    children.extend(node(p, left, lcell, depth + 1, out));
    children.extend(node(p, right, rcell, depth + 1, out));
    Some(finish(p, stay, children, bbox, cell, out))
}

/// Parallel build: large subtrees on separate rayon tasks, same ids as [`node`].
fn node_par(p: &Binary, items: &mut [Item], cell: Aabb, depth: usize) -> (Out, Option<u32>) {
    let mut out = Out::default();
    if items.len() < PAR_MIN {
        let r = node(p, items, cell, depth, &mut out);
        return (out, r);
    }
    let (bbox, sp) = split(p, items, &cell, depth);
    let Some((ns, nl, lcell, rcell)) = sp else {
        out.capped += (depth >= p.max_depth && items.len() > p.leaf) as usize;
        let r = finish(p, items, Vec::new(), bbox, cell, &mut out);
        return (out, Some(r));
    };
    let (stay, rest) = items.split_at_mut(ns);
    let (left, right) = rest.split_at_mut(nl);
    let (l, r) = rayon::join(
        || node_par(p, left, lcell, depth + 1),
        || node_par(p, right, rcell, depth + 1),
    );
    let children = out.append_all(vec![l, r]);
    let id = finish(p, stay, children, bbox, cell, &mut out);
    (out, Some(id))
}
