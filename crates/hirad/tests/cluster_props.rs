//! Properties of the cluster strategies (`spec/clustering.md`): validity, determinism (also
//! across thread counts), `obt(0) == kdt`, `okdt` binary, the OBT size and overlap relations,
//! `kdt` against a naive reference, the tf-oct and sah rules, degenerate input, real scenes.

use glam::Vec3;
use hirad::cluster::{
    kdt, obt, okdt, tf_oct, BuildTree, ClusterConfig, ClusterStats, ClusterTree, Prims, Strategy,
};
use hirad::geom::Aabb;
use hirad::rng::SplitMix64;
use proptest::prelude::*;

/// Builder inputs of a triangle list, zero-area triangles included.
fn prims_of(tris: &[[Vec3; 3]]) -> Prims {
    Prims::from_triangles(tris)
}

/// A random triangle of one of several kinds: ordinary, tiny, huge, a point, a segment.
fn random_tri(g: &mut SplitMix64) -> [Vec3; 3] {
    let mut v = || Vec3::new(g.next_f32(), g.next_f32(), g.next_f32()) * 2.0 - 1.0;
    let c = v() * 10.0;
    let kind = (v().x * 5.0 + 5.0) as u32;
    let (d1, d2) = (v(), v());
    match kind {
        0 => [c, c, c],                         // a point
        1 => [c, c + d1, c + d1 * 2.0],         // a segment
        2 => [c, c + d1 * 1e-4, c + d2 * 1e-4], // tiny
        3 => [c, c + d1 * 30.0, c + d2 * 30.0], // huge
        _ => [c, c + d1 * 1.5, c + d2 * 1.5],   // ordinary
    }
}

/// A random scene: `n` triangles, some duplicated, optionally all flattened to z = 0.
fn random_scene(seed: u64, n: usize, coplanar: bool, dup: bool) -> Vec<[Vec3; 3]> {
    let mut g = SplitMix64::new(seed);
    let mut tris: Vec<[Vec3; 3]> = (0..n).map(|_| random_tri(&mut g)).collect();
    if dup {
        let k = tris.len() / 3;
        for i in 0..k {
            tris.push(tris[i * 2 % tris.len()]);
        }
    }
    if coplanar {
        for t in &mut tris {
            for p in t.iter_mut() {
                p.z = 0.0;
            }
        }
    }
    tris
}

/// Thin random triangles spread over a cube, for the larger tests.
fn soup(seed: u64, n: usize) -> Vec<[Vec3; 3]> {
    let mut g = SplitMix64::new(seed);
    let mut v = || Vec3::new(g.next_f32(), g.next_f32(), g.next_f32());
    (0..n)
        .map(|_| {
            let c = v() * 100.0;
            [c, c + (v() - 0.5) * 0.8, c + (v() - 0.5) * 0.8]
        })
        .collect()
}

fn cfg_lambda(lambda: f32) -> ClusterConfig {
    ClusterConfig {
        lambda,
        ..Default::default()
    }
}

/// Tree with the strategy field ignored (for `obt(0) == kdt`).
fn same_tree(a: &ClusterTree, b: &ClusterTree) -> bool {
    a.nodes == b.nodes && a.surfaces == b.surfaces && a.surface_node == b.surface_node
}

fn in_pool<T: Send>(threads: usize, f: impl FnOnce() -> T + Send) -> T {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap()
        .install(f)
}

/// Node depths of a build tree (root 0).
fn build_depths(t: &BuildTree) -> Vec<usize> {
    let mut d = vec![0usize; t.nodes.len()];
    let mut stack = vec![t.root];
    while let Some(i) = stack.pop() {
        for &c in &t.nodes[i as usize].children {
            d[c as usize] = d[i as usize] + 1;
            stack.push(c);
        }
    }
    d
}

/// Number of surfaces in the subtree of every node of a build tree.
fn subtree_counts(t: &BuildTree) -> Vec<usize> {
    fn rec(t: &BuildTree, i: u32, out: &mut [usize]) -> usize {
        let n = &t.nodes[i as usize];
        let mut s = n.surfaces.len();
        for &c in &n.children {
            s += rec(t, c, out);
        }
        out[i as usize] = s;
        s
    }
    let mut out = vec![0; t.nodes.len()];
    rec(t, t.root, &mut out);
    out
}

