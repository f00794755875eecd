//! Solver benchmark (`cargo bench -p hirad --bench solve [-- FILTER]`): a full solve (refine,
//! gather, push-pull to convergence) with the default configuration on the built-in `cornell`
//! and `office` scenes, for the `proxi` and `okdt` cluster trees (trees built once, outside
//! the timing).

use criterion::{criterion_group, criterion_main, Criterion};
use hirad::cluster::{ClusterConfig, ClusterTree, Strategy};
use hirad::progress::NoProgress;
use hirad::radiosity::{solve, SolverConfig};
use hirad::scene::{Scene, SceneOptions};
use std::time::Duration;

fn bench(c: &mut Criterion) {
    for name in ["cornell", "office"] {
        let scene = Scene::load(name, &SceneOptions::default()).unwrap();
        let mut g = c.benchmark_group(format!("solve/{name}"));
        g.sample_size(10);
        g.measurement_time(Duration::from_secs(10));
        for s in [Strategy::Proxi, Strategy::Okdt] {
            let tree = ClusterTree::build(&scene, s, &ClusterConfig::default());
            let cfg = SolverConfig::default();
            g.bench_function(s.name(), |b| {
                b.iter(|| solve(&scene, &tree, &cfg, &NoProgress).unwrap().stats.links)
            });
        }
        g.finish();
    }
}

criterion_group!(benches, bench);
criterion_main!(benches);
