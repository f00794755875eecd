//! Analytic checks of the solver (spec/radiosity.md correctness tests 2, 3 and 6): form
//! factors of unit squares, reciprocity, energy conservation, thread independence, and the
//! no-light case.

mod radiosity_common;

use glam::Vec3;
use hirad::progress::NoProgress;
use hirad::radiosity::{solve, SolverConfig, VisibilityMode};
use hirad::rng::SplitMix64;
use hirad::scene::{Material, RawScene, Scene, SceneOptions};
use radiosity_common::*;

fn fine_config() -> SolverConfig {
    SolverConfig {
        eps: Some(2e-3),
        min_area: Some(2e-4),
        shadow_rays: 4,
        ..SolverConfig::default()
    }
}

#[test]
fn parallel_unit_squares_form_factor() {
    // Receiver at z = 0 facing up, emitter (E = 1) at z = 1 facing down.
    let scene = quads_scene(
        &[square_z(0.0, true, 0, 0), square_z(1.0, false, 1, 1)],
        vec![Material::diffuse("black", Vec3::ZERO), emitter()],
    );
    let tree = tree_by_object(&scene);
    let sol = solve(&scene, &tree, &fine_config(), &NoProgress).unwrap();
    let f = group_irradiance(&sol, &scene, 0);
    println!(
        "parallel squares: F = {f:.5} (exact 0.19982), {} links, {} elements",
        sol.stats.links, sol.stats.elements
    );
    assert!((f - 0.19982).abs() < 0.01 * 0.19982, "F = {f}");
}

#[test]
fn perpendicular_unit_squares_form_factor() {
    // Receiver z = 0 facing +z; emitter in the plane y = 0 facing +y, sharing the edge y=z=0.
    let wall = Quad {
        p: [
            Vec3::new(0.0, 0.0, 0.0),
            Vec3::new(0.0, 0.0, 1.0),
            Vec3::new(1.0, 0.0, 1.0),
            Vec3::new(1.0, 0.0, 0.0),
        ],
        mat: 1,
        group: 1,
    };
    let scene = quads_scene(
        &[square_z(0.0, true, 0, 0), wall],
        vec![Material::diffuse("black", Vec3::ZERO), emitter()],
    );
    assert!(scene.normals[2].y > 0.99);
    let tree = tree_by_object(&scene);
    let sol = solve(&scene, &tree, &fine_config(), &NoProgress).unwrap();
    let f = group_irradiance(&sol, &scene, 0);
    println!(
        "perpendicular squares: F = {f:.5} (exact 0.20004), {} links",
        sol.stats.links
    );
    assert!((f - 0.20004).abs() < 0.01 * 0.20004, "F = {f}");
}

/// Two random triangles, one emitting E = 1, both black; returns A_recv · F_recv→emitter.
fn transfer(scene_tris: &[[Vec3; 3]; 2], emitting: usize) -> f64 {
    let mut raw = RawScene {
        name: "pair".into(),
        materials: vec![Material::diffuse("black", Vec3::ZERO), emitter()],
        objects: vec!["a".into(), "b".into()],
        ..Default::default()
    };
    for (k, t) in scene_tris.iter().enumerate() {
        let b = raw.positions.len() as u32;
        raw.positions.extend_from_slice(t);
        raw.triangles.push([b, b + 1, b + 2]);
        raw.tri_material.push(if k == emitting { 1 } else { 0 });
        raw.tri_object.push(k as u32);
    }
    let scene = Scene::from_raw(raw, &SceneOptions::default()).unwrap();
    let tree = tree_by_object(&scene);
    let cfg = SolverConfig {
        eps: Some(1e-4),
        min_area: Some(scene.total_area() * 2e-4),
        shadow_levels: 0,
        visibility: VisibilityMode::None,
        ..SolverConfig::default()
    };
    let sol = solve(&scene, &tree, &cfg, &NoProgress).unwrap();
    let r = 1 - emitting;
    scene.areas[r] as f64 * sol.triangle_irradiance(r as u32, false).x
}

