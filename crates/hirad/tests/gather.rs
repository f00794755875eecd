//! Final gather (`render::gather`) against closed forms: the direct term under a quad light over
//! an open plane equals the point-to-polygon irradiance; in the furnace the gather returns the
//! analytic radiance B/π; adaptive samples go to an emitter's outline (exact coverage); the
//! image is seeded and does not depend on the thread count.

use glam::Vec3;
use hirad::cluster::{ClusterConfig, ClusterTree, Strategy};
use hirad::progress::NoProgress;
use hirad::radiosity::{output, solve, SolverConfig};
use hirad::ray::RayCaster;
use hirad::render::{
    render_solution, CameraView, GatherOptions, GatherStats, Gatherer, Image, Lookup,
    RasterOptions, SolutionLookup,
};
use hirad::scene::export::ColoredMesh;
use hirad::scene::{Material, RawScene, Scene, SceneOptions, UpAxis};
use std::f64::consts::PI;

fn gather(scene: &Scene, mesh: &ColoredMesh, view: &CameraView, opts: &GatherOptions) -> Image {
    gather_stats(scene, mesh, view, opts).0
}

fn gather_stats(
    scene: &Scene,
    mesh: &ColoredMesh,
    view: &CameraView,
    opts: &GatherOptions,
) -> (Image, GatherStats) {
    let tree = ClusterTree::build(scene, Strategy::Sah, &ClusterConfig::default());
    let caster = RayCaster::new(scene, &tree);
    let sol = SolutionLookup::new(mesh, scene, &caster, opts.lookup).unwrap();
    let (img, stats) = Gatherer::new(scene, &caster, &sol, opts)
        .render(view, &NoProgress, None)
        .unwrap();
    assert_eq!(stats.lookup_misses, 0, "every gather hit finds its element");
    (img, stats)
}

/// The quad `[-0.5, 0.5] × [-0.3, 0.3]` at z = 1 facing down (ρ = 0, emitted radiance `le`,
/// the solution's radiosity `b`) over the floor `[-half, half]²` at z = 0 facing up (ρ = 0.5,
/// radiosity 0): the scene, the solution mesh and the quad's corners.
fn quad_and_floor(half: f32, le: f32, b: f32) -> (Scene, ColoredMesh, [Vec3; 4]) {
    quad_and_floor_copies(half, le, b, false)
}

/// [`quad_and_floor`], with `copy`: the quad a second time in the same place (triangulated
/// along the other diagonal, after the first, of the same material and radiosity).
fn quad_and_floor_copies(
    half: f32,
    le: f32,
    b: f32,
    copy: bool,
) -> (Scene, ColoredMesh, [Vec3; 4]) {
    let quad = [
        Vec3::new(-0.5, -0.3, 1.0),
        Vec3::new(-0.5, 0.3, 1.0),
        Vec3::new(0.5, 0.3, 1.0),
        Vec3::new(0.5, -0.3, 1.0),
    ];
    let mut positions = vec![
        Vec3::new(-half, -half, 0.0),
        Vec3::new(half, -half, 0.0),
        Vec3::new(half, half, 0.0),
        Vec3::new(-half, half, 0.0),
    ];
    positions.extend_from_slice(&quad);
    // Quad corners in this order face down (-z).
    let mut triangles = vec![[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]];
    let mut tri_material = vec![0, 0, 1, 1];
    if copy {
        triangles.extend([[5, 6, 7], [5, 7, 4]]);
        tri_material.extend([1, 1]);
    }
    let n = triangles.len();
    let raw = RawScene {
        name: "quad over a floor".into(),
        positions: positions.clone(),
        triangles: triangles.clone(),
        tri_material,
        tri_object: vec![0; n],
        materials: vec![
            Material::diffuse("floor", Vec3::splat(0.5)),
            Material {
                name: "quad".into(),
                rho: Vec3::ZERO,
                emission: Vec3::splat(le),
            },
        ],
        up: UpAxis::Z,
        ..Default::default()
    };
    let scene = Scene::from_raw(raw, &SceneOptions::default()).unwrap();
    assert!(scene.normals[2].z < -0.99, "the quad faces down");
    assert!(scene.normals[n - 1].z < -0.99, "its copy faces down");
    let mut colors = vec![Vec3::ZERO; 4];
    colors.extend([Vec3::splat(b); 4]);
    let mesh = ColoredMesh {
        positions,
        triangles,
        colors,
    };
    (scene, mesh, quad)
}

