//! Strategy `proxi` (see `spec/clustering.md`). Placeholder until the strategy lands: one node
//! holding every surface, which is a valid tree for the other modules to work with.

use super::{BuildNode, BuildTree, ClusterConfig, Prims};
use crate::geom::Aabb;

/// Build the tree over every surface.
pub fn build(prims: &Prims, cfg: &ClusterConfig) -> BuildTree {
    let all: Vec<u32> = (0..prims.len() as u32).collect();
    let mut t = BuildTree::default();
    t.root = build_subset(prims, &all, cfg, &mut t);
    t
}

/// Cluster the surfaces `subset` bottom-up, adding the nodes to `out`; returns the id of the
/// subtree's root, whose box is tight around the subset. Used by `okdt-p` to re-cluster
/// over-full clusters locally.
pub fn build_subset(
    prims: &Prims,
    subset: &[u32],
    _cfg: &ClusterConfig,
    out: &mut BuildTree,
) -> u32 {
    let mut bbox = Aabb::EMPTY;
    for &s in subset {
        bbox.grow_box(&prims.bbox[s as usize]);
    }
    out.push(BuildNode {
        bbox,
        children: vec![],
        surfaces: subset.to_vec(),
    })
}