/// The split plane the builder uses for a cell (midpoint of the longest axis).
fn cell_plane(cell: &Aabb) -> (usize, f32, Aabb) {
    let a = cell.longest_axis();
    let p = 0.5 * (cell.min[a] + cell.max[a]);
    let mut half = *cell;
    half.max[a] = p;
    (a, p, half)
}

/// Check the OBT relations of `spec/clustering.md` on a tree built with λ > 0.
fn check_obt_relations(prims: &Prims, cfg: &ClusterConfig) -> Result<(), TestCaseError> {
    let lambda = cfg.lambda;
    let (t, cells) = obt::build_with_cells(prims, cfg);
    let depth = build_depths(&t);
    let count = subtree_counts(&t);
    for (i, n) in t.nodes.iter().enumerate() {
        let cell = cells[i];
        let (a, p, half) = cell_plane(&cell);
        let was_split = count[i] > cfg.kdt_leaf_size
            && depth[i] < cfg.max_depth
            && p > cell.min[a]
            && p < cell.max[a];
        // The node box is the cell grown by what lies below.
        prop_assert!(
            n.bbox.contains_box(&cell, 0.0),
            "node {i} box misses its cell"
        );
        if !was_split {
            continue;
        }
        let d = half.size();
        let eps = 1e-5 * cell.max.abs().max(cell.min.abs()).max_element().max(1.0);
        // Size relation: a surface attached to a split cell is larger than λ·d/2, i.e. the
        // halves of its cell are smaller than x = 2S/λ.
        for &s in &n.surfaces {
            let size = prims.size(s);
            let x = 2.0 * size / lambda;
            prop_assert!(
                d <= x * (1.0 + 1e-5) + eps,
                "surface {s}: half {d} > 2S/λ = {x}"
            );
            prop_assert!(cell.size() <= 2.0 * x * (1.0 + 1e-5) + eps);
            if cell
                .extent()
                .cmpeq(Vec3::splat(cell.size()))
                .bitmask()
                .count_ones()
                > 1
            {
                prop_assert!(cell.size() <= x * (1.0 + 1e-5) + eps);
            }
        }
        // Overlap relation between the two children (cells of size d).
        let kids: Vec<u32> = n.children.clone();
        for &c in &kids {
            let cb = t.nodes[c as usize].bbox;
            let ccell = cells[c as usize];
            if ccell.max[a] <= p {
                prop_assert!(
                    cb.max[a] <= p + lambda * d * 0.5 + eps,
                    "left child grows too far"
                );
            } else {
                prop_assert!(
                    cb.min[a] >= p - lambda * d * 0.5 - eps,
                    "right child grows too far"
                );
            }
        }
        if kids.len() == 2 {
            let (b0, b1) = (
                t.nodes[kids[0] as usize].bbox,
                t.nodes[kids[1] as usize].bbox,
            );
            let o = b0.max[a].min(b1.max[a]) - b0.min[a].max(b1.min[a]);
            prop_assert!(o <= 8.0 / 3.0 * lambda * d + eps, "overlap {o} > (8/3)λd");
        }
    }
    Ok(())
}

/// The kdt of `spec/clustering.md` written the obvious way: recursive cell subdivision, a
/// surface goes to the first child cell that fully contains its box.
fn naive_kdt(prims: &Prims, cfg: &ClusterConfig) -> Vec<(Aabb, Vec<u32>, usize)> {
    fn rec(
        prims: &Prims,
        cfg: &ClusterConfig,
        cell: Aabb,
        ids: Vec<u32>,
        depth: usize,
        out: &mut Vec<(Aabb, Vec<u32>, usize)>,
    ) {
        if ids.is_empty() {
            return;
        }
        let (a, p, left) = cell_plane(&cell);
        if ids.len() <= cfg.kdt_leaf_size
            || depth >= cfg.max_depth
            || !(p > cell.min[a] && p < cell.max[a])
        {
            out.push((cell, ids, depth));
            return;
        }
        let mut right = cell;
        right.min[a] = p;
        let inside = |c: &Aabb, b: &Aabb| b.min.cmpge(c.min).all() && b.max.cmple(c.max).all();
        let (mut here, mut l, mut r) = (vec![], vec![], vec![]);
        for s in ids {
            let b = prims.bbox[s as usize];
            if inside(&left, &b) {
                l.push(s);
            } else if inside(&right, &b) {
                r.push(s);
            } else {
                here.push(s);
            }
        }
        here.sort_unstable();
        out.push((cell, here, depth));
        rec(prims, cfg, left, l, depth + 1, out);
        rec(prims, cfg, right, r, depth + 1, out);
    }
    let mut out = Vec::new();
    let root = obt::root_cube(prims);
    rec(
        prims,
        cfg,
        root,
        (0..prims.len() as u32).collect(),
        0,
        &mut out,
    );
    out.sort_by(|x, y| x.1.cmp(&y.1).then(x.2.cmp(&y.2)));
    out
}

