//! The cluster hierarchy (`spec/clustering.md`): one [`ClusterTree`] type for every strategy.
//!
//! A tree is a flat arena of [`ClusterNode`]s addressed by `u32` ids, root first (id 0). The
//! children of a node are contiguous (`first_child .. first_child + num_children`), and the
//! surfaces attached directly to a node are a contiguous slice of [`ClusterTree::surfaces`].
//! Strategies build a loose [`BuildTree`] (one file per strategy in this module) which
//! [`ClusterTree::from_build`] lays out breadth-first.
//!
//! The top-down strategies (`kdt`, `obt`, `okdt`, `tf-oct`, `sah`) partition an array of
//! per-surface records in place and build subtrees of more than a few thousand surfaces on
//! separate rayon tasks; node ids are assigned as a sequential run would, so a tree never
//! depends on the thread count. [`stats`] computes the statistics `hirad clusters` reports,
//! [`dump`] writes the boxes as a wireframe.

use glam::Vec3;
use hirad_core::geom::Aabb;
use hirad_core::{choice, Error, Result};
use hirad_scene::Scene;
use serde::{Deserialize, Serialize};

/// Sentinel for "no node".
pub const NONE: u32 = u32::MAX;

/// A clustering strategy (`--clustering NAME`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize, PartialOrd, Ord)]
#[serde(rename_all = "kebab-case")]
pub enum Strategy {
    /// Sillion 1995 k-d tree: surfaces at the deepest cell containing them.
    Kdt,
    /// Overlapping binary tree with parameter λ.
    Obt,
    /// OBT, then bounding volumes of non-empty cells, chains collapsed.
    Okdt,
    /// OKDT with over-full clusters re-clustered by PROXI.
    OkdtP,
    /// Christensen et al. 1997 octree of bounding volumes.
    TfOct,
    /// Sillion & Drettakis 1995 bottom-up proximity clustering.
    Proxi,
    /// Binned SAH BVH, the ray-tracing baseline.
    Sah,
    /// Object reconstruction for polygon soups (issue 23): welded components, proximity above.
    Objr,
}

choice!(Strategy, "clustering strategy",
    Kdt => "kdt",
    Obt => "obt",
    Okdt => "okdt",
    OkdtP => "okdt-p",
    TfOct => "tf-oct",
    Proxi => "proxi",
    Sah => "sah",
    Objr => "objr",
);

impl Strategy {
    /// Every strategy, in the order tables list them.
    pub const ALL: [Strategy; 8] = [
        Strategy::Kdt,
        Strategy::Obt,
        Strategy::Okdt,
        Strategy::OkdtP,
        Strategy::TfOct,
        Strategy::Proxi,
        Strategy::Sah,
        Strategy::Objr,
    ];

    /// One of the paper's six strategies (not the ray-tracing baseline nor hirad's own).
    pub fn is_paper(self) -> bool {
        !matches!(self, Strategy::Sah | Strategy::Objr)
    }

    /// Parse a comma-separated list, `all` meaning every strategy.
    pub fn parse_list(s: &str) -> Result<Vec<Strategy>> {
        if s.eq_ignore_ascii_case("all") {
            return Ok(Strategy::ALL.to_vec());
        }
        s.split(',')
            .map(|x| {
                Strategy::parse(x.trim()).map_err(|e| match e {
                    Error::Config(m) => Error::Config(format!("{m}, a list of them, or all")),
                    e => e,
                })
            })
            .collect()
    }
}

