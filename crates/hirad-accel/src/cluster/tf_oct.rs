//! Strategy `tf-oct`, the tight-fitting octree of Christensen et al. 1997
//! (`spec/clustering.md`, paper §2.2.1).
//!
//! A node's box is the tight box of the surfaces it received (the root: the scene's bounding
//! box). While a node holds more than `octree_leaf_size` surfaces, its box is split into 8
//! octants at its centre: a surface smaller than an octant (`size(surface) < size(box)/2`) goes
//! to the octant containing its centroid (a coordinate equal to the centre goes to the upper
//! octant), any other surface stays attached to the node. Each non-empty octant becomes a child
//! whose box is refit tightly to what it received, and recursion goes on. Every child receives
//! strictly fewer surfaces than its parent (the surfaces reaching the far side of the longest
//! axis either stay or lie in an upper octant), so recursion ends; `max_depth` is a safety net.

use super::topdown::{self, Item, Out, PAR_MIN};
use super::{BuildNode, BuildTree, ClusterConfig, Prims};
use glam::Vec3;
use rayon::prelude::*;

/// Parameters of the octree.
#[derive(Clone, Copy)]
struct Params {
    leaf: usize,
    max_depth: usize,
}

/// Build the tree.
pub fn build(prims: &Prims, cfg: &ClusterConfig) -> BuildTree {
    let p = Params {
        leaf: cfg.octree_leaf_size.max(1),
        max_depth: cfg.max_depth,
    };
    let mut items = topdown::items(prims);
    let mut scratch = items.clone();
    let (out, root) = node_par(&p, &mut items, &mut scratch, 0);
    out.into_build(root, p.max_depth).0
}

/// Bucket 0 = stays, 1 + octant otherwise.
#[inline]
fn bucket(it: &Item, mid: Vec3, oct_size: f32) -> usize {
    if it.size() < oct_size {
        1 + (it.c.x >= mid.x) as usize
            + 2 * (it.c.y >= mid.y) as usize
            + 4 * (it.c.z >= mid.z) as usize
    } else {
        0
    }
}

/// Sort `items` by bucket (stable, through `scratch`); returns the tight box and the bucket
/// boundaries, or `None` when the node is a leaf.
fn split(
    p: &Params,
    items: &mut [Item],
    scratch: &mut [Item],
    depth: usize,
) -> (hirad_core::geom::Aabb, Option<[usize; 10]>) {
    let bbox = topdown::union(items);
    if items.len() <= p.leaf || depth >= p.max_depth {
        return (bbox, None);
    }
    let mid = bbox.center();
    let oct_size = 0.5 * bbox.size();
    let mut start = [0usize; 10];
    for it in items.iter() {
        start[bucket(it, mid, oct_size) + 1] += 1;
    }
    if start[1] == items.len() {
        // Every surface is at least as large as an octant: nothing to split.
        return (bbox, None);
    }
    for k in 1..10 {
        start[k] += start[k - 1];
    }
    let mut fill = start;
    for it in items.iter() {
        let b = bucket(it, mid, oct_size);
        scratch[fill[b]] = *it;
        fill[b] += 1;
    }
    items.copy_from_slice(scratch);
    (bbox, Some(start))
}

/// The node, given its children.
#[inline]
fn finish(stay: &[Item], children: Vec<u32>, bbox: hirad_core::geom::Aabb, out: &mut Out) -> u32 {
    out.push(
        BuildNode {
            bbox,
            children,
            surfaces: topdown::ids(stay),
        },
        bbox,
    )
}

/// Sequential build of a subtree into `out`.
fn node(p: &Params, items: &mut [Item], scratch: &mut [Item], depth: usize, out: &mut Out) -> u32 {
    let (bbox, sp) = split(p, items, scratch, depth);
    let Some(start) = sp else {
        out.capped += (depth >= p.max_depth && items.len() > p.leaf) as usize;
        return finish(items, Vec::new(), bbox, out);
    };
    let mut children = Vec::new();
    for k in 1..9 {
        let (a, b) = (start[k], start[k + 1]);
        if a < b {
            children.push(node(
                p,
                &mut items[a..b],
                &mut scratch[a..b],
                depth + 1,
                out,
            ));
        }
    }
    finish(&items[..start[1]], children, bbox, out)
}

/// Parallel build: octants of large nodes on separate rayon tasks, same ids as [`node`].
fn node_par(
    p: &Params,
    items: &mut [Item],
    scratch: &mut [Item],
    depth: usize,
) -> (Out, Option<u32>) {
    let mut out = Out::default();
    if items.is_empty() {
        return (out, None);
    }
    if items.len() < PAR_MIN {
        let r = node(p, items, scratch, depth, &mut out);
        return (out, Some(r));
    }
    let (bbox, sp) = split(p, items, scratch, depth);
    let Some(start) = sp else {
        out.capped += (depth >= p.max_depth && items.len() > p.leaf) as usize;
        let r = finish(items, Vec::new(), bbox, &mut out);
        return (out, Some(r));
    };
    let (stay, mut rest) = items.split_at_mut(start[1]);
    let (_, mut srest) = scratch.split_at_mut(start[1]);
    let mut parts = Vec::with_capacity(8);
    for k in 1..9 {
        let n = start[k + 1] - start[k];
        let (a, r) = rest.split_at_mut(n);
        let (sa, sr) = srest.split_at_mut(n);
        rest = r;
        srest = sr;
        if n > 0 {
            parts.push((a, sa));
        }
    }
    let subs: Vec<(Out, Option<u32>)> = parts
        .into_par_iter()
        .map(|(a, sa)| node_par(p, a, sa, depth + 1))
        .collect();
    let children = out.append_all(subs);
    let id = finish(stay, children, bbox, &mut out);
    (out, Some(id))
}