#[test]
fn reciprocity_on_random_pairs() {
    let mut rng = SplitMix64::new(7);
    let mut rp = || Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 2.0;
    let mut tested = 0;
    let mut worst: f64 = 0.0;
    while tested < 8 {
        let t0 = [rp(), rp(), rp()];
        let mut t1 = [rp(), rp(), rp()];
        for p in &mut t1 {
            p.z += 1.5;
        }
        let n0 = (t0[1] - t0[0]).cross(t0[2] - t0[0]);
        let n1 = (t1[1] - t1[0]).cross(t1[2] - t1[0]);
        // Skip slivers; make the pair face each other so that the exchange is not zero.
        if n0.length() < 0.3 || n1.length() < 0.3 {
            continue;
        }
        let mut tris = [t0, t1];
        if n0.z < 0.0 {
            tris[0].swap(1, 2);
        }
        if n1.z > 0.0 {
            tris[1].swap(1, 2);
        }
        let a = transfer(&tris, 1);
        let b = transfer(&tris, 0);
        if a.max(b) < 1e-3 {
            continue;
        }
        let rel = (a - b).abs() / a.max(b);
        println!("pair {tested}: A0 F01 = {a:.6}, A1 F10 = {b:.6}, rel diff {rel:.2e}");
        worst = worst.max(rel);
        tested += 1;
    }
    assert!(worst < 5e-3, "reciprocity error {worst}");
}

/// A room-like open scene: floor, two walls, a ceiling light, an open side.
fn open_scene() -> Scene {
    let wall_a = Quad {
        p: [
            Vec3::new(0.0, 0.0, 0.0),
            Vec3::new(0.0, 0.0, 1.0),
            Vec3::new(1.0, 0.0, 1.0),
            Vec3::new(1.0, 0.0, 0.0),
        ],
        mat: 0,
        group: 1,
    };
    let wall_b = Quad {
        p: [
            Vec3::new(0.0, 0.0, 0.0),
            Vec3::new(0.0, 1.0, 0.0),
            Vec3::new(0.0, 1.0, 1.0),
            Vec3::new(0.0, 0.0, 1.0),
        ],
        mat: 2,
        group: 2,
    };
    let mut light = square_z(1.0, false, 1, 3);
    for p in &mut light.p {
        *p = Vec3::new(0.3 + p.x * 0.4, 0.3 + p.y * 0.4, p.z);
    }
    quads_scene(
        &[square_z(0.0, true, 0, 0), wall_a, wall_b, light],
        vec![
            Material::diffuse("grey", Vec3::splat(0.6)),
            emitter(),
            Material::diffuse("red", Vec3::new(0.8, 0.2, 0.1)),
        ],
    )
}

#[test]
fn energy_balance_open_scene() {
    let scene = open_scene();
    let tree = tree_by_object(&scene);
    let cfg = SolverConfig {
        eps: Some(5e-3),
        tol_converge: 1e-7,
        ..SolverConfig::default()
    };
    let sol = solve(&scene, &tree, &cfg, &NoProgress).unwrap();
    let p = &sol.stats.power;
    let rel = (p.absorbed + p.escaping - p.emitted).abs() / p.emitted;
    println!(
        "open scene: emitted {:.6} absorbed {:.6} escaping {:.6} rel {rel:.2e}",
        p.emitted, p.absorbed, p.escaping
    );
    assert!(sol.stats.converged);
    assert!(rel < 1e-3, "balance {rel}");
    // Emitted power: 0.16 m² × E = 1 per channel.
    assert!((p.emitted - 3.0 * 0.16).abs() < 1e-5, "{}", p.emitted);
    assert!(p.escaping > 0.1 * p.emitted, "an open room loses power");
}

#[test]
fn closed_box_loses_nothing() {
    // In a closed box nothing escapes: absorbed = emitted. Only one triangle emits, so the
    // balance depends on the reciprocity of every kernel. With every element linked at the
    // same level (tiny ε, min-area bound) the only error left is kernel sampling noise;
    // with mixed levels, piecewise-constant radiosity adds HR's discretisation error
    // (printed for information).
    let mut scene = Scene::load("furnace:2", &SceneOptions::default()).unwrap();
    scene
        .materials
        .push(Material::diffuse("wall", Vec3::splat(0.7)));
    let wall = (scene.materials.len() - 1) as u32;
    for t in 1..scene.num_triangles() {
        scene.tri_material[t] = wall;
    }
    let tree = tree_by_object(&scene);
    let mut errs = Vec::new();
    for eps in [1e-9, 1e-2] {
        let cfg = SolverConfig {
            eps: Some(eps),
            min_area: Some(0.01),
            // Every element at the same level: nothing below the minimum area.
            shadow_levels: 0,
            tol_converge: 1e-7,
            max_iters: 200,
            ..SolverConfig::default()
        };
        let sol = solve(&scene, &tree, &cfg, &NoProgress).unwrap();
        let p = &sol.stats.power;
        let rel = (p.absorbed - p.emitted).abs() / p.emitted;
        println!(
            "closed box eps {eps:.0e}: links {} emitted {:.6} absorbed {:.6} escaping {:.2e} \
             |absorbed - emitted| / emitted = {rel:.2e}",
            sol.stats.links, p.emitted, p.absorbed, p.escaping
        );
        assert!((p.absorbed + p.escaping - p.emitted).abs() < 1e-3 * p.emitted);
        errs.push(rel);
    }
    assert!(errs[0] < 1e-2, "closed box loses {}", errs[0]);
}

