//! Statistics of a cluster tree (`spec/clustering.md`, paper §4.4 and Fig. 6), reported by
//! `hirad clusters`.

use super::{ClusterTree, Prims};
use serde::{Deserialize, Serialize};

/// Statistics of one [`ClusterTree`]. All averages are plain means in f64.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ClusterStats {
    /// Strategy name.
    pub strategy: String,
    /// Number of surfaces of the scene.
    pub surfaces: usize,
    /// Number of clusters (nodes of the tree).
    pub clusters: usize,
    /// Number of clusters without child clusters.
    pub leaves: usize,
    /// Largest node depth (root = 0).
    pub depth_max: u32,
    /// Mean over surfaces of the depth of the node each surface is attached to.
    pub depth_mean: f64,
    /// Mean number of surfaces attached directly, over the clusters that have at least one
    /// surface attached (clusters without surfaces would only dilute the figure).
    pub surfaces_per_cluster_avg: f64,
    /// Largest number of surfaces attached directly to one cluster.
    pub surfaces_per_cluster_max: u32,
    /// Mean number of child clusters, over the clusters that have at least one child cluster
    /// (averaged over every cluster it would be (clusters − 1)/clusters ≈ 1 for any tree).
    pub children_per_cluster_avg: f64,
    /// Largest number of child clusters of one cluster.
    pub children_per_cluster_max: u32,
    /// Mean of (child clusters + surfaces) over clusters with at least one child cluster.
    pub branching_factor: f64,
    /// Σ over unordered pairs of sibling clusters of vol(box_i ∩ box_j) / vol(parent box).
    /// Pairs whose parent box has zero volume (flat scenes) contribute 0.
    pub overlap: f64,
    /// Σ over clusters of vol(box) / (Σ surface areas × mean surface size): the volume the
    /// boxes enclose relative to a volume scale of the geometry, to compare tightness. 0 when
    /// the denominator is 0.
    pub empty_space_ratio: f64,
    /// Bytes of the tree's arrays ([`ClusterTree::memory_bytes`]).
    pub tree_bytes: usize,
    /// `tree_bytes` per surface.
    pub bytes_per_surface: f64,
    /// Median wall time of a single-threaded build, seconds (filled in by the caller).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub build_seconds_single: Option<f64>,
    /// Median wall time of a parallel build, seconds (filled in by the caller).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub build_seconds_parallel: Option<f64>,
    /// Remarks of the builder.
    pub notes: Vec<String>,
}

impl ClusterStats {
    /// Compute the statistics of `tree` built over `prims`.
    pub fn compute(tree: &ClusterTree, prims: &Prims) -> ClusterStats {
        let nodes = &tree.nodes;
        let mut leaves = 0usize;
        let mut depth_max = 0u32;
        let (mut with_surf, mut with_child) = (0usize, 0usize);
        let (mut sum_surf, mut sum_child) = (0u64, 0u64);
        let (mut max_surf, mut max_child) = (0u32, 0u32);
        let (mut inner, mut sum_branch) = (0usize, 0u64);
        let mut overlap = 0f64;
        let mut volume = 0f64;
        let mut depth_sum = 0f64;
        let mut pairs: Vec<(f32, u32)> = Vec::new();
        for n in nodes {
            depth_max = depth_max.max(n.depth);
            volume += n.bbox.volume_f64();
            depth_sum += n.depth as f64 * n.num_surfaces as f64;
            if n.num_children == 0 {
                leaves += 1;
            } else {
                inner += 1;
                sum_branch += (n.num_children + n.num_surfaces) as u64;
                overlap += sibling_overlap(tree, n, &mut pairs);
            }
            if n.num_surfaces > 0 {
                with_surf += 1;
                sum_surf += n.num_surfaces as u64;
            }
            if n.num_children > 0 {
                with_child += 1;
                sum_child += n.num_children as u64;
            }
            max_surf = max_surf.max(n.num_surfaces);
            max_child = max_child.max(n.num_children);
        }
        let ns = prims.len();
        let area: f64 = prims.area.iter().map(|&a| a as f64).sum();
        let mean_size = if ns > 0 {
            prims.bbox.iter().map(|b| b.size() as f64).sum::<f64>() / ns as f64
        } else {
            0.0
        };
        let denom = area * mean_size;
        let mean = |s: f64, k: usize| if k > 0 { s / k as f64 } else { 0.0 };
        let bytes = tree.memory_bytes();
        ClusterStats {
            strategy: tree.strategy.name().to_string(),
            surfaces: ns,
            clusters: nodes.len(),
            leaves,
            depth_max,
            depth_mean: mean(depth_sum, ns),
            surfaces_per_cluster_avg: mean(sum_surf as f64, with_surf),
            surfaces_per_cluster_max: max_surf,
            children_per_cluster_avg: mean(sum_child as f64, with_child),
            children_per_cluster_max: max_child,
            branching_factor: mean(sum_branch as f64, inner),
            overlap,
            empty_space_ratio: if denom > 0.0 { volume / denom } else { 0.0 },
            tree_bytes: bytes,
            bytes_per_surface: mean(bytes as f64, ns),
            build_seconds_single: None,
            build_seconds_parallel: None,
            notes: tree.notes.clone(),
        }
    }
}

