//! PROXI and OKDT-P: invariants on random and degenerate inputs, proximity grouping, the
//! `max_children` / `max_surfaces` bounds, determinism across runs and thread counts, and
//! statistics on a real scene.

use glam::Vec3;
use hirad::cluster::{okdt_p, proxi, BuildTree, ClusterConfig, ClusterTree, Prims, Strategy};
use hirad::geom::Aabb;
use hirad::rng::SplitMix64;
use proptest::prelude::*;

/// Builder inputs for a list of triangles.
fn prims_of(tris: &[[Vec3; 3]]) -> Prims {
    let bbox: Vec<Aabb> = tris.iter().map(|t| Aabb::from_points(t.iter())).collect();
    let centroid = tris.iter().map(|t| (t[0] + t[1] + t[2]) / 3.0).collect();
    let area = tris
        .iter()
        .map(|t| 0.5 * (t[1] - t[0]).cross(t[2] - t[0]).length())
        .collect();
    Prims {
        bbox,
        centroid,
        area,
        object: vec![0; tris.len()],
        positions: Vec::new(),
        triangles: Vec::new(),
        material: Vec::new(),
    }
}

/// `n` random triangles: centres in a cube of edge `extent`, edges of log-uniform length in
/// `[size/16, size]`.
fn random_tris(n: usize, extent: f32, size: f32, seed: u64) -> Vec<[Vec3; 3]> {
    let mut r = SplitMix64::new(seed);
    let v = |r: &mut SplitMix64| Vec3::new(r.next_f32(), r.next_f32(), r.next_f32());
    (0..n)
        .map(|_| {
            let c = v(&mut r) * extent;
            let s = size * (-(r.next_f32() * 4.0)).exp2();
            let a = c + (v(&mut r) - 0.5) * s;
            let b = c + (v(&mut r) - 0.5) * s;
            let d = c + (v(&mut r) - 0.5) * s;
            [a, b, d]
        })
        .collect()
}

fn tree(prims: &Prims, build: BuildTree, strategy: Strategy, cfg: &ClusterConfig) -> ClusterTree {
    ClusterTree::from_build(build, prims.len(), strategy, cfg.clone())
}

fn proxi_tree(prims: &Prims, cfg: &ClusterConfig) -> ClusterTree {
    tree(prims, proxi::build(prims, cfg), Strategy::Proxi, cfg)
}

fn okdt_p_tree(prims: &Prims, cfg: &ClusterConfig) -> ClusterTree {
    tree(prims, okdt_p::build(prims, cfg), Strategy::OkdtP, cfg)
}

/// Box of everything below node `id` (attached surfaces and children, recursively).
fn content_box(t: &ClusterTree, prims: &Prims, id: u32) -> Aabb {
    let n = &t.nodes[id as usize];
    let mut b = Aabb::EMPTY;
    for &s in t.node_surfaces(id) {
        b.grow_box(&prims.bbox[s as usize]);
    }
    for c in n.children() {
        b.grow_box(&t.nodes[c as usize].bbox);
    }
    b
}

/// The PROXI invariants: valid tree, ≤ `max_children` members (child clusters + surfaces)
/// per node, ≥ 2 members per node when there are ≥ 2 surfaces, boxes exactly tight.
fn check_proxi(t: &ClusterTree, prims: &Prims, max_children: usize) {
    t.validate(prims).unwrap();
    let max_children = max_children.max(2);
    for (id, n) in t.nodes.iter().enumerate() {
        let members = (n.num_children + n.num_surfaces) as usize;
        assert!(
            members <= max_children,
            "node {id} has {members} > {max_children} members"
        );
        if prims.len() >= 2 {
            assert!(members >= 2, "node {id} has {members} member");
        }
        if !prims.is_empty() {
            assert_eq!(
                n.bbox,
                content_box(t, prims, id as u32),
                "node {id} not tight"
            );
        }
    }
    if prims.len() >= 2 {
        // With ≥ 2 members everywhere, the tree has fewer nodes than surfaces.
        assert!(t.nodes.len() < prims.len());
    }
}