impl std::fmt::Display for Strategy {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// Parameters of the strategies, with the spec's defaults.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct ClusterConfig {
    /// OBT/OKDT/OKDT-P λ (default 0.25).
    pub lambda: f32,
    /// KDT/OBT/OKDT: split a cell only while it holds more than this many surfaces (default 4).
    pub kdt_leaf_size: usize,
    /// TF-OCT: recurse while a node holds more than this many surfaces (default 3).
    pub octree_leaf_size: usize,
    /// OKDT-P: clusters with more surfaces attached directly are re-clustered (default 12).
    pub max_surfaces: usize,
    /// PROXI: maximum children per cluster (default 8).
    pub max_children: usize,
    /// SAH: maximum surfaces per leaf (default 4).
    pub sah_leaf_size: usize,
    /// SAH: maximum children per node (default 8, a wide BVH as ray tracers use — Embree's
    /// BVH8; 2 gives the binary tree of the binned build).
    pub sah_width: usize,
    /// Maximum depth of top-down builders (a safety net for coincident geometry).
    pub max_depth: usize,
}

impl Default for ClusterConfig {
    fn default() -> Self {
        Self {
            lambda: 0.25,
            kdt_leaf_size: 4,
            octree_leaf_size: 3,
            max_surfaces: 12,
            max_children: 8,
            sah_leaf_size: 4,
            sah_width: 8,
            max_depth: 64,
        }
    }
}

/// Per-surface data the builders work from (bounding box, centroid, size = longest box edge).
#[derive(Clone, Debug)]
pub struct Prims {
    /// Bounding box per surface.
    pub bbox: Vec<Aabb>,
    /// Centroid (mean of the three vertices) per surface.
    pub centroid: Vec<Vec3>,
    /// Area per surface (scene units²).
    pub area: Vec<f32>,
    /// Object (group) id per surface, from the file.
    pub object: Vec<u32>,
    /// Vertex positions indexed by `triangles` (`objr` welds them); empty when unknown.
    pub positions: Vec<Vec3>,
    /// Vertex ids of each surface into `positions`; empty when unknown.
    pub triangles: Vec<[u32; 3]>,
    /// Material id per surface; empty when unknown (one material).
    pub material: Vec<u32>,
}

impl Prims {
    /// Compute the builder inputs of a scene.
    pub fn from_scene(scene: &Scene) -> Prims {
        let n = scene.num_triangles();
        let bbox: Vec<Aabb> = (0..n).map(|i| scene.tri_bbox(i)).collect();
        let centroid = (0..n).map(|i| scene.tri_centroid(i)).collect();
        Prims {
            bbox,
            centroid,
            area: scene.areas.clone(),
            object: scene.tri_object.clone(),
            positions: scene.positions.clone(),
            triangles: scene.triangles.clone(),
            material: scene.tri_material.clone(),
        }
    }

    /// Builder inputs of a list of triangles (zero-area ones included), object 0 for all; for
    /// tests and generated data that bypass [`Scene`].
    pub fn from_triangles(tris: &[[Vec3; 3]]) -> Prims {
        Prims {
            bbox: tris
                .iter()
                .map(|&[a, b, c]| Aabb::new(a.min(b).min(c), a.max(b).max(c)))
                .collect(),
            centroid: tris.iter().map(|&[a, b, c]| (a + b + c) / 3.0).collect(),
            area: tris
                .iter()
                .map(|&[a, b, c]| hirad_core::geom::triangle_area(a, b, c))
                .collect(),
            object: vec![0; tris.len()],
            positions: tris.iter().flatten().copied().collect(),
            triangles: (0..tris.len() as u32)
                .map(|i| [3 * i, 3 * i + 1, 3 * i + 2])
                .collect(),
            material: vec![0; tris.len()],
        }
    }

    /// Number of surfaces.
    pub fn len(&self) -> usize {
        self.bbox.len()
    }

    /// True when there are no surfaces.
    pub fn is_empty(&self) -> bool {
        self.bbox.is_empty()
    }

    /// `size(surface)`: longest edge of its bounding box.
    #[inline]
    pub fn size(&self, i: u32) -> f32 {
        self.bbox[i as usize].size()
    }
}

