//! Ray-casting benchmark (`cargo bench -p hirad --bench ray [-- FILTER]`): occlusion and
//! closest-hit queries of the paper's ray-casting test (`experiments.md` §2: 10,000 segments of
//! seed 1 per iteration, single-threaded) through the trees of `sah`, `okdt`, `proxi` and
//! `tf-oct` on `graz_office` and `copper_beech`; plus the volumetric transmittance of the same
//! segments and the traversal layout build.

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use hirad::cluster::{ClusterConfig, ClusterTree, Strategy};
use hirad::ray::sample::sample_pairs;
use hirad::ray::volume::{Endpoint, VolumeCaster, DEFAULT_VOL_RATIO};
use hirad::ray::RayCaster;
use hirad::scene::{Scene, SceneOptions};
use std::time::Duration;

fn real(name: &str) -> String {
    format!(
        "{}/../../../shared/scenes/{name}/{name}.obj",
        env!("CARGO_MANIFEST_DIR")
    )
}

const N: usize = 10_000;

fn bench_scene(c: &mut Criterion, name: &str) {
    let scene = Scene::load(&real(name), &SceneOptions::default()).unwrap();
    let pairs = sample_pairs(&scene, N, 1);
    let segs: Vec<_> = pairs.iter().map(|p| p.segment).collect();
    let mut g = c.benchmark_group(format!("ray/{name}"));
    g.throughput(Throughput::Elements(N as u64));
    g.measurement_time(Duration::from_secs(4));
    g.sample_size(10);
    for st in [
        Strategy::Sah,
        Strategy::Okdt,
        Strategy::Proxi,
        Strategy::TfOct,
    ] {
        let tree = ClusterTree::build(&scene, st, &ClusterConfig::default());
        let rc = RayCaster::new(&scene, &tree);
        g.bench_with_input(BenchmarkId::new("occluded", st), &segs, |b, segs| {
            b.iter(|| {
                segs.iter()
                    .filter(|s| rc.occluded(s.origin, s.dir, s.tmin, s.tmax))
                    .count()
            })
        });
        g.bench_with_input(BenchmarkId::new("closest", st), &segs, |b, segs| {
            b.iter(|| {
                segs.iter()
                    .filter_map(|s| rc.closest(s.origin, s.dir, s.tmin, s.tmax))
                    .count()
            })
        });
        let vc = VolumeCaster::new(&scene, &tree);
        // End points on surfaces: their own surfaces and holding clusters are excluded.
        g.bench_with_input(BenchmarkId::new("volume", st), &pairs, |b, pairs| {
            b.iter(|| {
                pairs
                    .iter()
                    .map(|p| {
                        vc.transmittance(
                            p.a.p.as_vec3(),
                            p.b.p.as_vec3(),
                            DEFAULT_VOL_RATIO,
                            Endpoint::Surface(p.a.tri),
                            Endpoint::Surface(p.b.tri),
                        ) as f64
                    })
                    .sum::<f64>()
            })
        });
        g.bench_function(BenchmarkId::new("layout", st), |b| {
            b.iter(|| RayCaster::new(&scene, &tree).memory_bytes())
        });
    }
    g.finish();
}

fn benches(c: &mut Criterion) {
    bench_scene(c, "graz_office");
    bench_scene(c, "copper_beech");
}

criterion_group!(ray, benches);
criterion_main!(ray);