/// The (cell, sorted surfaces, depth) of every node of a kdt build tree, sorted like
/// [`naive_kdt`].
fn kdt_cells(t: &BuildTree, cells: &[Aabb]) -> Vec<(Aabb, Vec<u32>, usize)> {
    let depth = build_depths(t);
    let mut out: Vec<_> = t
        .nodes
        .iter()
        .enumerate()
        .map(|(i, n)| {
            let mut s = n.surfaces.clone();
            s.sort_unstable();
            (cells[i], s, depth[i])
        })
        .collect();
    out.sort_by(|x, y| x.1.cmp(&y.1).then(x.2.cmp(&y.2)));
    out
}

/// Σ of per-node tightness: every box equals the union of its surfaces' and children's boxes.
fn check_tight(tree: &ClusterTree, prims: &Prims) -> Result<(), TestCaseError> {
    for (i, n) in tree.nodes.iter().enumerate() {
        let mut b = Aabb::EMPTY;
        for &s in tree.node_surfaces(i as u32) {
            b.grow_box(&prims.bbox[s as usize]);
        }
        for c in n.children() {
            b.grow_box(&tree.nodes[c as usize].bbox);
        }
        prop_assert_eq!(b, n.bbox, "node {} of {} not tight", i, tree.strategy);
    }
    Ok(())
}

