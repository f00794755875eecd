//! Machinery shared by the top-down builders (`kdt`, `obt`, `okdt`, `tf-oct`, `sah`).
//!
//! The builders work on a flat array of [`Item`]s (box, centroid and id of each surface, stored
//! inline so the partition passes read memory sequentially) which they partition in place,
//! recursing on sub-slices. Nodes are emitted in post-order into an [`Out`]; subtrees larger
//! than [`PAR_MIN`] surfaces are built on separate rayon tasks into their own `Out` and appended
//! with their ids shifted, which yields exactly the ids a sequential run assigns: the tree never
//! depends on the number of threads.

use super::{BuildNode, BuildTree, Prims};
use glam::Vec3;
use hirad_core::geom::Aabb;
use rayon::prelude::*;

/// Subtrees with at least this many surfaces are built as separate rayon tasks.
pub(crate) const PAR_MIN: usize = 8192;

/// One surface as the builders see it.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Item {
    pub lo: Vec3,
    pub hi: Vec3,
    pub c: Vec3,
    pub id: u32,
}

impl Item {
    /// `size(surface)`: longest edge of the bounding box.
    #[inline]
    pub fn size(&self) -> f32 {
        (self.hi - self.lo).max_element()
    }
}

/// The items of every surface, in id order.
pub(crate) fn items(prims: &Prims) -> Vec<Item> {
    prims
        .bbox
        .par_iter()
        .zip(prims.centroid.par_iter())
        .enumerate()
        .map(|(i, (b, c))| Item {
            lo: b.min,
            hi: b.max,
            c: *c,
            id: i as u32,
        })
        .collect()
}

/// Tight box of a slice of items.
#[inline]
pub(crate) fn union(items: &[Item]) -> Aabb {
    let mut lo = Vec3::splat(f32::INFINITY);
    let mut hi = Vec3::splat(f32::NEG_INFINITY);
    for it in items {
        lo = lo.min(it.lo);
        hi = hi.max(it.hi);
    }
    Aabb::new(lo, hi)
}

/// Surface ids of a slice of items.
#[inline]
pub(crate) fn ids(items: &[Item]) -> Vec<u32> {
    items.iter().map(|it| it.id).collect()
}

/// Nodes of a subtree in post-order, with the spatial cell each node was built from (equal to
/// its box for bounding-volume strategies).
#[derive(Default)]
pub(crate) struct Out {
    pub nodes: Vec<BuildNode>,
    pub cells: Vec<Aabb>,
    /// Nodes left unsplit because they reached the depth limit.
    pub capped: usize,
}

impl Out {
    /// Add a node, returning its id.
    #[inline]
    pub fn push(&mut self, node: BuildNode, cell: Aabb) -> u32 {
        self.nodes.push(node);
        self.cells.push(cell);
        (self.nodes.len() - 1) as u32
    }

    /// Append a subtree whose ids start at 0, shifting them; returns the shift.
    pub fn append(&mut self, mut other: Out) -> u32 {
        let off = self.nodes.len() as u32;
        self.capped += other.capped;
        other.capped = 0;
        if off > 0 {
            for n in &mut other.nodes {
                for c in &mut n.children {
                    *c += off;
                }
            }
        }
        if self.nodes.is_empty() {
            let capped = self.capped;
            *self = other;
            self.capped = capped;
        } else {
            self.nodes.append(&mut other.nodes);
            self.cells.append(&mut other.cells);
        }
        off
    }

    /// Append the outputs of parallel subtrees in order; returns their root ids shifted.
    pub fn append_all(&mut self, parts: Vec<(Out, Option<u32>)>) -> Vec<u32> {
        let mut roots = Vec::with_capacity(parts.len());
        for (o, r) in parts {
            let off = self.append(o);
            if let Some(r) = r {
                roots.push(r + off);
            }
        }
        roots
    }

    /// The finished tree (a single empty root when there are no surfaces); `max_depth` is
    /// named in the note about capped nodes.
    pub fn into_build(mut self, root: Option<u32>, max_depth: usize) -> (BuildTree, Vec<Aabb>) {
        let root = match root {
            Some(r) => r,
            None => self.push(BuildNode::default(), Aabb::EMPTY),
        };
        let mut notes = Vec::new();
        if self.capped > 0 {
            notes.push(format!(
                "{} clusters reached max_depth {max_depth} and were not split further",
                self.capped
            ));
        }
        (
            BuildTree {
                nodes: self.nodes,
                root,
                notes,
            },
            self.cells,
        )
    }
}

/// Three-way in-place partition of `items` by `class` (0 = first, 1 = middle, 2 = last),
/// returning the tight box of all items and the sizes of the first two groups.
#[inline]
pub(crate) fn partition3(
    items: &mut [Item],
    mut class: impl FnMut(&Item) -> u8,
) -> (Aabb, usize, usize) {
    let mut lo = Vec3::splat(f32::INFINITY);
    let mut hi = Vec3::splat(f32::NEG_INFINITY);
    let (mut a, mut m, mut b) = (0usize, 0usize, items.len());
    while m < b {
        let it = items[m];
        lo = lo.min(it.lo);
        hi = hi.max(it.hi);
        match class(&it) {
            0 => {
                items.swap(a, m);
                a += 1;
                m += 1;
            }
            1 => m += 1,
            _ => {
                b -= 1;
                items.swap(m, b);
            }
        }
    }
    (Aabb::new(lo, hi), a, b - a)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn item(x: f32, id: u32) -> Item {
        Item {
            lo: Vec3::splat(x),
            hi: Vec3::splat(x + 1.0),
            c: Vec3::splat(x + 0.5),
            id,
        }
    }

    #[test]
    fn partition3_groups_and_box() {
        let mut v: Vec<Item> = (0..10).map(|i| item(i as f32, i)).collect();
        let (b, n0, n1) = partition3(&mut v, |it| (it.id % 3) as u8);
        assert_eq!((n0, n1), (4, 3));
        assert_eq!(b, Aabb::new(Vec3::ZERO, Vec3::splat(10.0)));
        assert!(v[..4].iter().all(|it| it.id % 3 == 0));
        assert!(v[4..7].iter().all(|it| it.id % 3 == 1));
        assert!(v[7..].iter().all(|it| it.id % 3 == 2));
        let mut all = ids(&v);
        all.sort_unstable();
        assert_eq!(all, (0..10).collect::<Vec<_>>());
    }

    #[test]
    fn append_shifts_ids() {
        let mut a = Out::default();
        a.push(BuildNode::default(), Aabb::EMPTY);
        let mut b = Out::default();
        b.push(BuildNode::default(), Aabb::EMPTY);
        b.push(
            BuildNode {
                children: vec![0],
                ..Default::default()
            },
            Aabb::EMPTY,
        );
        let roots = a.append_all(vec![(b, Some(1))]);
        assert_eq!(roots, vec![2]);
        assert_eq!(a.nodes[2].children, vec![1]);
    }
}