/// Σ over pairs of children of `n` of vol(intersection) / vol(n), by a sweep along x so that
/// nodes with many children only pay for the pairs that overlap in x.
fn sibling_overlap(tree: &ClusterTree, n: &super::ClusterNode, order: &mut Vec<(f32, u32)>) -> f64 {
    let pv = n.bbox.volume_f64();
    if pv.is_nan() || pv <= 0.0 || n.num_children < 2 {
        return 0.0;
    }
    order.clear();
    order.extend(n.children().map(|c| (tree.nodes[c as usize].bbox.min.x, c)));
    order.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
    let mut sum = 0f64;
    for i in 0..order.len() {
        let bi = tree.nodes[order[i].1 as usize].bbox;
        for &(minx, j) in &order[i + 1..] {
            if minx > bi.max.x {
                break;
            }
            let bj = tree.nodes[j as usize].bbox;
            let x = bi.intersection(&bj);
            if !x.is_empty() {
                sum += x.volume_f64();
            }
        }
    }
    sum / pv
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cluster::{hand_scene, ClusterConfig, ClusterNode, Strategy};
    use hirad_core::geom::Aabb;

    /// Σ areas × mean size of the hand scene: areas 32√2, ½, ½, ½, 1, √2/2; sizes 8, 1, 1, 1,
    /// 2, 1.
    fn denom() -> f64 {
        (32.5 * 2f64.sqrt() + 2.5) * (14.0 / 6.0)
    }

    #[test]
    fn kdt_of_hand_scene() {
        let p = hand_scene();
        let t = ClusterTree::build_prims(&p, Strategy::Kdt, &ClusterConfig::default());
        let s = ClusterStats::compute(&t, &p);
        assert_eq!(s.strategy, "kdt");
        assert_eq!(
            (s.surfaces, s.clusters, s.leaves, s.depth_max),
            (6, 3, 2, 1)
        );
        // Depths of s0..s5: 0, 1, 1, 1, 0, 1.
        assert!((s.depth_mean - 4.0 / 6.0).abs() < 1e-12);
        assert_eq!(s.surfaces_per_cluster_avg, 2.0);
        assert_eq!(s.surfaces_per_cluster_max, 2);
        assert_eq!(s.children_per_cluster_avg, 2.0);
        assert_eq!(s.children_per_cluster_max, 2);
        // Root: 2 children + 2 surfaces.
        assert_eq!(s.branching_factor, 4.0);
        // The two halves only share the plane x = 4.
        assert_eq!(s.overlap, 0.0);
        // Volumes 512 + 256 + 256.
        assert!((s.empty_space_ratio - 1024.0 / denom()).abs() < 1e-5);
        let bytes = 3 * std::mem::size_of::<ClusterNode>() + 12 * 4;
        assert_eq!(s.tree_bytes, bytes);
        assert_eq!(s.bytes_per_surface, bytes as f64 / 6.0);
        assert!(s.notes.is_empty());
    }

    #[test]
    fn obt_of_hand_scene() {
        let p = hand_scene();
        let cfg = ClusterConfig {
            lambda: 0.5,
            ..Default::default()
        };
        let t = ClusterTree::build_prims(&p, Strategy::Obt, &cfg);
        let s = ClusterStats::compute(&t, &p);
        // Root {s0}; left [0,5]×[0,8]² {s1, s2, s4}; right [4,8]×[0,8]² {s3, s5}.
        assert!((s.depth_mean - 5.0 / 6.0).abs() < 1e-12);
        assert_eq!(s.surfaces_per_cluster_max, 3);
        assert_eq!(s.branching_factor, 3.0);
        // Siblings share [4,5]×[0,8]², 64 of the root's 512.
        assert!((s.overlap - 0.125).abs() < 1e-12);
        assert!((s.empty_space_ratio - (512.0 + 320.0 + 256.0) / denom()).abs() < 1e-5);
        let json = serde_json::to_string(&s).unwrap();
        let back: ClusterStats = serde_json::from_str(&json).unwrap();
        assert_eq!(back, s);
    }

    #[test]
    fn overlap_of_many_children() {
        // Root [0,10]³ with 4 children: three unit-spaced slabs overlapping their neighbour by
        // half, one disjoint cube; pairs (0,1) and (1,2) overlap by 0.5·10·10 each.
        let p = Prims::from_triangles(&[[glam::Vec3::ZERO, glam::Vec3::X, glam::Vec3::Y]; 5]);
        let slab = |x0: f32| {
            Aabb::new(
                glam::Vec3::new(x0, 0.0, 0.0),
                glam::Vec3::new(x0 + 1.0, 10.0, 10.0),
            )
        };
        let mut bt = crate::cluster::BuildTree::default();
        let kids: Vec<u32> = [
            slab(0.0),
            slab(0.5),
            slab(1.0),
            Aabb::new(glam::Vec3::splat(5.0), glam::Vec3::splat(6.0)),
        ]
        .iter()
        .enumerate()
        .map(|(i, b)| {
            bt.push(crate::cluster::BuildNode {
                bbox: *b,
                children: vec![],
                surfaces: vec![i as u32 + 1],
            })
        })
        .collect();
        bt.root = bt.push(crate::cluster::BuildNode {
            bbox: Aabb::new(glam::Vec3::ZERO, glam::Vec3::splat(10.0)),
            children: kids,
            surfaces: vec![0],
        });
        let t = ClusterTree::from_build(bt, 5, Strategy::Proxi, ClusterConfig::default());
        let s = ClusterStats::compute(&t, &p);
        assert!(
            (s.overlap - 2.0 * 50.0 / 1000.0).abs() < 1e-12,
            "{}",
            s.overlap
        );
        assert_eq!(s.branching_factor, 5.0);
        assert_eq!(s.children_per_cluster_max, 4);
        assert_eq!(s.children_per_cluster_avg, 4.0);
        assert_eq!(s.surfaces_per_cluster_avg, 1.0);
    }
}
