//! Strategy `okdt(λ)` (`spec/clustering.md`, paper §2.3): the `obt` subdivision, keeping for
//! every non-empty cell only the bounding box of its contents (surfaces and child clusters),
//! dropping empty cells and collapsing chains of cells that hold no surface and a single child
//! cell. The result is a hierarchy of tight bounding volumes with at most 2 child clusters per
//! node. Both passes are fused: a node is emitted after its children, with its tight box, or
//! replaced by its only child.

use super::obt::{build_binary, Binary};
use super::{BuildTree, ClusterConfig, Prims};

/// Build the tree (`okdt-p` builds on this).
pub fn build(prims: &Prims, cfg: &ClusterConfig) -> BuildTree {
    let p = Binary {
        tight: true,
        ..Binary::obt(cfg, cfg.lambda)
    };
    build_binary(prims, p).0
}
