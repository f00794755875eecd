//! Strategy `sah`: a binned surface-area-heuristic BVH, the ray-tracing baseline of
//! `spec/clustering.md` (paper §3.2.2 discusses the trade-off).
//!
//! Tree of tight boxes with surfaces only at the leaves. The binned build below makes a
//! binary tree; it is then collapsed to at most `sah_width` children per node (default 8, the
//! wide BVH of ray tracers such as Embree's BVH8): starting from the binary children, the
//! inner child of largest surface area is repeatedly replaced by its own children while the
//! count stays within the width (ties: lowest position). A node holding more than
//! `sah_leaf_size` surfaces is always split: the centroids are binned into [`BINS`] equal bins
//! along each axis of the centroid bounds, and the plane between bins minimising
//! `area(left)·n(left) + area(right)·n(right)` over the three axes is chosen (ties: lowest axis,
//! then lowest plane). A node of at most [`SWEEP_MAX`] surfaces is split exactly instead: every
//! position of the surfaces sorted by centroid along each axis is costed the same way
//! (`sweep`). When all centroids of a larger node coincide the surfaces are split in two
//! halves of the (deterministic) current order. Below depth `max_depth/2` (reached only by pathological
//! centroid distributions, e.g. exponentially spaced) nodes are split at the centroid median
//! of their widest centroid axis instead, which bounds the depth by `max_depth/2 + log2(n)`.

use super::topdown::{self, Item, Out, PAR_MIN};
use super::{BuildNode, BuildTree, ClusterConfig, Prims};
use hirad_core::geom::Aabb;

/// Number of bins per axis: many, so that the binned split comes close to the exact sweep's
/// (`docs/perf-log.md` 2026-12-07 (55)).
pub const BINS: usize = 256;

/// Build the tree.
pub fn build(prims: &Prims, cfg: &ClusterConfig) -> BuildTree {
    let p = Params {
        leaf: cfg.sah_leaf_size.max(1),
        median_depth: cfg.max_depth / 2,
    };
    let mut items = topdown::items(prims);
    let (out, root) = node_par(&p, &mut items, 0);
    let mut tree = out.into_build(root, cfg.max_depth).0;
    collapse(&mut tree, cfg.sah_width.max(2));
    tree
}

/// Collapse the binary tree to at most `width` children per node (module docs). Nodes that
/// are pulled up become unreachable and are dropped by
/// [`ClusterTree::from_build`](super::ClusterTree::from_build).
pub fn collapse(tree: &mut BuildTree, width: usize) {
    if tree.nodes.is_empty() || width <= 2 {
        return;
    }
    let mut stack = vec![tree.root];
    while let Some(id) = stack.pop() {
        let mut kids = std::mem::take(&mut tree.nodes[id as usize].children);
        loop {
            let mut pick: Option<(usize, f32)> = None;
            for (i, &c) in kids.iter().enumerate() {
                let n = &tree.nodes[c as usize];
                if n.children.is_empty() || kids.len() - 1 + n.children.len() > width {
                    continue;
                }
                let a = n.bbox.surface_area();
                if pick.is_none_or(|(_, b)| a > b) {
                    pick = Some((i, a));
                }
            }
            let Some((i, _)) = pick else { break };
            let c = kids.remove(i);
            let grand = tree.nodes[c as usize].children.clone();
            for (k, g) in grand.into_iter().enumerate() {
                kids.insert(i + k, g);
            }
        }
        stack.extend(kids.iter().rev().copied());
        tree.nodes[id as usize].children = kids;
    }
}

/// Parameters of the build.
struct Params {
    leaf: usize,
    /// Depth from which nodes are split at the centroid median.
    median_depth: usize,
}

/// Bin index of a centroid coordinate.
#[inline]
fn bin_of(x: f32, lo: f32, scale: f32) -> usize {
    (((x - lo) * scale) as usize).min(BINS - 1)
}

