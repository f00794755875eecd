//! PROXI / OKDT-P build-time benchmark (`cargo bench -p hirad --bench proxi [-- FILTER]`).
//!
//! Prints one JSON object per line: per scene the build time (best of several runs, one
//! rayon thread and the default pool) of `okdt`, `okdt-p` and `proxi`, the ratios to `okdt`,
//! and statistics of the trees; then the scaling of `proxi` from n to 4n triangles on a
//! generated scene (O(n log n) gives a ratio a little above 4; O(n²) would give 16).
//! FILTER selects the parts whose name contains it (`generated`, `graz_office`, `copper_beech`,
//! `bathroom`, `degenerate`, `scaling`).

use glam::Vec3;
use hirad::cluster::{okdt, okdt_p, proxi, BuildTree, ClusterConfig, ClusterTree, Prims, Strategy};
use hirad::geom::Aabb;
use hirad::rng::SplitMix64;
use std::time::Instant;

/// A generated scene of about `n` triangles: closed UV-spheres of log-uniform radii (0.05 to
/// 2 m, 24 to ~2000 triangles each) scattered in a 100 m × 20 m × 100 m hall, the kind of
/// many-object scene the clustering strategies are compared on.
fn generated(n: usize, seed: u64) -> Prims {
    let mut r = SplitMix64::new(seed);
    let mut tris: Vec<[Vec3; 3]> = Vec::with_capacity(n + 2048);
    while tris.len() < n {
        let c = Vec3::new(
            r.next_f32() * 100.0,
            r.next_f32() * 20.0,
            r.next_f32() * 100.0,
        );
        let t = r.next_f32();
        let radius = 0.05 * 40f32.powf(t);
        let seg = 4 + (t * 28.0) as usize; // 4..32 segments around
        let rings = seg.div_ceil(2).max(2);
        let p = |i: usize, j: usize| {
            let th = std::f32::consts::PI * i as f32 / rings as f32;
            let ph = std::f32::consts::TAU * j as f32 / seg as f32;
            c + radius * Vec3::new(th.sin() * ph.cos(), th.cos(), th.sin() * ph.sin())
        };
        for i in 0..rings {
            for j in 0..seg {
                let (a, b, cc, d) = (p(i, j), p(i + 1, j), p(i + 1, j + 1), p(i, j + 1));
                if i > 0 {
                    tris.push([a, b, d]);
                }
                if i + 1 < rings {
                    tris.push([b, cc, d]);
                }
            }
        }
    }
    tris.truncate(n);
    prims_from(&tris)
}

fn prims_from(tris: &[[Vec3; 3]]) -> Prims {
    let n = tris.len();
    Prims {
        bbox: tris.iter().map(|t| Aabb::from_points(t.iter())).collect(),
        centroid: tris.iter().map(|t| (t[0] + t[1] + t[2]) / 3.0).collect(),
        area: tris
            .iter()
            .map(|t| 0.5 * (t[1] - t[0]).cross(t[2] - t[0]).length())
            .collect(),
        object: vec![0; n],
        positions: Vec::new(),
        triangles: Vec::new(),
        material: Vec::new(),
    }
}

fn real(name: &str) -> Option<Prims> {
    let path = format!(
        "{}/../../../shared/scenes/{name}/{name}.obj",
        env!("CARGO_MANIFEST_DIR")
    );
    match hirad::scene::Scene::load(&path, &Default::default()) {
        Ok(s) => Some(Prims::from_scene(&s)),
        Err(e) => {
            eprintln!("skipping {name}: {e}");
            None
        }
    }
}

/// Best wall time of `runs` builds with `threads` rayon threads (0 = default pool).
fn time(runs: usize, threads: usize, f: &(dyn Fn() -> BuildTree + Sync)) -> (f64, BuildTree) {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .expect("thread pool");
    let mut best = f64::INFINITY;
    let mut tree = BuildTree::default();
    for _ in 0..runs {
        let t0 = Instant::now();
        tree = pool.install(f);
        best = best.min(t0.elapsed().as_secs_f64());
    }
    (best, tree)
}