fn check_okdt_p(t: &ClusterTree, prims: &Prims, max_surfaces: usize) {
    t.validate(prims).unwrap();
    if max_surfaces >= 2 {
        for (id, n) in t.nodes.iter().enumerate() {
            assert!(
                n.num_surfaces as usize <= max_surfaces,
                "node {id} holds {} > {max_surfaces} surfaces",
                n.num_surfaces
            );
        }
        assert!(
            t.notes.iter().all(|s| !s.contains("keep more than")),
            "{:?}",
            t.notes
        );
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    #[test]
    fn proxi_random_scenes_valid(
        n in 1usize..400,
        extent in 0.01f32..100.0,
        size in 0.001f32..10.0,
        max_children in 0usize..12,
        seed in any::<u64>(),
    ) {
        let prims = prims_of(&random_tris(n, extent, size, seed));
        let cfg = ClusterConfig { max_children, ..Default::default() };
        let t = proxi_tree(&prims, &cfg);
        check_proxi(&t, &prims, max_children);
    }

    #[test]
    fn okdt_p_random_scenes_valid(
        n in 1usize..400,
        extent in 0.01f32..100.0,
        size in 0.001f32..10.0,
        max_surfaces in 0usize..20,
        seed in any::<u64>(),
    ) {
        let prims = prims_of(&random_tris(n, extent, size, seed));
        let cfg = ClusterConfig { max_surfaces, ..Default::default() };
        let t = okdt_p_tree(&prims, &cfg);
        check_okdt_p(&t, &prims, max_surfaces);
    }

    #[test]
    fn proxi_subset_is_tight_and_local(
        n in 2usize..300,
        seed in any::<u64>(),
        keep in 1u64..4,
    ) {
        let prims = prims_of(&random_tris(n, 10.0, 1.0, seed));
        let subset: Vec<u32> = (0..n as u32).filter(|&i| !(i as u64 * 7).wrapping_add(seed).is_multiple_of(keep + 1)).collect();
        let mut out = BuildTree::default();
        // Nodes already in `out` must be left alone.
        out.push(Default::default());
        let root = proxi::build_subset(&prims, &subset, &ClusterConfig::default(), &mut out);
        prop_assert_eq!(root as usize, out.nodes.len() - 1);
        let mut seen: Vec<u32> = Vec::new();
        let mut stack = vec![root];
        let mut reached = 0;
        while let Some(id) = stack.pop() {
            reached += 1;
            let node = &out.nodes[id as usize];
            prop_assert!(id >= 1);
            seen.extend(&node.surfaces);
            stack.extend(&node.children);
        }
        // Every node pushed belongs to the subtree.
        prop_assert_eq!(reached, out.nodes.len() - 1);
        seen.sort();
        let mut want = subset.clone();
        want.sort();
        prop_assert_eq!(&seen, &want);
        let mut tight = Aabb::EMPTY;
        for &s in &subset {
            tight.grow_box(&prims.bbox[s as usize]);
        }
        if !subset.is_empty() {
            prop_assert_eq!(out.nodes[root as usize].bbox, tight);
        }
    }
}

/// Well separated groups of surfaces are each clustered on their own: for every group there
/// is a node whose subtree holds exactly that group.
#[test]
fn proxi_groups_by_proximity() {
    let mut r = SplitMix64::new(7);
    let mut tris = Vec::new();
    let mut groups = Vec::new();
    for gx in 0..6 {
        for gy in 0..5 {
            for gz in 0..4 {
                let base = Vec3::new(gx as f32, gy as f32, gz as f32) * 10.0;
                let k = 3 + (gx + gy + gz) % 6; // 3..8 surfaces per group
                let ids: Vec<u32> = (tris.len() as u32..(tris.len() + k) as u32).collect();
                for _ in 0..k {
                    let p = |r: &mut SplitMix64| {
                        base + Vec3::new(r.next_f32(), r.next_f32(), r.next_f32()) * 0.3
                    };
                    tris.push([p(&mut r), p(&mut r), p(&mut r)]);
                }
                groups.push(ids);
            }
        }
    }
    let prims = prims_of(&tris);
    let cfg = ClusterConfig::default();
    let t = proxi_tree(&prims, &cfg);
    check_proxi(&t, &prims, cfg.max_children);
    // Surfaces below each node, by post-order accumulation (children have larger ids).
    let mut below: Vec<Vec<u32>> = vec![Vec::new(); t.nodes.len()];
    for id in (0..t.nodes.len()).rev() {
        let mut v: Vec<u32> = t.node_surfaces(id as u32).to_vec();
        for c in t.nodes[id].children() {
            v.extend(&below[c as usize]);
        }
        v.sort();
        below[id] = v;
    }
    for g in &groups {
        assert!(below.iter().any(|b| b == g), "group {g:?} is split");
    }
}

/// A regular grid of equal quads (a floor): every cluster stays compact, i.e. its box is at
/// most a few times the size a perfect packing of its surfaces would have.
#[test]
fn proxi_clusters_on_a_floor_are_compact() {
    let n = 64;
    let mut tris = Vec::new();
    for i in 0..n {
        for j in 0..n {
            let p = Vec3::new(i as f32, 0.0, j as f32);
            tris.push([p, p + Vec3::X, p + Vec3::Z]);
            tris.push([p + Vec3::X, p + Vec3::X + Vec3::Z, p + Vec3::Z]);
        }
    }
    let prims = prims_of(&tris);
    let cfg = ClusterConfig::default();
    let t = proxi_tree(&prims, &cfg);
    check_proxi(&t, &prims, cfg.max_children);
    let mut count = vec![0usize; t.nodes.len()];
    for id in (0..t.nodes.len()).rev() {
        count[id] = t.nodes[id].num_surfaces as usize
            + t.nodes[id]
                .children()
                .map(|c| count[c as usize])
                .sum::<usize>();
    }
    let mut worst = 0.0f64;
    for (id, node) in t.nodes.iter().enumerate() {
        let e = node.bbox.extent();
        // Area of the box on the floor / area of the unit-square halves it holds.
        let ratio = (e.x as f64 * e.z as f64) / (count[id] as f64 * 0.5);
        worst = worst.max(ratio);
        assert!(e.y == 0.0);
    }
    assert!(worst <= 4.0, "worst box area / surface area = {worst}");
    let depth = t.nodes.iter().map(|n| n.depth).max().unwrap();
    // 8192 surfaces, ≤ 8 members per node: depth at least log8(8192) ≈ 4.3; a balanced
    // bottom-up build stays well below the linear worst case.
    assert!((5..=16).contains(&depth), "depth {depth}");
}

/// Size filtering: small surfaces lying on large ones are clustered among themselves first,
/// so each small surface is attached to a cluster of its own scale, not to a large one.
#[test]
fn proxi_size_filtering_keeps_small_surfaces_in_small_clusters() {
    let mut tris = Vec::new();
    // A floor of 16 × 16 quads of 8 m.
    for i in 0..16 {
        for j in 0..16 {
            let p = Vec3::new(i as f32, 0.0, j as f32) * 8.0;
            let (x, z) = (Vec3::X * 8.0, Vec3::Z * 8.0);
            tris.push([p, p + x, p + z]);
            tris.push([p + x, p + x + z, p + z]);
        }
    }
    let big = tris.len();
    // 300 clumps of 10 small triangles (5 cm) each within 20 cm, resting on the floor.
    let mut r = SplitMix64::new(99);
    for _ in 0..300 {
        let c = Vec3::new(r.next_f32() * 128.0, 0.0, r.next_f32() * 128.0);
        for _ in 0..10 {
            let p = c + Vec3::new(r.next_f32(), r.next_f32(), r.next_f32()) * 0.15;
            tris.push([p, p + Vec3::X * 0.05, p + Vec3::Y * 0.05]);
        }
    }
    let prims = prims_of(&tris);
    let cfg = ClusterConfig::default();
    let t = proxi_tree(&prims, &cfg);
    check_proxi(&t, &prims, cfg.max_children);
    let worst = (big..tris.len())
        .map(|s| t.nodes[t.surface_node[s] as usize].bbox.size())
        .fold(0.0f32, f32::max);
    let mut worst_clump = 0.0f32;
    // Measured: 0.41 m, against 8 m for the floor's surfaces.
    assert!(worst <= 1.0, "small surface in a cluster of size {worst}");
    // The clumps stay whole: the deepest node holding a whole clump is not much bigger.
    for clump in 0..300 {
        let ids: Vec<u32> = (0..10).map(|i| (big + clump * 10 + i) as u32).collect();
        let mut b = Aabb::EMPTY;
        for &i in &ids {
            b.grow_box(&prims.bbox[i as usize]);
        }
        // Walk up from one surface to the first node containing the whole clump.
        let mut id = t.surface_node[ids[0] as usize];
        while !ids
            .iter()
            .all(|&s| is_below(&t, t.surface_node[s as usize], id))
        {
            id = t.nodes[id as usize].parent;
        }
        let size = t.nodes[id as usize].bbox.size();
        worst_clump = worst_clump.max(size / b.size());
        assert!(
            size <= 2.0,
            "clump {clump} first complete in a node of size {size}"
        );
    }
    // Measured: 2.69.
    assert!(
        worst_clump <= 4.0,
        "clump cluster / clump size {worst_clump}"
    );
}

/// True when node `a` is `b` or below it.
fn is_below(t: &ClusterTree, mut a: u32, b: u32) -> bool {
    loop {
        if a == b {
            return true;
        }
        if a == 0 {
            return false;
        }
        a = t.nodes[a as usize].parent;
    }
}

#[test]
fn proxi_and_okdt_p_are_deterministic_and_thread_independent() {
    let prims = prims_of(&random_tris(30_000, 50.0, 1.0, 42));
    let cfg = ClusterConfig::default();
    let a = proxi::build(&prims, &cfg);
    let b = proxi::build(&prims, &cfg);
    assert_eq!(a, b);
    let pool = |k| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(k)
            .build()
            .unwrap()
    };
    let c = pool(1).install(|| proxi::build(&prims, &cfg));
    let d = pool(2).install(|| proxi::build(&prims, &cfg));
    assert_eq!(a, c);
    assert_eq!(a, d);
    let p1 = pool(1).install(|| okdt_p::build(&prims, &cfg));
    let p2 = pool(2).install(|| okdt_p::build(&prims, &cfg));
    assert_eq!(p1, p2);
    check_proxi(&proxi_tree(&prims, &cfg), &prims, cfg.max_children);
    check_okdt_p(&okdt_p_tree(&prims, &cfg), &prims, cfg.max_surfaces);
}