fn check_all(tris: &[[Vec3; 3]], lambda: f32) -> Result<(), TestCaseError> {
    let prims = prims_of(tris);
    let cfg = cfg_lambda(lambda);
    for s in Strategy::ALL {
        let t = ClusterTree::build_prims(&prims, s, &cfg);
        if let Err(e) = t.validate(&prims) {
            return Err(TestCaseError::fail(format!("{s}: {e}")));
        }
        let again = ClusterTree::build_prims(&prims, s, &cfg);
        prop_assert!(t == again, "{} is not deterministic", s);
        let stats = ClusterStats::compute(&t, &prims);
        prop_assert_eq!(stats.clusters, t.nodes.len());
        prop_assert!(stats.depth_mean <= stats.depth_max as f64);
        // Averages are over clusters with surfaces / with children respectively.
        let with_surf = t.nodes.iter().filter(|n| n.num_surfaces > 0).count() as f64;
        let inner = t.nodes.iter().filter(|n| n.num_children > 0).count() as f64;
        prop_assert!(
            (stats.surfaces_per_cluster_avg * with_surf - prims.len() as f64).abs() < 1e-6
        );
        prop_assert!(
            (stats.children_per_cluster_avg * inner - (t.nodes.len() - 1) as f64).abs() < 1e-6
        );
        prop_assert!(
            (stats.branching_factor * inner
                - (t.nodes.len() - 1) as f64
                - t.nodes
                    .iter()
                    .filter(|n| n.num_children > 0)
                    .map(|n| n.num_surfaces as f64)
                    .sum::<f64>())
            .abs()
                < 1e-6
        );
        match s {
            Strategy::Okdt => {
                prop_assert!(t.nodes.iter().all(|n| n.num_children <= 2));
                // No chain node: a node without surfaces has two children.
                prop_assert!(t
                    .nodes
                    .iter()
                    .all(|n| n.num_surfaces > 0 || n.num_children == 2));
                check_tight(&t, &prims)?;
            }
            Strategy::Kdt | Strategy::Obt => {
                prop_assert!(t.nodes.iter().all(|n| n.num_children <= 2));
            }
            Strategy::TfOct => {
                check_tight(&t, &prims)?;
                for (i, n) in t.nodes.iter().enumerate() {
                    prop_assert!(n.num_children <= 8);
                    if n.num_children > 0 {
                        // Surfaces kept at a split node are not smaller than an octant.
                        let oct = 0.5 * n.bbox.size();
                        for &x in t.node_surfaces(i as u32) {
                            prop_assert!(prims.size(x) >= oct);
                        }
                    } else if n.depth < cfg.max_depth as u32 && n.num_surfaces > 3 {
                        // A leaf holding more than 3 surfaces: all are large.
                        for &x in t.node_surfaces(i as u32) {
                            prop_assert!(prims.size(x) >= 0.5 * n.bbox.size());
                        }
                    }
                }
            }
            Strategy::Sah => {
                check_tight(&t, &prims)?;
                for n in &t.nodes {
                    if n.num_children > 0 {
                        prop_assert_eq!(n.num_surfaces, 0);
                        prop_assert!((2..=cfg.sah_width as u32).contains(&n.num_children));
                    } else {
                        prop_assert!(n.num_surfaces as usize <= cfg.sah_leaf_size);
                    }
                }
            }
            _ => {}
        }
    }
    // obt with λ = 0 is kdt.
    let kdt_t = ClusterTree::build_prims(&prims, Strategy::Kdt, &cfg);
    let obt0 = ClusterTree::build_prims(&prims, Strategy::Obt, &cfg_lambda(0.0));
    prop_assert!(same_tree(&kdt_t, &obt0), "obt(0) != kdt");
    // kdt boxes are the cells, and the tree is the naive kdt.
    let (kb, cells) = kdt::build_with_cells(&prims, &cfg);
    prop_assert!(kb.nodes.iter().zip(&cells).all(|(n, c)| n.bbox == *c));
    prop_assert_eq!(kdt_cells(&kb, &cells), naive_kdt(&prims, &cfg));
    if lambda > 0.0 {
        check_obt_relations(&prims, &cfg)?;
    }
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 48, ..ProptestConfig::default() })]

    #[test]
    fn random_scenes(seed in any::<u64>(), n in 1usize..300, coplanar in any::<bool>(),
                     dup in any::<bool>(), lambda in 0.0f32..1.5) {
        check_all(&random_scene(seed, n, coplanar, dup), lambda)?;
    }

    #[test]
    fn obt_relations_many_lambdas(seed in any::<u64>(), lambda in 0.01f32..2.0) {
        let prims = prims_of(&random_scene(seed, 400, false, false));
        check_obt_relations(&prims, &cfg_lambda(lambda))?;
    }
}

#[test]
fn degenerate_scenes() {
    let p = Vec3::new(1.0, 2.0, 3.0);
    let cases: Vec<Vec<[Vec3; 3]>> = vec![
        vec![[p, p, p]; 100],                                     // all at one point
        vec![[p, p + Vec3::X, p + Vec3::Y]],                      // one surface
        vec![[p, p + Vec3::X, p + Vec3::Y]; 50],                  // coincident
        vec![[Vec3::ZERO, Vec3::X * 1e-30, Vec3::Y * 1e-30]; 20], // below f32 resolution
        (0..64)
            .map(|i| {
                let x = i as f32;
                [
                    Vec3::new(x, 0.0, 0.0),
                    Vec3::new(x + 1.0, 0.0, 0.0),
                    Vec3::new(x, 1.0, 0.0),
                ]
            })
            .collect(), // coplanar strip
    ];
    for tris in &cases {
        for lambda in [0.0, 0.25, 1.0] {
            check_all(tris, lambda).unwrap();
        }
    }
    // One point, many surfaces: the tree stays shallow (no recursion to max_depth).
    let prims = prims_of(&cases[0]);
    for s in [
        Strategy::Kdt,
        Strategy::Obt,
        Strategy::Okdt,
        Strategy::TfOct,
    ] {
        let t = ClusterTree::build_prims(&prims, s, &ClusterConfig::default());
        assert_eq!(t.nodes.len(), 1, "{s}");
    }
    // Coincident surfaces with extent: kdt goes down until they cross a plane, then stops.
    let prims = prims_of(&cases[2]);
    let t = ClusterTree::build_prims(&prims, Strategy::Kdt, &ClusterConfig::default());
    assert_eq!(t.nodes.len(), 1);
    // Empty input gives one empty root.
    let empty = prims_of(&[]);
    for s in Strategy::ALL {
        let t = ClusterTree::build_prims(&empty, s, &ClusterConfig::default());
        assert_eq!(t.validate(&empty), Ok(()));
    }
}