fn stats(prims: &Prims, b: BuildTree, s: Strategy) -> String {
    let t = ClusterTree::from_build(b, prims.len(), s, ClusterConfig::default());
    t.validate(prims).expect("valid tree");
    let k = t.nodes.len() as f64;
    let members: f64 = t
        .nodes
        .iter()
        .map(|n| (n.num_children + n.num_surfaces) as f64)
        .sum();
    let child_sum: f64 = t.nodes.iter().map(|n| n.num_children as f64).sum();
    let max_members = t
        .nodes
        .iter()
        .map(|n| n.num_children + n.num_surfaces)
        .max()
        .unwrap_or(0);
    let max_surf = t.nodes.iter().map(|n| n.num_surfaces).max().unwrap_or(0);
    let depth = t.nodes.iter().map(|n| n.depth).max().unwrap_or(0);
    let mean_depth: f64 = t
        .surface_node
        .iter()
        .map(|&n| t.nodes[n as usize].depth as f64)
        .sum::<f64>()
        / prims.len().max(1) as f64;
    // Sum of node box areas relative to the root's (the SAH traversal cost of the nodes).
    let root_area = t.nodes[0].bbox.surface_area() as f64;
    let area_sum: f64 = t
        .nodes
        .iter()
        .map(|n| n.bbox.surface_area() as f64)
        .sum::<f64>()
        / root_area.max(f64::MIN_POSITIVE);
    format!(
        "{{\"clusters\":{},\"node_area_sum_over_root\":{area_sum:.1},\"mean_members\":{:.3},\"mean_child_clusters\":{:.3},\"max_members\":{},\"max_surfaces\":{},\"max_depth\":{},\"mean_surface_depth\":{:.2},\"notes\":{:?}}}",
        t.nodes.len(),
        members / k,
        child_sum / k,
        max_members,
        max_surf,
        depth,
        mean_depth,
        t.notes
    )
}

fn bench_scene(name: &str, prims: &Prims, runs: usize) {
    let cfg = ClusterConfig::default();
    let mut out = format!("{{\"scene\":\"{name}\",\"triangles\":{}", prims.len());
    let mut okdt_time = [0.0; 2];
    let builders: [(Strategy, &(dyn Fn() -> BuildTree + Sync)); 3] = [
        (Strategy::Okdt, &|| okdt::build(prims, &cfg)),
        (Strategy::OkdtP, &|| okdt_p::build(prims, &cfg)),
        (Strategy::Proxi, &|| proxi::build(prims, &cfg)),
    ];
    for (s, f) in builders {
        let (t1, tree1) = time(runs, 1, f);
        let (tp, tree) = time(runs, 0, f);
        assert_eq!(tree1, tree, "{s} depends on the thread count");
        if s == Strategy::Okdt {
            okdt_time = [t1, tp];
        }
        out += &format!(
            ",\"{s}\":{{\"seconds_1_thread\":{t1:.4},\"seconds_parallel\":{tp:.4},\"ratio_to_okdt_1_thread\":{:.2},\"stats\":{}}}",
            t1 / okdt_time[0],
            stats(prims, tree, s)
        );
    }
    println!("{out}}}");
}

fn main() {
    let filter: Option<String> = std::env::args().skip(1).find(|a| !a.starts_with("--"));
    let want = |name: &str| filter.as_deref().is_none_or(|f| name.contains(f));
    if want("generated") {
        for n in [250_000, 1_000_000] {
            bench_scene(&format!("generated-{n}"), &generated(n, 1), 3);
        }
    }
    for name in ["graz_office", "copper_beech", "bathroom"] {
        if want(name) {
            if let Some(p) = real(name) {
                bench_scene(name, &p, 3);
            }
        }
    }
    if want("degenerate") {
        // Pathological inputs: everything at one point (one grid cell), zero-area slivers on a
        // line, and tiny far-apart surfaces that must rise through many levels.
        let cfg = ClusterConfig::default();
        for n in [250_000usize, 1_000_000] {
            let p = Vec3::new(1.0, 2.0, 3.0);
            let point = prims_from(&vec![[p, p, p]; n]);
            let line = prims_from(
                &(0..n)
                    .map(|i| {
                        let a = Vec3::new(i as f32 * 1e-3, 0.0, 0.0);
                        [a, a + Vec3::X * 5e-4, a + Vec3::X * 1e-3]
                    })
                    .collect::<Vec<_>>(),
            );
            let mut r = SplitMix64::new(3);
            let sparse = prims_from(
                &(0..n)
                    .map(|_| {
                        let a = Vec3::new(r.next_f32(), r.next_f32(), r.next_f32()) * 1000.0;
                        [a, a + Vec3::X * 1e-4, a + Vec3::Y * 1e-4]
                    })
                    .collect::<Vec<_>>(),
            );
            for (name, prims) in [
                ("one-point", point),
                ("line", line),
                ("sparse-tiny", sparse),
            ] {
                let (t, tree) = time(1, 1, &|| proxi::build(&prims, &cfg));
                println!(
                    "{{\"degenerate\":\"{name}\",\"triangles\":{n},\"proxi_seconds_1_thread\":{t:.4},\"stats\":{}}}",
                    stats(&prims, tree, Strategy::Proxi)
                );
            }
        }
    }
    if want("scaling") {
        let cfg = ClusterConfig::default();
        let mut prev: Option<(usize, f64)> = None;
        for n in [62_500, 250_000, 1_000_000] {
            let prims = generated(n, 2);
            let (t, _) = time(3, 1, &|| proxi::build(&prims, &cfg));
            let ratio = prev.map(|(_, p)| t / p);
            println!(
                "{{\"scaling\":\"proxi\",\"triangles\":{n},\"seconds_1_thread\":{t:.4},\"ratio_to_n_over_4\":{}}}",
                ratio.map_or("null".to_string(), |r| format!("{r:.2}"))
            );
            prev = Some((n, t));
        }
    }
}