#[test]
fn degenerate_inputs_do_not_panic() {
    let cfg = ClusterConfig::default();
    let p = Vec3::new(1.0, 2.0, 3.0);
    let cases: Vec<(&str, Vec<[Vec3; 3]>)> = vec![
        ("empty", vec![]),
        ("one surface", vec![[Vec3::ZERO, Vec3::X, Vec3::Y]]),
        ("all at one point", vec![[p, p, p]; 5000]),
        (
            "zero-area collinear",
            (0..3000)
                .map(|i| {
                    let a = Vec3::new(i as f32 * 0.01, 0.0, 0.0);
                    [a, a + Vec3::X * 0.5, a + Vec3::X]
                })
                .collect(),
        ),
        (
            "coplanar",
            random_tris(3000, 10.0, 1.0, 3)
                .into_iter()
                .map(|t| t.map(|v| Vec3::new(v.x, 5.0, v.z)))
                .collect(),
        ),
        (
            "identical triangles",
            vec![[Vec3::ZERO, Vec3::X, Vec3::Y]; 4000],
        ),
        ("tiny surfaces 10^6 sizes apart", {
            let mut r = SplitMix64::new(8);
            (0..3000)
                .map(|_| {
                    let a = Vec3::new(r.next_f32(), r.next_f32(), r.next_f32()) * 1000.0;
                    [a, a + Vec3::X * 1e-4, a + Vec3::Y * 1e-4]
                })
                .collect()
        }),
        ("sizes over 12 decades", {
            let mut v = random_tris(500, 1e6, 1e5, 5);
            v.extend(random_tris(500, 1e-3, 1e-6, 6));
            v
        }),
    ];
    for (name, tris) in cases {
        let prims = prims_of(&tris);
        let t = proxi_tree(&prims, &cfg);
        check_proxi(&t, &prims, cfg.max_children);
        let t = okdt_p_tree(&prims, &cfg);
        check_okdt_p(&t, &prims, cfg.max_surfaces);
        if prims.len() >= 2 {
            // Each level at least halves the objects in the worst case; depth stays logarithmic.
            let depth = t.nodes.iter().map(|n| n.depth).max().unwrap_or(0) as f64;
            assert!(
                depth <= 4.0 * (prims.len() as f64).log2() + 8.0,
                "{name}: depth {depth}"
            );
        }
    }
}