/// Irradiance at `x` (normal `n`) from a polygon of uniform radiance `l` (Lambert's
/// point-to-polygon form factor: E = L/2 · |Σ γᵢ n·(rᵢ × rᵢ₊₁)/|rᵢ × rᵢ₊₁||).
fn polygon_irradiance(x: Vec3, n: Vec3, poly: &[Vec3], l: f64) -> f64 {
    let mut s = 0.0f64;
    for i in 0..poly.len() {
        let a = (poly[i] - x).as_dvec3().normalize();
        let b = (poly[(i + 1) % poly.len()] - x).as_dvec3().normalize();
        let g = a.dot(b).clamp(-1.0, 1.0).acos();
        s += g * n.as_dvec3().dot(a.cross(b).normalize());
    }
    0.5 * l * s.abs()
}

/// A 40 × 40 floor z = 0 (ρ = 0.5, facing +z) under a 1 × 0.6 quad at z = 1 facing down
/// (ρ = 0) of emitted radiance `le` whose solution reads radiosity `b` (the floor's reads 0,
/// which no gather ray from the floor sees; a bright quad is sampled by area): nothing else, so a floor point's radiance is
/// ρ/π · E(x), E the irradiance from a polygon of radiance L_e + (b − π L_e)/π. Gathers a view
/// of the floor; returns the gather's statistics, the worst pixel's error relative to its own
/// value and to the brightest pixel's, and the error of the mean.
fn quad_over_floor(
    le: f32,
    b: f32,
    opts: &GatherOptions,
    size: (u32, u32),
) -> (GatherStats, f64, f64, f64) {
    quad_over_floor_copies(le, b, opts, size, false)
}

/// [`quad_over_floor`] with the quad twice in the same place when `copy`
/// ([`quad_and_floor_copies`]): the floor's light is the same.
fn quad_over_floor_copies(
    le: f32,
    b: f32,
    opts: &GatherOptions,
    size: (u32, u32),
    copy: bool,
) -> (GatherStats, f64, f64, f64) {
    let (scene, mesh, quad) = quad_and_floor_copies(20.0, le, b, copy);
    let rho = 0.5f32;
    let view = CameraView {
        eye: Vec3::new(0.2, 0.1, 0.6),
        target: Vec3::new(0.5, 0.2, 0.0),
        up: Vec3::Y,
        fov_deg: 70.0,
        width: size.0,
        height: size.1,
    };
    let (img, stats) = gather_stats(&scene, &mesh, &view, opts);
    let l = le as f64 + (b as f64 - PI * le as f64).max(0.0) / PI;
    let frame = view.frame();
    let (mut worst, mut sum_err, mut sum_want) = (0.0f64, 0.0f64, 0.0f64);
    let (mut worst_abs, mut peak) = (0.0f64, 0.0f64);
    for y in 0..view.height {
        for x in 0..view.width {
            // The pixel's mean over an 8 × 8 grid of points on the floor.
            let mut want = 0.0f64;
            for j in 0..8 {
                for i in 0..8 {
                    let d = frame.direction(
                        x as f32 + (i as f32 + 0.5) / 8.0,
                        y as f32 + (j as f32 + 0.5) / 8.0,
                    );
                    let p = frame.eye + d * (-frame.eye.z / d.z);
                    want += rho as f64 / PI * polygon_irradiance(p, Vec3::Z, &quad, l);
                }
            }
            want /= 64.0;
            let got = img.get(x, y);
            assert!((got.x - got.y).abs() < 1e-6 && (got.x - got.z).abs() < 1e-6);
            let rel = (got.x as f64 - want).abs() / want;
            worst = worst.max(rel);
            worst_abs = worst_abs.max((got.x as f64 - want).abs());
            peak = peak.max(want);
            sum_err += got.x as f64 - want;
            sum_want += want;
        }
    }
    let (peak_rel, mean) = (worst_abs / peak, sum_err / sum_want);
    println!(
        "quad over a floor, L_e {le}, B {b}, cache {}: worst pixel {:.3}% ({:.3}% of the \
         brightest), mean {:.3}%, {} of {} samples cached",
        opts.cache,
        100.0 * worst,
        100.0 * peak_rel,
        100.0 * mean,
        stats.cached,
        stats.camera_rays
    );
    (stats, worst, peak_rel, mean)
}