/// A node of a tree under construction.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct BuildNode {
    /// The node's box.
    pub bbox: Aabb,
    /// Ids of the child nodes in [`BuildTree::nodes`].
    pub children: Vec<u32>,
    /// Surfaces attached directly to the node.
    pub surfaces: Vec<u32>,
}

/// A tree under construction: nodes in any order, `root` names the root.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct BuildTree {
    /// The nodes, addressed by their index.
    pub nodes: Vec<BuildNode>,
    /// Id of the root node.
    pub root: u32,
    /// Remarks of the builder for the statistics (e.g. groups that could not be split).
    pub notes: Vec<String>,
}

impl BuildTree {
    /// Add a node, returning its id.
    pub fn push(&mut self, node: BuildNode) -> u32 {
        self.nodes.push(node);
        (self.nodes.len() - 1) as u32
    }
}

/// A node of a [`ClusterTree`].
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct ClusterNode {
    /// The cluster's box, as the strategy built it (it contains the node's surfaces and its
    /// children's boxes, up to a small f32 slack).
    pub bbox: Aabb,
    /// Id of the first child (children are contiguous); meaningless when `num_children == 0`.
    pub first_child: u32,
    /// Number of children.
    pub num_children: u32,
    /// Offset of the first attached surface in [`ClusterTree::surfaces`].
    pub first_surface: u32,
    /// Number of surfaces attached directly to the node.
    pub num_surfaces: u32,
    /// Parent id, [`NONE`] for the root.
    pub parent: u32,
    /// Depth (root = 0).
    pub depth: u32,
}

impl ClusterNode {
    /// Ids of the children.
    #[inline]
    pub fn children(&self) -> std::ops::Range<u32> {
        self.first_child..self.first_child + self.num_children
    }

    /// True when the node has no child clusters.
    #[inline]
    pub fn is_leaf(&self) -> bool {
        self.num_children == 0
    }
}

/// The cluster hierarchy shared by the solver and the ray caster.
#[derive(Clone, Debug, PartialEq)]
pub struct ClusterTree {
    /// The strategy that built the tree.
    pub strategy: Strategy,
    /// The parameters it was built with.
    pub config: ClusterConfig,
    /// Nodes, root first, children contiguous, breadth-first order.
    pub nodes: Vec<ClusterNode>,
    /// Surface ids grouped by node (`first_surface .. first_surface + num_surfaces`).
    pub surfaces: Vec<u32>,
    /// For each surface, the node it is attached to.
    pub surface_node: Vec<u32>,
    /// Builder remarks.
    pub notes: Vec<String>,
}

impl ClusterTree {
    /// Build the tree of `strategy` for a scene.
    pub fn build(scene: &Scene, strategy: Strategy, config: &ClusterConfig) -> ClusterTree {
        let prims = Prims::from_scene(scene);
        Self::build_prims(&prims, strategy, config)
    }

    /// Build from precomputed builder inputs.
    pub fn build_prims(prims: &Prims, strategy: Strategy, config: &ClusterConfig) -> ClusterTree {
        let build = match strategy {
            Strategy::Kdt => kdt::build(prims, config),
            Strategy::Obt => obt::build(prims, config),
            Strategy::Okdt => okdt::build(prims, config),
            Strategy::OkdtP => okdt_p::build(prims, config),
            Strategy::TfOct => tf_oct::build(prims, config),
            Strategy::Proxi => proxi::build(prims, config),
            Strategy::Sah => sah::build(prims, config),
            Strategy::Objr => objr::build(prims, config),
        };
        let tree = ClusterTree::from_build(build, prims.len(), strategy, config.clone());
        debug_assert!(tree.validate(prims).is_ok(), "{:?}", tree.validate(prims));
        tree
    }

