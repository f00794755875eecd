//! Build time of the top-down cluster strategies on the built-in 1M-triangle `soup:1000000`
//! scene, single-threaded and on the global rayon pool. Run with
//! `cargo bench -p hirad --bench cluster_build`.

use criterion::{criterion_group, criterion_main, Criterion};
use hirad::cluster::{ClusterConfig, ClusterTree, Prims, Strategy};
use hirad::scene::{Scene, SceneOptions};
use std::time::Duration;

fn bench(c: &mut Criterion) {
    let scene = Scene::load("soup:1000000", &SceneOptions::default()).expect("soup scene");
    let prims = Prims::from_scene(&scene);
    let cfg = ClusterConfig::default();
    let single = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap();
    let mut g = c.benchmark_group(format!("cluster_build/{}tris", prims.len()));
    g.sample_size(10)
        .warm_up_time(Duration::from_secs(1))
        .measurement_time(Duration::from_secs(8));
    for s in [
        Strategy::Kdt,
        Strategy::Obt,
        Strategy::Okdt,
        Strategy::TfOct,
        Strategy::Sah,
    ] {
        g.bench_function(format!("{s}/1thread"), |b| {
            b.iter(|| single.install(|| ClusterTree::build_prims(&prims, s, &cfg)))
        });
        g.bench_function(
            format!("{s}/{}threads", rayon::current_num_threads()),
            |b| b.iter(|| ClusterTree::build_prims(&prims, s, &cfg)),
        );
    }
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