#[test]
fn same_solution_with_1_and_2_threads() {
    let scene = open_scene();
    let tree = tree_by_object(&scene);
    let cfg = SolverConfig {
        eps: Some(1e-2),
        ..SolverConfig::default()
    };
    let run = |n: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(n)
            .build()
            .unwrap();
        pool.install(|| solve(&scene, &tree, &cfg, &NoProgress).unwrap())
    };
    let a = run(1);
    let b = run(2);
    assert_eq!(a.stats.links, b.stats.links);
    assert_eq!(a.stats.elements, b.stats.elements);
    assert_eq!(a.stats.rays, b.stats.rays);
    assert_eq!(
        a.elements.b, b.elements.b,
        "radiosity differs between thread counts"
    );
    println!("1 vs 2 threads: {} elements identical", a.elements.b.len());
}

#[test]
fn no_emitter_gives_zero_and_says_so() {
    let scene = quads_scene(
        &[square_z(0.0, true, 0, 0), square_z(1.0, false, 0, 1)],
        vec![Material::diffuse("grey", Vec3::splat(0.5))],
    );
    let tree = tree_by_object(&scene);
    let sol = solve(&scene, &tree, &SolverConfig::default(), &NoProgress).unwrap();
    assert!(sol.stats.no_light);
    assert!(sol.stats.warnings.iter().any(|w| w.contains("no light")));
    assert!(sol.elements.b.iter().all(|b| *b == glam::DVec3::ZERO));
    assert_eq!(sol.stats.power.emitted, 0.0);
}

#[test]
fn memory_budget_stops_refinement() {
    let scene = open_scene();
    let tree = tree_by_object(&scene);
    let base = SolverConfig {
        eps: Some(1e-3),
        ..SolverConfig::default()
    };
    let free = solve(&scene, &tree, &base, &NoProgress).unwrap();
    // The budget holds the fixed part (scene, tree, process) and a quarter of what the
    // unbounded solve added to it.
    let fixed = free.stats.memory.fixed_bytes;
    assert!(fixed > 0 && fixed < free.stats.memory.peak_counted_bytes);
    let budget = fixed + (free.stats.memory.peak_counted_bytes - fixed) / 4;
    let cfg = SolverConfig {
        max_memory: Some(budget),
        ..base
    };
    let capped = solve(&scene, &tree, &cfg, &NoProgress).unwrap();
    let m = &capped.stats.memory;
    println!(
        "budget {budget} B: links {} (free {}), peak counted {} B (free {} B)",
        capped.stats.links,
        free.stats.links,
        m.peak_counted_bytes,
        free.stats.memory.peak_counted_bytes
    );
    assert!(!free.stats.memory.budget_hit);
    assert!(m.budget_hit);
    assert!(capped
        .stats
        .warnings
        .iter()
        .any(|w| w.contains("memory budget")));
    assert!(capped.stats.links < free.stats.links);
    // Refinement projects the later peaks (gather, push-pull, output) before it grows.
    assert!(
        m.peak_counted_bytes <= budget,
        "{} > {budget}",
        m.peak_counted_bytes
    );
    assert_eq!(m.fixed_bytes, fixed);
    // Still a converged, energy-consistent solution.
    assert!(capped.stats.converged);
    let p = &capped.stats.power;
    assert!((p.absorbed + p.escaping - p.emitted).abs() < 1e-3 * p.emitted);
}