    /// Lay a [`BuildTree`] out breadth-first, root first, children contiguous.
    pub fn from_build(
        build: BuildTree,
        num_surfaces: usize,
        strategy: Strategy,
        config: ClusterConfig,
    ) -> ClusterTree {
        let mut nodes = Vec::with_capacity(build.nodes.len());
        let mut surfaces = Vec::with_capacity(num_surfaces);
        let mut surface_node = vec![NONE; num_surfaces];
        // Queue of (build id, parent id, depth); index in the queue = final id.
        let mut queue: Vec<(u32, u32, u32)> = vec![(build.root, NONE, 0)];
        let mut head = 0;
        while head < queue.len() {
            let (bid, parent, depth) = queue[head];
            let b = &build.nodes[bid as usize];
            let id = head as u32;
            head += 1;
            let first_child = queue.len() as u32;
            for &c in &b.children {
                queue.push((c, id, depth + 1));
            }
            let first_surface = surfaces.len() as u32;
            for &s in &b.surfaces {
                surfaces.push(s);
                if let Some(slot) = surface_node.get_mut(s as usize) {
                    *slot = id;
                }
            }
            nodes.push(ClusterNode {
                bbox: b.bbox,
                first_child,
                num_children: b.children.len() as u32,
                first_surface,
                num_surfaces: b.surfaces.len() as u32,
                parent,
                depth,
            });
        }
        ClusterTree {
            strategy,
            config,
            nodes,
            surfaces,
            surface_node,
            notes: build.notes,
        }
    }

    /// The root node.
    pub fn root(&self) -> &ClusterNode {
        &self.nodes[0]
    }

    /// Surfaces attached directly to node `id`.
    #[inline]
    pub fn node_surfaces(&self, id: u32) -> &[u32] {
        let n = &self.nodes[id as usize];
        &self.surfaces[n.first_surface as usize..(n.first_surface + n.num_surfaces) as usize]
    }

    /// Calls `f` on the surfaces of every node whose box meets the box `lo..hi` (a superset
    /// of the surfaces whose own boxes meet it) until `f` returns true; true when it did.
    pub fn any_surface_near(&self, lo: Vec3, hi: Vec3, mut f: impl FnMut(u32) -> bool) -> bool {
        let mut stack = vec![0u32];
        while let Some(node) = stack.pop() {
            let nd = &self.nodes[node as usize];
            if nd.bbox.max.cmplt(lo).any() || nd.bbox.min.cmpgt(hi).any() {
                continue;
            }
            if self.node_surfaces(node).iter().any(|&j| f(j)) {
                return true;
            }
            stack.extend(nd.children());
        }
        false
    }

    /// Bytes used by the tree's arrays.
    pub fn memory_bytes(&self) -> usize {
        self.nodes.len() * std::mem::size_of::<ClusterNode>()
            + (self.surfaces.len() + self.surface_node.len()) * std::mem::size_of::<u32>()
    }

    /// Check the invariants of `clustering.md`: every surface attached exactly once, every box
    /// contains its contents (with f32 slack), parent/child links consistent, no empty leaf.
    pub fn validate(&self, prims: &Prims) -> std::result::Result<(), String> {
        let n = prims.len();
        if self.nodes.is_empty() {
            return Err("tree has no nodes".into());
        }
        if self.surfaces.len() != n || self.surface_node.len() != n {
            return Err(format!(
                "{} surfaces attached, scene has {n}",
                self.surfaces.len()
            ));
        }
        let mut seen = vec![false; n];
        for (id, node) in self.nodes.iter().enumerate() {
            let id = id as u32;
            if id == 0 && node.parent != NONE {
                return Err("root has a parent".into());
            }
            if node.num_children == 0 && node.num_surfaces == 0 && n > 0 {
                return Err(format!("node {id} is empty"));
            }
            let end = node.first_surface as usize + node.num_surfaces as usize;
            if end > self.surfaces.len() {
                return Err(format!("node {id} surface range out of bounds"));
            }
            for &s in self.node_surfaces(id) {
                let si = s as usize;
                if si >= n {
                    return Err(format!("node {id} holds unknown surface {s}"));
                }
                if seen[si] {
                    return Err(format!("surface {s} attached twice"));
                }
                seen[si] = true;
                if self.surface_node[si] != id {
                    return Err(format!("surface_node[{s}] != {id}"));
                }
                if !node.bbox.contains_box(&prims.bbox[si], 1e-5) {
                    return Err(format!(
                        "node {id} box {:?} does not contain surface {s} {:?}",
                        node.bbox, prims.bbox[si]
                    ));
                }
            }
            for c in node.children() {
                let Some(child) = self.nodes.get(c as usize) else {
                    return Err(format!("node {id} child {c} out of bounds"));
                };
                if c <= id || child.parent != id {
                    return Err(format!("node {id} child {c} has parent {}", child.parent));
                }
                if child.depth != node.depth + 1 {
                    return Err(format!("node {c} depth inconsistent"));
                }
                if !node.bbox.contains_box(&child.bbox, 1e-5) {
                    return Err(format!("node {id} box does not contain child {c}"));
                }
            }
        }
        if let Some(s) = seen.iter().position(|&x| !x) {
            return Err(format!("surface {s} is not attached"));
        }
        Ok(())
    }
}