/// Partition `items` for a split; returns the box and the size of the left part, or `None`
/// for a leaf.
fn split(p: &Params, items: &mut [Item], depth: usize) -> (Aabb, Option<usize>) {
    let mut cb = Aabb::EMPTY;
    let mut bbox = Aabb::EMPTY;
    for it in items.iter() {
        cb.grow(it.c);
        bbox.grow(it.lo);
        bbox.grow(it.hi);
    }
    let n = items.len();
    if n <= p.leaf {
        return (bbox, None);
    }
    let ext = cb.extent();
    if depth >= p.median_depth {
        let a = cb.longest_axis();
        items.select_nth_unstable_by(n / 2, |x, y| {
            x.c[a].total_cmp(&y.c[a]).then(x.id.cmp(&y.id))
        });
        return (bbox, Some(n / 2));
    }
    if n <= SWEEP_MAX {
        return (bbox, Some(sweep(items)));
    }
    let mut best: Option<(f32, usize, usize)> = None; // (cost, axis, last bin of the left side)
    for a in 0..3 {
        if !ext[a].is_finite() || ext[a] <= 0.0 {
            continue;
        }
        let scale = BINS as f32 / ext[a];
        let mut boxes = [Aabb::EMPTY; BINS];
        let mut counts = [0usize; BINS];
        for it in items.iter() {
            let b = bin_of(it.c[a], cb.min[a], scale);
            counts[b] += 1;
            boxes[b].grow(it.lo);
            boxes[b].grow(it.hi);
        }
        // Right-to-left sweep: area·count of the right side of every plane.
        let mut right_cost = [0f32; BINS];
        let mut acc = Aabb::EMPTY;
        let mut cnt = 0usize;
        for b in (1..BINS).rev() {
            acc.grow_box(&boxes[b]);
            cnt += counts[b];
            right_cost[b - 1] = acc.surface_area() * cnt as f32;
        }
        let mut acc = Aabb::EMPTY;
        let mut cnt = 0usize;
        for b in 0..BINS - 1 {
            acc.grow_box(&boxes[b]);
            cnt += counts[b];
            if cnt == 0 || cnt == n {
                continue;
            }
            let cost = acc.surface_area() * cnt as f32 + right_cost[b];
            if best.is_none_or(|(c, _, _)| cost < c) {
                best = Some((cost, a, b));
            }
        }
    }
    let nl = match best {
        Some((_, a, last)) => {
            let scale = BINS as f32 / ext[a];
            let lo = cb.min[a];
            let (_, _, nl) =
                topdown::partition3(items, |it| (bin_of(it.c[a], lo, scale) > last) as u8 + 1);
            nl
        }
        None => n / 2,
    };
    (bbox, Some(nl))
}

/// Largest node split by an exact sweep (`sweep`) instead of bins.
pub const SWEEP_MAX: usize = 64;

/// The exact object split of a small node: on each axis the items sorted by centroid (ties by
/// id), every split position costed as `area(left)·n(left) + area(right)·n(right)`; the
/// cheapest (ties: lowest axis, then lowest position) is applied. Returns the left size.
fn sweep(items: &mut [Item]) -> usize {
    let n = items.len();
    let key = |a: usize| move |x: &Item, y: &Item| x.c[a].total_cmp(&y.c[a]).then(x.id.cmp(&y.id));
    let mut right = vec![0f32; n];
    let mut best: Option<(f32, usize, usize)> = None;
    for a in 0..3 {
        items.sort_unstable_by(key(a));
        let mut acc = Aabb::EMPTY;
        for i in (1..n).rev() {
            acc.grow(items[i].lo);
            acc.grow(items[i].hi);
            right[i] = acc.surface_area() * (n - i) as f32;
        }
        let mut acc = Aabb::EMPTY;
        for i in 1..n {
            acc.grow(items[i - 1].lo);
            acc.grow(items[i - 1].hi);
            let cost = acc.surface_area() * i as f32 + right[i];
            if best.is_none_or(|(c, _, _)| cost < c) {
                best = Some((cost, a, i));
            }
        }
    }
    let (_, a, i) = best.expect("a node to split has two items or more");
    if a != 2 {
        // The items are in the last axis's order.
        items.sort_unstable_by(key(a));
    }
    i
}