/// Direct light: the quad is an emitter (L_e = 2), the solution reads its exitance there, so
/// the gather rays add nothing; with and without the irradiance cache.
#[test]
fn direct_term_under_a_quad_light_is_the_polygon_irradiance() {
    let le = 2.0f32;
    for cache in [0, 2] {
        let opts = GatherOptions {
            rays: 4096,
            seed: 7,
            cache,
            ..Default::default()
        };
        let (stats, worst, _, mean) =
            quad_over_floor(le, std::f32::consts::PI * le, &opts, (10, 8));
        assert!(worst < 0.015, "worst pixel off by {:.2}%", 100.0 * worst);
        assert!(mean.abs() < 0.004, "mean off by {:.2}%", 100.0 * mean);
        // With the cache, a fair share of the samples take two emitter samples without
        // multiple importance weights.
        assert_eq!(stats.cached > stats.camera_rays / 5, cache > 0, "{stats:?}");
    }
}

/// A lamp modelled twice in the same place (a model merged with itself, the hospital's
/// `hosp.mgf`) lights the floor once, as a ray onto it sees it once: the light samples on the
/// copy that rays do not see count nowhere.
#[test]
fn a_duplicated_lamp_lights_the_floor_once() {
    let le = 2.0f32;
    let opts = GatherOptions {
        rays: 4096,
        seed: 7,
        cache: 0,
        ..Default::default()
    };
    let (_, worst, _, mean) =
        quad_over_floor_copies(le, std::f32::consts::PI * le, &opts, (10, 8), true);
    assert!(worst < 0.015, "worst pixel off by {:.2}%", 100.0 * worst);
    assert!(mean.abs() < 0.004, "mean off by {:.2}%", 100.0 * mean);
}

/// Indirect light: the quad emits nothing but the solution gives it B = 2π, so all the
/// floor's light comes through the gather rays, which vary across the floor as the polygon
/// irradiance does; the irradiance cache interpolates it, a pixel spanning 1–4 cm of floor
/// (errors measured against the brightest pixel, as ΔE*uv weighs them against white).
#[test]
fn gathered_light_from_a_bright_quad_is_the_polygon_irradiance() {
    for (cache, rays) in [(0, 4096), (2, 256), (4, 64)] {
        let opts = GatherOptions {
            rays,
            seed: 5,
            cache,
            ..Default::default()
        };
        let (stats, _, peak_rel, mean) =
            quad_over_floor(0.0, 2.0 * std::f32::consts::PI, &opts, (64, 48));
        assert!(
            peak_rel < 0.02,
            "worst pixel off by {:.2}%",
            100.0 * peak_rel
        );
        assert!(mean.abs() < 0.004, "mean off by {:.2}%", 100.0 * mean);
        if cache > 0 {
            assert!(stats.cache_points > 0);
            assert!(
                stats.cached > stats.camera_rays * 9 / 10,
                "{} of {} samples cached",
                stats.cached,
                stats.camera_rays
            );
        } else {
            assert_eq!(stats.cached, 0);
        }
    }
}