pub mod dump;
pub mod kdt;
mod knn;
pub mod objr;
pub mod obt;
pub mod okdt;
pub mod okdt_p;
pub mod proxi;
pub mod sah;
pub mod stats;
pub mod tf_oct;
mod topdown;

pub use stats::ClusterStats;

/// A six-triangle scene whose trees and statistics are worked out by hand in the unit tests of
/// the strategies and of [`stats`]. Bounding box `[0, 8]³`; s0 spans it, s4 = `[3, 5]×[0, 1]×0`
/// crosses x = 4, s1, s2 lie in `[0, 2]³`, s3, s5 in `[5, 7]³`.
#[cfg(test)]
pub(crate) fn hand_scene() -> Prims {
    let v = Vec3::new;
    Prims::from_triangles(&[
        [v(0., 0., 0.), v(8., 0., 0.), v(0., 8., 8.)],
        [v(0., 0., 0.), v(1., 0., 0.), v(0., 1., 0.)],
        [v(1., 1., 1.), v(2., 1., 1.), v(1., 2., 1.)],
        [v(5., 5., 5.), v(6., 5., 5.), v(5., 6., 5.)],
        [v(3., 0., 0.), v(5., 0., 0.), v(3., 1., 0.)],
        [v(6., 6., 6.), v(7., 6., 6.), v(6., 7., 7.)],
    ])
}

#[cfg(test)]
mod tests {
    use super::*;

    fn b(min: [f32; 3], max: [f32; 3]) -> Aabb {
        Aabb::new(Vec3::from(min), Vec3::from(max))
    }

    /// (box, sorted surfaces) of every node, breadth-first.
    fn shape(t: &ClusterTree) -> Vec<(Aabb, Vec<u32>, u32)> {
        (0..t.nodes.len() as u32)
            .map(|i| {
                let mut s = t.node_surfaces(i).to_vec();
                s.sort_unstable();
                (
                    t.nodes[i as usize].bbox,
                    s,
                    t.nodes[i as usize].num_children,
                )
            })
            .collect()
    }

