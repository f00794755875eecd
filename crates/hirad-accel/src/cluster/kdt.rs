//! Strategy `kdt` (Sillion 1995; `spec/clustering.md`): the k-d tree of the scene's bounding
//! cube, every surface attached to the deepest cell that fully contains its bounding box, cells
//! split at the middle of their longest axis while they hold more than `kdt_leaf_size`
//! surfaces, empty cells not stored. It is the λ = 0 case of [`obt`](super::obt), whose module
//! documents the construction; a node's box is its cell.

use super::obt::{build_binary, Binary};
use super::{BuildTree, ClusterConfig, Prims};
use hirad_core::geom::Aabb;

/// Build the tree.
pub fn build(prims: &Prims, cfg: &ClusterConfig) -> BuildTree {
    build_with_cells(prims, cfg).0
}

/// Build the tree and return the cell of every node (equal to its box).
pub fn build_with_cells(prims: &Prims, cfg: &ClusterConfig) -> (BuildTree, Vec<Aabb>) {
    build_binary(prims, Binary::obt(cfg, 0.0))
}
