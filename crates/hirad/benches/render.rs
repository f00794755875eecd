//! Rendering benchmarks: the z-buffer rasteriser on a 1M-triangle height field at 1024²
//! (target < 1 s on 2 threads), with and without 2×2 supersampling, and the path tracer on the
//! Cornell box and on `office` (path segments per second, rays per segment and the share of ray
//! casting are printed once before the timed runs).

use criterion::{criterion_group, criterion_main, Criterion};
use glam::Vec3;
use hirad::cluster::{ClusterConfig, ClusterTree, Strategy};
use hirad::progress::NoProgress;
use hirad::ray::RayCaster;
use hirad::render::{
    rasterize, render_reference, CameraView, MeshColors, PathTracer, RasterMesh, RasterOptions,
    ReferenceOptions,
};
use hirad::scene::{Scene, SceneOptions};
use std::hint::black_box;

/// A wavy height field of `n × n` quads (2n² triangles) over [−1, 1]², per-vertex colours.
fn height_field(n: u32) -> (Vec<Vec3>, Vec<[u32; 3]>, Vec<Vec3>) {
    let mut p = Vec::with_capacity(((n + 1) * (n + 1)) as usize);
    for j in 0..=n {
        for i in 0..=n {
            let x = -1.0 + 2.0 * i as f32 / n as f32;
            let z = -1.0 + 2.0 * j as f32 / n as f32;
            let y = 0.05 * (9.0 * x).sin() * (7.0 * z).cos();
            p.push(Vec3::new(x, y, z));
        }
    }
    let mut t = Vec::with_capacity((2 * n * n) as usize);
    for j in 0..n {
        for i in 0..n {
            let a = j * (n + 1) + i;
            t.push([a, a + n + 1, a + n + 2]);
            t.push([a, a + n + 2, a + 1]);
        }
    }
    let c = p.iter().map(|q| (*q + Vec3::ONE) * 0.5).collect();
    (p, t, c)
}

fn bench_raster(c: &mut Criterion) {
    let (p, t, col) = height_field(708); // 1,002,528 triangles
    let mesh = RasterMesh {
        positions: &p,
        triangles: &t,
        colors: MeshColors::PerVertex(&col),
    };
    let view = CameraView {
        eye: Vec3::new(0.0, 1.6, 1.6),
        target: Vec3::ZERO,
        up: Vec3::Y,
        fov_deg: 60.0,
        width: 1024,
        height: 1024,
    };
    let mut g = c.benchmark_group("raster");
    g.sample_size(10);
    for ss in [1, 2] {
        let opts = RasterOptions {
            supersample: ss,
            ..Default::default()
        };
        g.bench_function(format!("heightfield_1M_tris_1024x1024_ss{ss}"), |b| {
            b.iter(|| black_box(rasterize(&mesh, &view, &opts).unwrap()))
        });
    }
    g.finish();
}

fn bench_pathtrace(c: &mut Criterion) {
    let scene = Scene::load("cornell", &SceneOptions::default()).unwrap();
    let tree = ClusterTree::build(&scene, Strategy::Sah, &ClusterConfig::default());
    let caster = RayCaster::new(&scene, &tree);
    let mut view = CameraView::from_camera(&scene.default_camera());
    view.width = 64;
    view.height = 64;
    let opts = ReferenceOptions {
        spp: 4,
        ..Default::default()
    };
    let (_, stats) = render_reference(&scene, &caster, &view, &opts, &NoProgress).unwrap();
    eprintln!(
        "cornell 64x64 at 4 spp: {} segments, {} shadow rays, {:.2} M segments/s",
        stats.segments,
        stats.shadow_rays,
        stats.segments_per_second() * 1e-6
    );
    let mut g = c.benchmark_group("pathtrace");
    g.sample_size(10);
    g.bench_function("cornell_64x64_4spp", |b| {
        b.iter(|| black_box(render_reference(&scene, &caster, &view, &opts, &NoProgress).unwrap()))
    });
    g.finish();
}

/// The path tracer on `office` (the target scene: ≥ 5 M segments/s on 2 threads), with the
/// share of ray casting measured by replaying the recorded rays.
fn bench_pathtrace_office(c: &mut Criterion) {
    let scene = Scene::load("office", &SceneOptions::default()).unwrap();
    let tree = ClusterTree::build(&scene, Strategy::Sah, &ClusterConfig::default());
    let caster = RayCaster::new(&scene, &tree);
    let mut view = CameraView::from_camera(&scene.default_camera());
    view.width = 160;
    view.height = 120;
    let opts = ReferenceOptions {
        spp: 2,
        ..Default::default()
    };
    let tracer = PathTracer::new(&scene, &caster, &opts);
    let (_, stats) = tracer.render(&view, &NoProgress, None).unwrap();
    let (rep, _, _) = tracer.record_rays(&view, 1).unwrap().replay(&caster);
    eprintln!(
        "office 160x120 at 2 spp: {:.2} M segments/s, {:.3} rays per segment, ray casting {:.0}% \
         (replay: closest {:.2} M/s, shadow {:.2} M/s)",
        stats.segments_per_second() * 1e-6,
        (stats.segments + stats.shadow_rays) as f64 / stats.segments as f64,
        100.0 * rep.ray_seconds_for(&stats) / stats.seconds,
        rep.closest_per_second() * 1e-6,
        rep.shadow_per_second() * 1e-6
    );
    let mut g = c.benchmark_group("pathtrace");
    g.sample_size(10);
    g.bench_function("office_160x120_2spp", |b| {
        b.iter(|| black_box(tracer.render(&view, &NoProgress, None).unwrap()))
    });
    g.finish();
}

/// The real bathroom scene (379,844 triangles) with flat per-triangle colours ρ, at 1024².
fn bench_raster_bathroom(c: &mut Criterion) {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../../shared/scenes/bathroom/bathroom.obj"
    );
    let scene = match Scene::load(path, &SceneOptions::default()) {
        Ok(s) => s,
        Err(e) => {
            eprintln!("raster/bathroom not run: {e}");
            return;
        }
    };
    let rho: Vec<Vec3> = (0..scene.num_triangles())
        .map(|i| scene.material_of(i).rho)
        .collect();
    let mesh = RasterMesh {
        positions: &scene.positions,
        triangles: &scene.triangles,
        colors: MeshColors::PerTriangle(&rho),
    };
    let mut view = CameraView::from_camera(&scene.default_camera());
    view.width = 1024;
    view.height = 1024;
    let opts = RasterOptions::default();
    let mut g = c.benchmark_group("raster");
    g.sample_size(10);
    g.bench_function("bathroom_380k_tris_1024x1024_flat", |b| {
        b.iter(|| black_box(rasterize(&mesh, &view, &opts).unwrap()))
    });
    g.finish();
}

criterion_group!(
    benches,
    bench_raster,
    bench_raster_bathroom,
    bench_pathtrace,
    bench_pathtrace_office
);
criterion_main!(benches);