/// Non-finite coordinates are rejected at load; the builders still must not panic on them.
#[test]
fn non_finite_prims_do_not_panic() {
    let mut tris = random_tris(200, 1.0, 0.1, 9);
    tris[3][1] = Vec3::new(f32::NAN, 0.0, 0.0);
    tris[50][0] = Vec3::splat(f32::INFINITY);
    let prims = prims_of(&tris);
    let cfg = ClusterConfig::default();
    let t = proxi::build(&prims, &cfg);
    let t = ClusterTree::from_build(t, prims.len(), Strategy::Proxi, cfg.clone());
    // Every surface is still attached exactly once.
    let mut s = t.surfaces.clone();
    s.sort();
    assert_eq!(s, (0..200).collect::<Vec<u32>>());
    let t = okdt_p::build(&prims, &cfg);
    let t = ClusterTree::from_build(t, prims.len(), Strategy::OkdtP, cfg);
    let mut s = t.surfaces.clone();
    s.sort();
    assert_eq!(s, (0..200).collect::<Vec<u32>>());
}

/// OKDT-P with `max_surfaces` below 2 cannot always be met; the tree says how often.
#[test]
fn okdt_p_reports_unsplittable_groups() {
    let prims = prims_of(&random_tris(500, 1.0, 0.1, 11));
    let cfg = ClusterConfig {
        max_surfaces: 1,
        ..Default::default()
    };
    let t = okdt_p_tree(&prims, &cfg);
    t.validate(&prims).unwrap();
    let over = t.nodes.iter().filter(|n| n.num_surfaces > 1).count();
    for n in &t.nodes {
        assert!(n.num_surfaces <= 2);
    }
    // PROXI pairs surfaces, so some clusters must keep two.
    assert!(over > 0);
    let want = format!("okdt-p: {over} clusters keep more than max_surfaces = 1");
    assert!(
        t.notes.iter().any(|s| s.starts_with(&want)),
        "{:?}",
        t.notes
    );
}