/// Emit a node.
#[inline]
fn finish(items: &[Item], children: Vec<u32>, bbox: Aabb, out: &mut Out) -> u32 {
    let surfaces = if children.is_empty() {
        topdown::ids(items)
    } else {
        Vec::new()
    };
    out.push(
        BuildNode {
            bbox,
            children,
            surfaces,
        },
        bbox,
    )
}

/// Sequential build of a subtree into `out`.
fn node(p: &Params, items: &mut [Item], depth: usize, out: &mut Out) -> u32 {
    let (bbox, sp) = split(p, items, depth);
    let Some(nl) = sp else {
        return finish(items, Vec::new(), bbox, out);
    };
    let (l, r) = items.split_at_mut(nl);
    let a = node(p, l, depth + 1, out);
    let b = node(p, r, depth + 1, out);
    finish(&[], vec![a, b], bbox, out)
}

/// Parallel build: large subtrees on separate rayon tasks, same ids as [`node`].
fn node_par(p: &Params, items: &mut [Item], depth: usize) -> (Out, Option<u32>) {
    let mut out = Out::default();
    if items.is_empty() {
        return (out, None);
    }
    if items.len() < PAR_MIN {
        let r = node(p, items, depth, &mut out);
        return (out, Some(r));
    }
    let (bbox, sp) = split(p, items, depth);
    let Some(nl) = sp else {
        let r = finish(items, Vec::new(), bbox, &mut out);
        return (out, Some(r));
    };
    let (l, r) = items.split_at_mut(nl);
    let (a, b) = rayon::join(|| node_par(p, l, depth + 1), || node_par(p, r, depth + 1));
    let children = out.append_all(vec![a, b]);
    let id = finish(&[], children, bbox, &mut out);
    (out, Some(id))
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    /// `area(left)·n(left) + area(right)·n(right)` of a split, boxes grown from scratch.
    fn cost(left: &[Item], right: &[Item]) -> f32 {
        let area = |s: &[Item]| {
            let mut b = Aabb::EMPTY;
            for it in s {
                b.grow(it.lo);
                b.grow(it.hi);
            }
            b.surface_area() * s.len() as f32
        };
        area(left) + area(right)
    }

    #[test]
    fn sweep_finds_the_cheapest_split_of_every_axis_order() {
        // Deterministic pseudo-random boxes of varied sizes.
        let mut state = 0x9E37_79B9_7F4A_7C15u64;
        let mut rnd = || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 40) as f32 / (1u64 << 24) as f32
        };
        for n in [2usize, 3, 7, 20, 64] {
            let mut items: Vec<Item> = (0..n as u32)
                .map(|id| {
                    let c = Vec3::new(rnd(), rnd(), rnd()) * 10.0;
                    let h = Vec3::new(rnd(), rnd(), rnd()) * if id % 3 == 0 { 4.0 } else { 0.3 };
                    Item {
                        lo: c - h,
                        hi: c + h,
                        c,
                        id,
                    }
                })
                .collect();
            // Brute force: every position of every axis order.
            let mut best = f32::INFINITY;
            for a in 0..3 {
                let mut v = items.clone();
                v.sort_by(|x, y| x.c[a].total_cmp(&y.c[a]).then(x.id.cmp(&y.id)));
                for i in 1..n {
                    best = best.min(cost(&v[..i], &v[i..]));
                }
            }
            let nl = sweep(&mut items);
            assert!((1..n).contains(&nl));
            let got = cost(&items[..nl], &items[nl..]);
            assert!(
                (got - best).abs() <= 1e-4 * best,
                "n {n}: {got} against {best}"
            );
            let mut ids: Vec<u32> = items.iter().map(|it| it.id).collect();
            ids.sort_unstable();
            assert_eq!(ids, (0..n as u32).collect::<Vec<_>>());
        }
    }
}