/// Adaptive sampling: a camera under a quad light (L_e = 1, ρ = 0, nothing else in view) sees
/// each pixel at L_e × the share of its footprint the quad covers (exact by a 64 × 64 grid of
/// rays to the quad's plane). The extra samples go to the outline's pixels and their
/// neighbours only, lower the error there below what twice the samples everywhere reach, and
/// leave the image unbiased.
#[test]
fn adaptive_samples_go_to_an_emitter_s_outline() {
    let (scene, mesh, _) = quad_and_floor(2.0, 1.0, std::f32::consts::PI);
    // Looking up at the quad's corner (0.5, 0.3) from below: the floor faces away.
    let view = CameraView {
        eye: Vec3::new(0.3, 0.1, 0.5),
        target: Vec3::new(0.5, 0.3, 1.0),
        up: Vec3::Y,
        fov_deg: 60.0,
        width: 48,
        height: 36,
    };
    let frame = view.frame();
    let (w, h) = (view.width as usize, view.height as usize);
    let want: Vec<f64> = (0..w * h)
        .map(|i| {
            let (x, y) = (i % w, i / w);
            let mut inside = 0u32;
            for j in 0..64 {
                for k in 0..64 {
                    let d = frame.direction(
                        x as f32 + (k as f32 + 0.5) / 64.0,
                        y as f32 + (j as f32 + 0.5) / 64.0,
                    );
                    let t = (1.0 - frame.eye.z) / d.z;
                    let p = frame.eye + d * t;
                    inside += (t > 0.0 && p.x.abs() < 0.5 && p.y.abs() < 0.3) as u32;
                }
            }
            inside as f64 / 4096.0
        })
        .collect();
    let outline: Vec<bool> = want.iter().map(|&c| c > 0.0 && c < 1.0).collect();
    assert!(outline.iter().any(|&o| o) && want.contains(&1.0));
    let near_outline = (0..w * h)
        .filter(|&i| {
            let (x, y) = (i % w, i / w);
            (y.saturating_sub(1)..(y + 2).min(h))
                .any(|yy| (x.saturating_sub(1)..(x + 2).min(w)).any(|xx| outline[yy * w + xx]))
        })
        .count() as u64;
    let run = |rays: u32, adaptive: f32| {
        let opts = GatherOptions {
            rays,
            seed: 9,
            adaptive,
            ..Default::default()
        };
        let (img, stats) = gather_stats(&scene, &mesh, &view, &opts);
        let (mut se, mut sum, mut sum_want) = (0.0f64, 0.0f64, 0.0f64);
        for (i, p) in img.pixels.iter().enumerate() {
            se += (p.x as f64 - want[i]).powi(2);
            sum += p.x as f64;
            sum_want += want[i];
        }
        ((se / (w * h) as f64).sqrt(), sum / sum_want - 1.0, stats)
    };
    let (uniform, uniform_mean, _) = run(32, 0.0);
    let (adaptive, adaptive_mean, stats) = run(16, 1.0);
    println!(
        "under a quad light: RMS error {uniform:.5} with 32 samples, {adaptive:.5} with 16 + \
         {} adaptive in {} pixels ({near_outline} on or beside the outline); mean {:.3}% / \
         {:.3}%",
        stats.adaptive_samples,
        stats.adaptive_pixels,
        100.0 * uniform_mean,
        100.0 * adaptive_mean
    );
    assert!(stats.adaptive_samples <= 16 * (w * h) as u64);
    assert!(stats.adaptive_samples > 15 * (w * h) as u64);
    assert!(stats.adaptive_pixels > 0 && stats.adaptive_pixels <= near_outline);
    assert!(adaptive < 0.6 * uniform, "{adaptive} against {uniform}");
    assert!(adaptive_mean.abs() < 0.003 && uniform_mean.abs() < 0.003);
}

/// `mesh` with radiosity `b` at every vertex.
fn uniform(mesh: &ColoredMesh, b: f32) -> ColoredMesh {
    ColoredMesh {
        colors: vec![Vec3::splat(b); mesh.colors.len()],
        ..mesh.clone()
    }
}

fn solved(name: &str, preset: &str) -> (Scene, ColoredMesh) {
    let scene = Scene::load(name, &SceneOptions::default()).unwrap();
    let tree = ClusterTree::build(&scene, Strategy::Proxi, &ClusterConfig::default());
    let cfg = SolverConfig::preset(preset).unwrap();
    let sol = solve(&scene, &tree, &cfg, &NoProgress).unwrap();
    let mesh = output::radiosity_mesh(&sol, &scene, false);
    (scene, mesh)
}