fn real_scene(name: &str) -> Prims {
    let path = format!(
        "{}/../../../shared/scenes/{name}",
        env!("CARGO_MANIFEST_DIR")
    );
    let scene = hirad::scene::Scene::load(&path, &Default::default())
        .unwrap_or_else(|e| panic!("cannot load {path}: {e}"));
    Prims::from_scene(&scene)
}

/// Statistics of PROXI and OKDT-P on graz_office (26,928 triangles).
#[test]
fn graz_office_proxi_and_okdt_p() {
    let prims = real_scene("graz_office/graz_office.obj");
    assert!(prims.len() > 26_000, "{} triangles", prims.len());
    let cfg = ClusterConfig::default();
    let t = proxi_tree(&prims, &cfg);
    check_proxi(&t, &prims, cfg.max_children);
    // Golden statistics (measured 5,758 clusters, 5.68 members per cluster, depth 12), with
    // room for small changes of the loader or the floating-point details.
    let clusters = t.nodes.len();
    assert!((5_400..=6_100).contains(&clusters), "{clusters} clusters");
    let members: f64 = t
        .nodes
        .iter()
        .map(|x| (x.num_children + x.num_surfaces) as f64)
        .sum::<f64>()
        / clusters as f64;
    assert!((5.4..=6.0).contains(&members), "mean members {members}");
    let depth = t.nodes.iter().map(|x| x.depth).max().unwrap();
    assert!((10..=14).contains(&depth), "depth {depth}");
    eprintln!(
        "graz_office proxi: {} clusters, mean members {members:.3}, depth {depth}",
        t.nodes.len()
    );
    let t = okdt_p_tree(&prims, &cfg);
    check_okdt_p(&t, &prims, cfg.max_surfaces);
    eprintln!(
        "graz_office okdt-p: {} clusters, depth {}, notes {:?}",
        t.nodes.len(),
        t.nodes.iter().map(|x| x.depth).max().unwrap(),
        t.notes
    );
}
