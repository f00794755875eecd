//! The refinement keeps links without choosing them by their own samples: over the links
//! with a cluster end, the kernels the solver kept deliver what independent evaluations of
//! the same links deliver. A decision taken on the kept samples (split when they came out
//! high) leaves the kept ones low, a bias towards dark (`docs/perf-log.md` 2026-12-04 (14)
//! and 2026-12-06 (37)).

use hirad::cluster::{ClusterConfig, ClusterTree, Strategy};
use hirad::progress::NoProgress;
use hirad::radiosity::element::Kind;
use hirad::radiosity::formfactor::KernelCtx;
use hirad::radiosity::overlap::Covers;
use hirad::radiosity::visibility::Visibility;
use hirad::radiosity::{solve, ClusterEmission, SolverConfig};
use hirad::scene::{Scene, SceneOptions};
use rayon::prelude::*;

/// Independent evaluations per link.
const FRESH: u64 = 4;

#[test]
fn kept_cluster_links_deliver_what_fresh_samples_deliver() {
    let scene = Scene::load("objsoup", &SceneOptions::default()).unwrap();
    for strategy in [Strategy::Objr, Strategy::TfOct] {
        let tree = ClusterTree::build(&scene, strategy, &ClusterConfig::default());
        let cfg = SolverConfig {
            cluster_emission: ClusterEmission::Directional,
            eps_rel: 0.108819,
            ..SolverConfig::default()
        };
        let sol = solve(&scene, &tree, &cfg, &NoProgress).unwrap();
        let vis = Visibility::new(&scene, &tree, cfg.visibility, cfg.vol_ratio).unwrap();
        let covers = Covers::build(&scene, &tree, cfg.two_sided);
        let el = &sol.elements;
        let ctx = KernelCtx {
            elems: el,
            tree: &tree,
            vis: &vis,
            covers: &covers,
            n_rays: cfg.shadow_rays as usize,
            seed: 0,
            emission: cfg.cluster_emission,
            reception: cfg.cluster_receive,
            occlusion: true,
        };
        // Power delivered per unit of the source's radiosity, kept and fresh (the mean of
        // `FRESH` evaluations with seeds of their own: a single one of these heavy-tailed
        // kernels is off by 0.2%), over the links with a cluster end (the others are not
        // judged on their samples).
        let (kept, fresh, n) = sol
            .links
            .links
            .par_iter()
            .filter(|l| {
                l.recv != l.src
                    && (el.elems[l.recv as usize].kind == Kind::Cluster
                        || el.elems[l.src as usize].kind == Kind::Cluster)
            })
            .map(|l| {
                let w = el.elems[l.recv as usize].area as f64 * el.b[l.src as usize].element_sum();
                let k = (0..FRESH)
                    .map(|seed| {
                        KernelCtx { seed, ..ctx }
                            .evaluate_with(l.recv, l.src, false, None, false, false)
                            .k
                    })
                    .sum::<f64>()
                    / FRESH as f64;
                (w * l.k as f64, w * k, 1usize)
            })
            .reduce(|| (0.0, 0.0, 0), |a, b| (a.0 + b.0, a.1 + b.1, a.2 + b.2));
        let ratio = kept / fresh;
        println!("{strategy}: {n} links with a cluster end, kept / fresh {ratio:.4}");
        assert!(
            (ratio - 1.0).abs() < 0.005,
            "{strategy}: the kept links deliver {ratio:.4} of a fresh evaluation"
        );
    }
}