/// Furnace (ρ = 0.5, L_e = 1/π everywhere, closed): the gather of the solver's own solution
/// returns B/π = 2/π, the emitted radiance seen by the camera plus one bounce of exact direct
/// light plus ρ(B − E)/π read from the solution; with an exact solution (B = 2 on every vertex)
/// to the sampling noise, with the solver's to a quarter of its per-vertex image's error.
#[test]
fn furnace_gather_returns_the_analytic_radiosity() {
    let (scene, mesh) = solved("furnace:2", "default");
    let view = CameraView {
        width: 24,
        height: 24,
        ..CameraView::from_camera(&scene.default_camera())
    };
    let want = 2.0 / PI;
    let exact = uniform(&mesh, 2.0);
    // The gather reads ρ(B − E)/π, a quarter of the radiance, from the solution: where the
    // per-vertex image of the solver's mesh is off by e (centroid vertices of the mean-keeping
    // fit are off by up to 70% on this coarse solve), the gather is off by about e/4.
    let worst_of = |img: &Image| {
        img.pixels
            .iter()
            .map(|p| (p.x as f64 - want).abs() / want)
            .fold(0.0, f64::max)
    };
    let raster = render_solution(
        &mesh,
        &view,
        &RasterOptions {
            supersample: 4,
            ..Default::default()
        },
    )
    .unwrap();
    let raster_worst = worst_of(&raster);
    println!(
        "furnace, per-vertex image: worst pixel {:.3}%",
        100.0 * raster_worst
    );
    for (what, m, mean_tol, pixel_tol) in [
        ("exact solution", &exact, 0.002, 0.02),
        (
            "solver's solution",
            &mesh,
            0.006,
            0.015 + raster_worst / 4.0,
        ),
    ] {
        // Bright factor 0.5: every element of the uniform furnace is also sampled by area, so
        // the multiple importance sampling of gather rays and element samples is exercised.
        for (lookup, bright) in [
            (Lookup::Vertex, 0.0),
            (Lookup::Element, 0.0),
            (Lookup::Element, 0.5),
        ] {
            // Without the irradiance cache: its samples take direct light from the emitter
            // samples alone, whose 1/r² spikes in the corners this small image cannot average.
            let opts = GatherOptions {
                rays: 256,
                lookup,
                bright,
                cache: 0,
                ..Default::default()
            };
            let img = gather(&scene, m, &view, &opts);
            let mean = img.mean().x as f64;
            let worst = worst_of(&img);
            // Element samples are not stratified: noisier pixels, the same mean.
            let pixel_tol = if bright > 0.0 {
                2.5 * pixel_tol
            } else {
                pixel_tol
            };
            println!(
                "furnace, {what}, {lookup:?}, bright {bright}: mean {:.4}% off, worst pixel {:.3}%",
                100.0 * (mean - want) / want,
                100.0 * worst
            );
            assert!(
                (mean - want).abs() / want < mean_tol,
                "{what} {lookup:?} {bright}"
            );
            assert!(worst < pixel_tol, "{what} {lookup:?} {bright}");
        }
    }
}

/// One more bounce at near hits: in the furnace (ρ = 0.5, L_e = 1/π) with a solution that holds
/// the emission only (B = E = 1, no reflected light), the gather reads nothing from the
/// solution's elements, so an image is the emitted radiance plus the bounces it shades
/// exactly: L_e (1 + ρ) without near hits, L_e (1 + ρ + ρ²) when every hit is near; with the
/// exact solution (B = 2) it is B/π whatever the near factor, with bright-element samples too.
#[test]
fn near_hits_get_one_more_bounce_of_exact_light() {
    let (scene, mesh) = solved("furnace:2", "fast");
    let view = CameraView {
        width: 16,
        height: 16,
        ..CameraView::from_camera(&scene.default_camera())
    };
    let (emission_only, exact) = (uniform(&mesh, 1.0), uniform(&mesh, 2.0));
    // Bright factor 0.5 samples every element by area too: the near bounce's estimate is
    // weighted against those samples, or light would be counted twice.
    for (what, m, near, bright, want) in [
        ("emission only, no near hits", &emission_only, 0.0, 0.0, 1.5),
        (
            "emission only, every hit near",
            &emission_only,
            1e6,
            0.0,
            1.75,
        ),
        ("exact, every hit near", &exact, 1e6, 0.0, 2.0),
        (
            "exact, every hit near, bright elements",
            &exact,
            1e6,
            0.5,
            2.0,
        ),
        (
            "exact, default near",
            &exact,
            GatherOptions::default().near,
            0.0,
            2.0,
        ),
    ] {
        let opts = GatherOptions {
            rays: 256,
            bright,
            near,
            cache: 0,
            ..Default::default()
        };
        let want = want / PI;
        let mean = gather(&scene, m, &view, &opts).mean().x as f64;
        println!(
            "furnace, {what}: mean {:.4}% off",
            100.0 * (mean - want) / want
        );
        assert!(
            (mean - want).abs() / want < 0.003,
            "{what}: {mean} against {want}"
        );
    }
}