/// A budget below the fixed part (scene, tree, ray layout, process) fails before refinement
/// with an input error naming the size needed.
#[test]
fn memory_budget_below_the_scene_is_an_error() {
    let scene = open_scene();
    let tree = tree_by_object(&scene);
    let cfg = SolverConfig {
        max_memory: Some(1_000_000),
        ..SolverConfig::default()
    };
    let e = solve(&scene, &tree, &cfg, &NoProgress).unwrap_err();
    assert!(matches!(e, hirad::Error::Budget(_)), "{e}");
    assert!(e.is_input());
    let msg = e.to_string();
    assert!(msg.contains("--max-memory 1 MB is below the"), "{msg}");
}

#[test]
fn a_small_receiver_takes_the_source_radiosity_where_it_sees_it() {
    // A lamp (E = 1, 0.5 m square at z = 0.5, facing down) lights a 4 m grey floor (ρ = 0.5)
    // in a bright spot; a small black receiver hangs beside the spot, facing down (2 cm
    // square at z = 0.3 over x = 0.9). The floor is two triangles of 8 m², subdivided under
    // the lamp: a link from a coarse floor element that carried the element's mean radiosity
    // would give the receiver the floor's average instead of the bright spot below it. Ground
    // truth by quadrature: the floor's radiosity is ρ times the lamp's unoccluded form factor
    // (the receiver's own shadow is 4 cm² of floor), the receiver's irradiance the floor's
    // radiosity over the point-to-point kernel, at 6 × 6 receiver points and 1 cm cells.
    use hirad::radiosity::formfactor::point_to_polygon;
    use std::f64::consts::PI;
    let floor = rect(
        Vec3::new(-2.0, -2.0, 0.0),
        Vec3::X * 4.0,
        Vec3::Y * 4.0,
        0,
        0,
    );
    let lamp = rect(
        Vec3::new(0.25, 0.25, 0.5),
        Vec3::Y * 0.5,
        Vec3::X * 0.5,
        1,
        1,
    );
    let (x0, y0, z0, side) = (0.9f64, 0.49f64, 0.3f64, 0.02f64);
    let recv = rect(
        Vec3::new(x0 as f32, y0 as f32, z0 as f32),
        Vec3::Y * side as f32,
        Vec3::X * side as f32,
        2,
        2,
    );
    let scene = quads_scene(
        &[floor, lamp, recv],
        vec![
            Material::diffuse("grey", Vec3::splat(0.5)),
            emitter(),
            Material::diffuse("black", Vec3::ZERO),
        ],
    );
    let lamp_poly: Vec<glam::DVec3> = [(0.25, 0.25), (0.25, 0.75), (0.75, 0.75), (0.75, 0.25)]
        .iter()
        .map(|&(x, y)| glam::DVec3::new(x, y, 0.5))
        .collect();
    let h = 0.01;
    let cells_per_side = (4.0 / h) as usize;
    let cells: Vec<(f64, f64, f64)> = (0..cells_per_side * cells_per_side)
        .map(|k| {
            let x = -2.0 + (k / cells_per_side) as f64 * h + h / 2.0;
            let y = -2.0 + (k % cells_per_side) as f64 * h + h / 2.0;
            let f = point_to_polygon(
                glam::DVec3::new(x, y, 0.0),
                glam::DVec3::Z,
                &lamp_poly,
                -glam::DVec3::Z,
            );
            (x, y, 0.5 * f)
        })
        .collect();
    let m = 6;
    let mut exact = 0.0;
    for i in 0..m {
        for j in 0..m {
            let p = glam::DVec3::new(
                x0 + (i as f64 + 0.5) / m as f64 * side,
                y0 + (j as f64 + 0.5) / m as f64 * side,
                z0,
            );
            exact += cells
                .iter()
                .map(|&(x, y, b)| {
                    let r2 = glam::DVec3::new(x, y, 0.0).distance_squared(p);
                    b * z0 * z0 / (PI * r2 * r2) * h * h
                })
                .sum::<f64>();
        }
    }
    exact /= (m * m) as f64;
    let tree = tree_by_object(&scene);
    let cfg = SolverConfig {
        shadow_rays: 16,
        ..SolverConfig::default()
    };
    let sol = solve(&scene, &tree, &cfg, &NoProgress).unwrap();
    let got = group_irradiance(&sol, &scene, 2);
    println!(
        "receiver beside the bright spot: H = {got:.5}, quadrature {exact:.5}, ratio {:.4}; {} links",
        got / exact,
        sol.stats.links
    );
    assert!((got / exact - 1.0).abs() < 0.02, "H = {got}, exact {exact}");
}