    #[test]
    fn hand_scene_trees() {
        let p = hand_scene();
        let cfg = ClusterConfig::default();
        let kdt = ClusterTree::build_prims(&p, Strategy::Kdt, &cfg);
        assert_eq!(
            shape(&kdt),
            vec![
                (b([0., 0., 0.], [8., 8., 8.]), vec![0, 4], 2),
                (b([0., 0., 0.], [4., 8., 8.]), vec![1, 2], 0),
                (b([4., 0., 0.], [8., 8., 8.]), vec![3, 5], 0),
            ]
        );
        // λ = 0.5: s4 (size 2, centroid x = 11/3) is pushed left since 2 ≤ 0.5·8/2.
        let half = ClusterConfig {
            lambda: 0.5,
            ..Default::default()
        };
        let obt = ClusterTree::build_prims(&p, Strategy::Obt, &half);
        assert_eq!(
            shape(&obt),
            vec![
                (b([0., 0., 0.], [8., 8., 8.]), vec![0], 2),
                (b([0., 0., 0.], [5., 8., 8.]), vec![1, 2, 4], 0),
                (b([4., 0., 0.], [8., 8., 8.]), vec![3, 5], 0),
            ]
        );
        // Just below the threshold s4 stays: λ = 0.49 gives kdt.
        let below = ClusterConfig {
            lambda: 0.49,
            ..Default::default()
        };
        let obt49 = ClusterTree::build_prims(&p, Strategy::Obt, &below);
        assert_eq!(shape(&obt49), shape(&kdt));
        let okdt = ClusterTree::build_prims(&p, Strategy::Okdt, &half);
        assert_eq!(
            shape(&okdt),
            vec![
                (b([0., 0., 0.], [8., 8., 8.]), vec![0], 2),
                (b([0., 0., 0.], [5., 2., 1.]), vec![1, 2, 4], 0),
                (b([5., 5., 5.], [7., 7., 7.]), vec![3, 5], 0),
            ]
        );
        // tf-oct: octant size 4; s0 (size 8) stays, s1, s2, s4 go to the low octant, s3, s5
        // to the high one.
        let oct = ClusterTree::build_prims(&p, Strategy::TfOct, &cfg);
        assert_eq!(
            shape(&oct),
            vec![
                (b([0., 0., 0.], [8., 8., 8.]), vec![0], 2),
                (b([0., 0., 0.], [5., 2., 1.]), vec![1, 2, 4], 0),
                (b([5., 5., 5.], [7., 7., 7.]), vec![3, 5], 0),
            ]
        );
        // sah: 6 > 4 surfaces, split into two leaves, surfaces only at leaves.
        let sah = ClusterTree::build_prims(&p, Strategy::Sah, &cfg);
        assert_eq!(sah.nodes.len(), 3);
        assert_eq!(sah.nodes[0].num_surfaces, 0);
        assert_eq!(sah.nodes[0].bbox, b([0., 0., 0.], [8., 8., 8.]));
        for t in [&kdt, &obt, &okdt, &oct, &sah] {
            assert_eq!(t.validate(&p), Ok(()));
        }
    }

    #[test]
    fn okdt_collapses_chains() {
        // Two clumps far apart in one corner: obt has a chain of single-child cells above
        // them, okdt goes straight from the root box to the two clumps.
        let mut tris = Vec::new();
        for k in 0..5 {
            let o = Vec3::splat(0.01 * k as f32);
            tris.push([o, o + Vec3::X * 0.01, o + Vec3::Y * 0.01]);
            let q = Vec3::new(0.9, 0.0, 0.0) + o;
            tris.push([q, q + Vec3::X * 0.01, q + Vec3::Y * 0.01]);
        }
        tris.push([Vec3::ZERO, Vec3::splat(64.0), Vec3::new(64.0, 0.0, 0.0)]);
        let p = Prims::from_triangles(&tris);
        let cfg = ClusterConfig::default();
        let obt = ClusterTree::build_prims(&p, Strategy::Obt, &cfg);
        let okdt = ClusterTree::build_prims(&p, Strategy::Okdt, &cfg);
        assert!(obt
            .nodes
            .iter()
            .any(|n| n.num_surfaces == 0 && n.num_children == 1));
        assert!(okdt
            .nodes
            .iter()
            .all(|n| n.num_surfaces > 0 || n.num_children == 2));
        assert_eq!(okdt.node_surfaces(0), &[10]);
        assert_eq!(okdt.nodes[0].num_children, 1);
        assert!(okdt.nodes.len() < obt.nodes.len());
        assert_eq!(okdt.validate(&p), Ok(()));
    }
}