/// A double-sided lamp panel modelled as two one-sided emitters back to back (the down-facing
/// one first, so that it wins ties, and triangulated along the other diagonal) over a floor:
/// a camera above it sees the up-facing one's L_e on every pixel, not the back of the other.
#[test]
fn a_camera_ray_sees_the_face_of_coincident_faces_that_faces_it() {
    let h = 0.5f32;
    let positions = vec![
        Vec3::new(-4.0, -4.0, 0.0),
        Vec3::new(4.0, -4.0, 0.0),
        Vec3::new(4.0, 4.0, 0.0),
        Vec3::new(-4.0, 4.0, 0.0),
        Vec3::new(-h, -h, 1.0),
        Vec3::new(-h, h, 1.0),
        Vec3::new(h, h, 1.0),
        Vec3::new(h, -h, 1.0),
    ];
    let triangles = vec![
        [0, 1, 2],
        [0, 2, 3],
        [4, 5, 6],
        [4, 6, 7],
        [5, 4, 7],
        [5, 7, 6],
    ];
    let (down, up) = (Vec3::ONE, Vec3::new(2.0, 3.0, 4.0));
    let raw = RawScene {
        name: "double-sided panel".into(),
        positions: positions.clone(),
        triangles: triangles.clone(),
        tri_material: vec![0, 0, 1, 1, 2, 2],
        tri_object: vec![0; 6],
        materials: vec![
            Material::diffuse("floor", Vec3::splat(0.5)),
            Material {
                name: "down".into(),
                rho: Vec3::ZERO,
                emission: down,
            },
            Material {
                name: "up".into(),
                rho: Vec3::ZERO,
                emission: up,
            },
        ],
        up: UpAxis::Z,
        ..Default::default()
    };
    let scene = Scene::from_raw(raw, &SceneOptions::default()).unwrap();
    assert!(scene.normals[2].z < -0.99 && scene.normals[4].z > 0.99);
    let mut colors = vec![Vec3::ZERO; 4];
    colors.extend([Vec3::splat(std::f32::consts::PI); 4]);
    let mesh = ColoredMesh {
        positions,
        triangles,
        colors,
    };
    let view = CameraView {
        eye: Vec3::new(0.05, 0.02, 2.0),
        target: Vec3::new(0.05, 0.02, 0.0),
        up: Vec3::Y,
        fov_deg: 40.0,
        width: 12,
        height: 10,
    };
    let opts = GatherOptions {
        rays: 4,
        ..Default::default()
    };
    let img = gather(&scene, &mesh, &view, &opts);
    for p in &img.pixels {
        assert!((*p - up).abs().max_element() < 1e-5, "{p}");
    }
}

/// Same seed: the same image with 1 and 2 threads, bit for bit; another seed: another image.
#[test]
fn gather_is_seeded_and_thread_count_independent() {
    let (scene, mesh) = solved("cornell", "fast");
    let run = |threads: usize, seed: u64, cache: u32, (width, height): (u32, u32)| {
        let view = CameraView {
            width,
            height,
            ..CameraView::from_camera(&scene.default_camera())
        };
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        let opts = GatherOptions {
            rays: 16,
            seed,
            cache,
            ..Default::default()
        };
        pool.install(|| gather_stats(&scene, &mesh, &view, &opts))
    };
    let small = (40, 30);
    let a = run(1, 3, 0, small).0;
    let b = run(2, 3, 0, small).0;
    assert!(a.mean().x > 0.0);
    assert_eq!(a.pixels, b.pixels);
    assert_eq!(a.pixels, run(2, 3, 0, small).0.pixels);
    assert_ne!(a.pixels, run(2, 4, 0, small).0.pixels);
    // With the irradiance cache too, in an image whose blocks are small enough to be used.
    let (c, stats) = run(1, 3, 2, (160, 120));
    assert!(stats.cached > stats.camera_rays / 10, "{stats:?}");
    assert_eq!(c.pixels, run(2, 3, 2, (160, 120)).0.pixels);
}

/// A solution of another scene is refused.
#[test]
fn a_solution_of_another_scene_is_refused() {
    let (_, mesh) = solved("furnace:2", "fast");
    let scene = Scene::load("cornell", &SceneOptions::default()).unwrap();
    let tree = ClusterTree::build(&scene, Strategy::Sah, &ClusterConfig::default());
    let caster = RayCaster::new(&scene, &tree);
    let err = SolutionLookup::new(&mesh, &scene, &caster, Lookup::Vertex)
        .err()
        .expect("refused");
    assert!(err.to_string().contains("does not fit the scene"), "{err}");
}