#[test]
fn depth_limits() {
    // Exponentially spaced surfaces: SAH would peel a few per level; the median fallback
    // bounds the depth by max_depth/2 + log2(n).
    let tris: Vec<[Vec3; 3]> = (0..400)
        .map(|k| {
            let x = 1.2f32.powi(k - 200);
            let o = Vec3::new(x, 0.0, 0.0);
            [o, o + Vec3::Y * 1e-3, o + Vec3::Z * 1e-3]
        })
        .collect();
    let prims = prims_of(&tris);
    let cfg = ClusterConfig::default();
    for s in Strategy::ALL {
        let t = ClusterTree::build_prims(&prims, s, &cfg);
        assert_eq!(t.validate(&prims), Ok(()), "{s}");
        let d = t.nodes.iter().map(|n| n.depth).max().unwrap();
        assert!(d as usize <= cfg.max_depth + 9, "{s}: depth {d}");
    }
    // The binary SAH tree (width 2) alone goes deeper than max_depth/2 = 32 here: the SAH
    // peels a few surfaces per level until the median splits from depth 32 on, which bound
    // it by 32 + ⌈log2 400⌉ (below with max_depth 16: 8 + ⌈log2 400⌉). The default 8-wide
    // collapse of the same tree keeps its leaves and removes inner levels.
    let binary = ClusterConfig {
        sah_width: 2,
        ..Default::default()
    };
    let d = |t: &ClusterTree| t.nodes.iter().map(|n| n.depth).max().unwrap();
    let sah2 = ClusterTree::build_prims(&prims, Strategy::Sah, &binary);
    assert!(sah2.nodes.iter().all(|n| n.num_surfaces <= 4));
    assert!(sah2
        .nodes
        .iter()
        .all(|n| n.num_children == 0 || n.num_children == 2));
    // ⌈log2 400⌉ = 9.
    let half = binary.max_depth as u32 / 2;
    assert!(
        (half + 1..=half + 9).contains(&d(&sah2)),
        "binary depth {}",
        d(&sah2)
    );
    let sah = ClusterTree::build_prims(&prims, Strategy::Sah, &cfg);
    assert!(sah
        .nodes
        .iter()
        .all(|n| n.num_surfaces <= 4 && n.num_children <= 8));
    // Collapsing keeps the leaves (same surface groups) and removes only inner nodes.
    let leaves = |t: &ClusterTree| {
        let mut v: Vec<Vec<u32>> = (0..t.nodes.len() as u32)
            .filter(|&i| t.nodes[i as usize].num_children == 0)
            .map(|i| {
                let mut s = t.node_surfaces(i).to_vec();
                s.sort_unstable();
                s
            })
            .collect();
        v.sort();
        v
    };
    assert_eq!(leaves(&sah), leaves(&sah2));
    assert!(sah.nodes.len() < sah2.nodes.len());
    assert!(d(&sah) < d(&sah2), "8-wide depth {}", d(&sah));
    let cfg16 = ClusterConfig {
        max_depth: 16,
        sah_width: 2,
        ..Default::default()
    };
    let sah16 = ClusterTree::build_prims(&prims, Strategy::Sah, &cfg16);
    assert_eq!(sah16.validate(&prims), Ok(()));
    assert!(d(&sah16) <= 8 + 9, "{}", d(&sah16));
    assert!(sah16.nodes.iter().all(|n| n.num_surfaces <= 4));
    // A tight depth limit: kdt/obt/okdt/tf-oct stop there and say so.
    let shallow = ClusterConfig {
        max_depth: 2,
        ..Default::default()
    };
    let prims = prims_of(&soup(3, 500));
    for s in [
        Strategy::Kdt,
        Strategy::Obt,
        Strategy::Okdt,
        Strategy::TfOct,
    ] {
        let t = ClusterTree::build_prims(&prims, s, &shallow);
        assert_eq!(t.validate(&prims), Ok(()), "{s}");
        assert!(t.nodes.iter().all(|n| n.depth <= 2), "{s}");
        assert_eq!(t.notes.len(), 1, "{s}: {:?}", t.notes);
        assert!(t.notes[0].contains("max_depth 2"), "{s}: {:?}", t.notes);
    }
    let t = ClusterTree::build_prims(&prims, Strategy::Kdt, &cfg);
    assert!(t.notes.is_empty(), "{:?}", t.notes);
}

