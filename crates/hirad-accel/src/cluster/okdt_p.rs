//! Strategy `okdt-p` (`spec/clustering.md`, paper §3.2): [`okdt`](super::okdt), then every
//! cluster with more than `max_surfaces` surfaces attached directly is re-clustered locally
//! with [`proxi`].
//!
//! Re-clustering a node `N` with surfaces `S` (`|S| > max_surfaces`): PROXI builds a subtree
//! over `S` alone, with at most `min(max_children, max(max_surfaces, 2))` members per cluster.
//! `N` keeps its box and its own child clusters; it takes over the PROXI root's content: the
//! root's child clusters are appended to `N`'s children and the root's surfaces (at most
//! `max_surfaces`) replace `S`. The PROXI root node itself is dropped, so no chain of
//! single-child nodes is created. Every PROXI cluster holds at most `max_surfaces` surfaces, so
//! afterwards no node holds more than `max_surfaces` surfaces, except when `max_surfaces < 2`
//! and a node must keep two surfaces (PROXI clusters have at least two members); such nodes are
//! counted in a note of the tree. Nodes are re-clustered in parallel, each independently, and
//! spliced in node order, so the tree does not depend on the thread count.

use super::{proxi, BuildNode, BuildTree, ClusterConfig, Prims};
use rayon::prelude::*;

/// Build the tree.
pub fn build(prims: &Prims, cfg: &ClusterConfig) -> BuildTree {
    let mut t = super::okdt::build(prims, cfg);
    recluster_overfull(prims, cfg, &mut t);
    t
}

/// Re-cluster with PROXI every node of `t` holding more than `cfg.max_surfaces` surfaces
/// directly (see the module docs). Returns the number of nodes re-clustered.
pub fn recluster_overfull(prims: &Prims, cfg: &ClusterConfig, t: &mut BuildTree) -> usize {
    let limit = cfg.max_surfaces;
    let overfull: Vec<u32> = (0..t.nodes.len() as u32)
        .filter(|&i| t.nodes[i as usize].surfaces.len() > limit)
        .collect();
    let local_cfg = ClusterConfig {
        max_children: cfg.max_children.min(cfg.max_surfaces.max(2)).max(2),
        ..cfg.clone()
    };
    let locals: Vec<BuildTree> = overfull
        .par_iter()
        .map(|&i| {
            let mut local = BuildTree::default();
            local.root =
                proxi::build_subset(prims, &t.nodes[i as usize].surfaces, &local_cfg, &mut local);
            local
        })
        .collect();
    let mut moved = 0usize;
    for (&i, mut local) in overfull.iter().zip(locals) {
        moved += t.nodes[i as usize].surfaces.len();
        // `build_subset` pushes its root last.
        debug_assert_eq!(local.root as usize, local.nodes.len() - 1);
        let root = local.nodes.pop().unwrap_or_default();
        let base = t.nodes.len() as u32;
        for mut n in local.nodes {
            for c in &mut n.children {
                *c += base;
            }
            t.nodes.push(n);
        }
        let node: &mut BuildNode = &mut t.nodes[i as usize];
        node.children
            .extend(root.children.iter().map(|&c| c + base));
        node.surfaces = root.surfaces;
    }
    if !overfull.is_empty() {
        t.notes.push(format!(
            "okdt-p: re-clustered {} clusters holding {} surfaces with proxi",
            overfull.len(),
            moved
        ));
    }
    let still = t.nodes.iter().filter(|n| n.surfaces.len() > limit).count();
    if still > 0 {
        t.notes.push(format!(
            "okdt-p: {still} clusters keep more than max_surfaces = {limit} surfaces (cannot be split further)"
        ));
    }
    overfull.len()
}
