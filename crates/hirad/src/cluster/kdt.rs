//! Strategy `kdt` (see `spec/clustering.md`). Placeholder until the strategy lands: one node
//! holding every surface, which is a valid tree for the other modules to work with.

use super::{BuildNode, BuildTree, ClusterConfig, Prims};
use crate::geom::Aabb;

/// Build the tree.
pub fn build(prims: &Prims, _cfg: &ClusterConfig) -> BuildTree {
    let mut bbox = Aabb::EMPTY;
    for b in &prims.bbox {
        bbox.grow_box(b);
    }
    let mut t = BuildTree::default();
    t.root = t.push(BuildNode {
        bbox,
        children: vec![],
        surfaces: (0..prims.len() as u32).collect(),
    });
    t
}