#[test]
fn thread_count_does_not_change_trees() {
    // Large enough for the parallel subtree builds to kick in.
    let prims = prims_of(&soup(7, 60_000));
    let cfg = ClusterConfig::default();
    for s in [
        Strategy::Kdt,
        Strategy::Obt,
        Strategy::Okdt,
        Strategy::TfOct,
        Strategy::Sah,
    ] {
        let one = in_pool(1, || ClusterTree::build_prims(&prims, s, &cfg));
        let two = in_pool(2, || ClusterTree::build_prims(&prims, s, &cfg));
        let four = in_pool(4, || ClusterTree::build_prims(&prims, s, &cfg));
        assert_eq!(one.validate(&prims), Ok(()), "{s}");
        assert!(one == two && two == four, "{s} depends on the thread count");
        // Memory budget of the brief: < 64 bytes per surface.
        assert!(
            one.memory_bytes() < 64 * prims.len(),
            "{s}: {}",
            one.memory_bytes()
        );
    }
    // okdt is the bounding-volume version of obt: same surfaces per non-chain node.
    let o = obt::build(&prims, &cfg);
    let k = okdt::build(&prims, &cfg);
    let kept = |t: &BuildTree| t.nodes.iter().filter(|n| !n.surfaces.is_empty()).count();
    assert_eq!(kept(&o), kept(&k));
    let _ = tf_oct::build(&prims, &cfg);
}

fn scene_path(rel: &str) -> String {
    format!(
        "{}/../../../shared/scenes/{rel}",
        env!("CARGO_MANIFEST_DIR")
    )
}

#[test]
fn graz_office_trees_are_valid() {
    let path = scene_path("graz_office/graz_office.obj");
    let scene = hirad::scene::Scene::load(&path, &Default::default())
        .unwrap_or_else(|e| panic!("cannot load {path}: {e}"));
    let prims = Prims::from_scene(&scene);
    let cfg = ClusterConfig::default();
    for s in Strategy::ALL {
        let t = ClusterTree::build_prims(&prims, s, &cfg);
        assert_eq!(t.validate(&prims), Ok(()), "{s}");
        let st = ClusterStats::compute(&t, &prims);
        assert_eq!(st.surfaces, scene.num_triangles());
        if s == Strategy::Okdt {
            assert!(t.nodes.iter().all(|n| n.num_children <= 2));
        }
        // Regression goldens of the top-down strategies on this scene (26,928 triangles):
        // (clusters, max depth, max surfaces on one cluster, overlap to 3 decimals). They
        // depend only on the set of triangles, not on their order.
        let golden = match s {
            Strategy::Kdt => Some((4928, 30, 420, 0.0)),
            Strategy::Obt => Some((6296, 31, 429, 11.995)),
            Strategy::Okdt => Some((3945, 24, 429, 9.537)),
            Strategy::TfOct => Some((8440, 11, 184, 245.337)),
            Strategy::Sah => Some((11349, 10, 4, 463.715)),
            _ => None,
        };
        if let Some((clusters, depth, smax, overlap)) = golden {
            assert_eq!(scene.num_triangles(), 26_928);
            assert_eq!(
                (st.clusters, st.depth_max, st.surfaces_per_cluster_max),
                (clusters, depth, smax),
                "{s}"
            );
            assert!((st.overlap - overlap).abs() < 5e-4, "{s}: {}", st.overlap);
        }
    }
}
