//! The solver against independent ground truth: a small room with an occluder (a table whose
//! shadow falls on a tiled floor) compared tile by tile with the path tracer's irradiance, at
//! the three presets, with the `error` oracle, with volume visibility and two-sided; sun and
//! sky against their closed forms; the wall behind a panel hung close in front of it.

use glam::Vec3;
use hirad::cluster::{ClusterConfig, ClusterTree, Strategy};
use hirad::progress::NoProgress;
use hirad::radiosity::{solve, Oracle, Solution, SolverConfig, VisibilityMode};
use hirad::ray::RayCaster;
use hirad::render::{PathTracer, ReferenceOptions};
use hirad::rng::SplitMix64;
use hirad::scene::{Material, Scene, Sun, UpAxis};

mod radiosity_common;
use hirad::radiosity::formfactor::sample_triangle;
use radiosity_common::{cosine_dir, face_irradiance, quads_scene, rect, Quad};

const GREY: u32 = 0;
const LAMP: u32 = 1;
/// The table top's material: `GREY`'s reflectance, two-sided on its own in
/// `per_material_sides_match_the_path_tracer`.
const TABLE: u32 = 2;
/// Floor tiles per side.
const TILES: u32 = 4;

/// Room 2 m × 2 m × 2 m (groups 0: ceiling, 1–4: walls), a lamp facing down under the
/// ceiling (5), a table top 0.8 m square at 0.7 m (6: its top; one-sided it faces up, its
/// underside is group 7 unless `two_sided`), the floor in `TILES`² tiles (groups 8…).
fn room(two_sided_table: bool) -> Scene {
    let (q, mats) = room_parts(two_sided_table);
    quads_scene(&q, mats)
}

/// The quads and materials of [`room`].
fn room_parts(two_sided_table: bool) -> (Vec<Quad>, Vec<Material>) {
    let (x, y, z) = (Vec3::X * 2.0, Vec3::Y * 2.0, Vec3::Z * 2.0);
    let o = Vec3::ZERO;
    let mut q: Vec<Quad> = vec![
        rect(o + z, y, x, GREY, 0),
        rect(o, z, x, GREY, 1),
        rect(o + y, x, z, GREY, 2),
        rect(o, y, z, GREY, 3),
        rect(o + x, z, y, GREY, 4),
        rect(
            Vec3::new(0.8, 0.8, 1.95),
            Vec3::Y * 0.4,
            Vec3::X * 0.4,
            LAMP,
            5,
        ),
        rect(
            Vec3::new(0.5, 0.6, 0.7),
            Vec3::X * 0.8,
            Vec3::Y * 0.8,
            TABLE,
            6,
        ),
    ];
    if !two_sided_table {
        q.push(rect(
            Vec3::new(0.5, 0.6, 0.7),
            Vec3::Y * 0.8,
            Vec3::X * 0.8,
            GREY,
            7,
        ));
    }
    let s = 2.0 / TILES as f32;
    for i in 0..TILES {
        for j in 0..TILES {
            let c = Vec3::new(i as f32 * s, j as f32 * s, 0.0);
            q.push(rect(c, Vec3::X * s, Vec3::Y * s, GREY, 8 + i * TILES + j));
        }
    }
    let mats = vec![
        Material::diffuse("grey", Vec3::splat(0.6)),
        Material {
            name: "lamp".into(),
            rho: Vec3::ZERO,
            emission: Vec3::splat(5.0),
        },
        Material::diffuse("table", Vec3::splat(0.6)),
    ];
    (q, mats)
}

/// Path-traced mean irradiance (red channel) over the front (or back) faces of `group`:
/// `π · mean L` over area-uniform points and cosine-distributed directions.
fn reference(scene: &Scene, pt: &PathTracer, group: u32, back: bool, n: usize) -> f64 {
    let tris: Vec<usize> = (0..scene.num_triangles())
        .filter(|&t| scene.tri_object[t] == group)
        .collect();
    let mut rng = SplitMix64::new(group as u64 * 2 + back as u64);
    let mut sum = 0.0;
    for k in 0..n {
        let t = tris[k % tris.len()];
        let v = scene.tri_vertices(t);
        let nrm = if back {
            -scene.normals[t]
        } else {
            scene.normals[t]
        };
        let p = sample_triangle(&v, rng.next_f32(), rng.next_f32());
        let d = cosine_dir(nrm, rng.next_f32(), rng.next_f32());
        sum += pt.radiance(p + nrm * 1e-4, d, &mut rng).x as f64;
    }
    std::f64::consts::PI * sum / n as f64
}

/// The faces compared: every group but the lamp, with the table's underside as its own group
/// or as the back of the two-sided table top.
fn faces(two_sided: bool) -> Vec<(u32, bool)> {
    let mut f: Vec<(u32, bool)> = (0..5).map(|g| (g, false)).collect();
    f.push((6, false));
    f.push(if two_sided { (6, true) } else { (7, false) });
    f.extend((8..8 + TILES * TILES).map(|g| (g, false)));
    f
}

/// Path-traced irradiance of every compared face (the table's back when `two_sided` or when
/// the scene makes its material two-sided).
fn references(scene: &Scene, tree: &ClusterTree, two_sided: bool) -> Vec<f64> {
    let caster = RayCaster::new(scene, tree);
    let opts = ReferenceOptions {
        two_sided,
        ..Default::default()
    };
    let pt = PathTracer::new(scene, &caster, &opts);
    faces(two_sided || scene.two_sided_materials[TABLE as usize])
        .iter()
        .map(|&(g, b)| reference(scene, &pt, g, b, 200_000))
        .collect()
}

/// Relative error of a solution over the compared faces: `Σ |H − H_ref| / Σ H_ref`.
fn error(sol: &Solution, scene: &Scene, refs: &[f64], two_sided: bool) -> f64 {
    let (mut num, mut den) = (0.0, 0.0);
    for (&(g, b), r) in faces(two_sided).iter().zip(refs) {
        if std::env::var_os("GT_FACES").is_some() {
            eprintln!(
                "  face {g} back {b}: solver {:.3} path tracer {r:.3}",
                face_irradiance(sol, scene, g, b)
            );
        }
        num += (face_irradiance(sol, scene, g, b) - r).abs();
        den += r;
    }
    num / den
}

fn solve_with(scene: &Scene, tree: &ClusterTree, cfg: SolverConfig) -> Solution {
    solve(scene, tree, &cfg, &NoProgress).unwrap()
}

#[test]
fn presets_converge_towards_the_path_tracer() {
    let scene = room(false);
    let tree = ClusterTree::build(&scene, Strategy::Proxi, &ClusterConfig::default());
    let refs = references(&scene, &tree, false);
    let errs: Vec<f64> = ["fast", "default", "fine"]
        .iter()
        .map(|p| {
            let sol = solve_with(&scene, &tree, SolverConfig::preset(p).unwrap());
            error(&sol, &scene, &refs, false)
        })
        .collect();
    eprintln!("error against the path tracer, fast/default/fine: {errs:.4?}");
    // The references' own noise is about 1%: default and fine agree within it.
    assert!(
        errs[1] < errs[0] && errs[2] < errs[0],
        "fast is the closest: {errs:?}"
    );
    assert!(
        errs[1] < 0.045 && errs[2] < 0.045,
        "default, fine: {errs:?}"
    );
}

#[test]
fn error_oracle_volume_visibility_and_two_sided_match_the_path_tracer() {
    let scene = room(false);
    let tree = ClusterTree::build(&scene, Strategy::Kdt, &ClusterConfig::default());
    let refs = references(&scene, &tree, false);
    let err = |cfg: SolverConfig| error(&solve_with(&scene, &tree, cfg), &scene, &refs, false);
    let e_error = err(SolverConfig {
        refine: Oracle::Error,
        ..Default::default()
    });
    let e_volume = err(SolverConfig {
        visibility: VisibilityMode::Volume,
        ..Default::default()
    });
    // The table as one two-sided quad: its back face is the underside.
    let scene2 = room(true);
    let tree2 = ClusterTree::build(&scene2, Strategy::Kdt, &ClusterConfig::default());
    let refs2 = references(&scene2, &tree2, true);
    let sol2 = solve_with(
        &scene2,
        &tree2,
        SolverConfig {
            two_sided: true,
            ..Default::default()
        },
    );
    let e_two = error(&sol2, &scene2, &refs2, true);
    eprintln!("error against the path tracer: error oracle {e_error:.4}, volume {e_volume:.4}, two-sided {e_two:.4}");
    assert!(e_error < 0.05, "error oracle: {e_error}");
    assert!(e_volume < 0.05, "volume visibility: {e_volume}");
    assert!(e_two < 0.05, "two-sided: {e_two}");
}

#[test]
fn sun_and_sky_match_their_closed_forms() {
    // A floor square facing up and, 9 m away, a wall square facing the sun's azimuth; both
    // black (ρ = 0), so the irradiance is the direct part alone.
    let black = Material::diffuse("black", Vec3::ZERO);
    let (x, y, z) = (Vec3::X, Vec3::Y, Vec3::Z);
    let q = vec![
        rect(Vec3::ZERO, x, y, 0, 0),
        rect(Vec3::new(10.0, 0.0, 0.0), z, y, 0, 1),
    ];
    let mut scene = quads_scene(&q, vec![black]);
    scene.up = UpAxis::Z;
    let elev = 40f32.to_radians();
    // Towards the sun: elevation 40°, azimuth along −x (the wall faces −x).
    let s = Vec3::new(-elev.cos(), 0.0, elev.sin());
    let (e_sun, l_sky) = (800.0f32, 20.0f32);
    scene.sun = Some(Sun {
        direction: s,
        irradiance: Vec3::splat(e_sun),
    });
    scene.sky = Some(Vec3::splat(l_sky));
    let tree = ClusterTree::build(&scene, Strategy::Proxi, &ClusterConfig::default());
    let sol = solve_with(
        &scene,
        &tree,
        SolverConfig {
            sky_rays: 256,
            ..Default::default()
        },
    );
    let pi = std::f64::consts::PI;
    let floor = face_irradiance(&sol, &scene, 0, false);
    let wall = face_irradiance(&sol, &scene, 1, false);
    let want_floor = e_sun as f64 * elev.sin() as f64 + pi * l_sky as f64;
    // A vertical surface sees the upper half of its hemisphere: π·L/2.
    let want_wall = e_sun as f64 * elev.cos() as f64 + pi * l_sky as f64 / 2.0;
    eprintln!("floor {floor:.2} (closed form {want_floor:.2}), wall {wall:.2} ({want_wall:.2})");
    assert!(
        (floor / want_floor - 1.0).abs() < 0.01,
        "floor {floor} vs {want_floor}"
    );
    assert!(
        (wall / want_wall - 1.0).abs() < 0.03,
        "wall {wall} vs {want_wall}"
    );
}

#[test]
fn per_material_sides_match_the_path_tracer() {
    // Only the table's material is two-sided (as MGF `sides 2` among `sides 1` materials):
    // its back face is the underside, the walls keep no back face, without `two_sided`.
    let mut scene = room(true);
    scene.two_sided_materials[TABLE as usize] = true;
    let tree = ClusterTree::build(&scene, Strategy::Proxi, &ClusterConfig::default());
    let refs = references(&scene, &tree, false);
    let sol = solve_with(&scene, &tree, SolverConfig::default());
    let e = error(&sol, &scene, &refs, true);
    let el = &sol.elements;
    let mut table_back = 0.0;
    for t in 0..scene.num_triangles() {
        let back = el.first_root + el.num_tris + t as u32;
        let dead = el.is_dead(back);
        assert_eq!(dead, scene.tri_object[t] != 6, "triangle {t}'s back");
        if dead {
            // No back face: nothing is linked to it, it reflects nothing.
            assert_eq!(el.b[back as usize], glam::DVec3::ZERO, "triangle {t}");
        } else {
            table_back += el.b[back as usize].x;
        }
    }
    eprintln!("per-material sides: error against the path tracer {e:.4}, table underside B {table_back:.4}");
    assert!(
        table_back > 0.0,
        "the table's underside is lit from the floor"
    );
    assert!(e < 0.05, "per-material sides: {e}");
}

/// Mean irradiance (red channel) over `n` points of the wall at x = 0 (group 3, facing +x)
/// drawn uniformly where `keep(y, z)`: the solver's leaf at each point, and the path tracer's
/// `π · L` over a cosine direction there.
fn wall_irradiance(
    sol: &Solution,
    scene: &Scene,
    pt: &PathTracer,
    keep: impl Fn(f32, f32) -> bool,
    n: usize,
) -> (f64, f64) {
    let el = &sol.elements;
    let tris: Vec<u32> = (0..scene.num_triangles() as u32)
        .filter(|&t| scene.tri_object[t as usize] == 3)
        .collect();
    let mut rng = SplitMix64::new(0x3A11);
    let (mut solver, mut path, mut k) = (0.0, 0.0, 0);
    while k < n {
        let p = Vec3::new(0.0, 2.0 * rng.next_f32(), 2.0 * rng.next_f32());
        if !keep(p.y, p.z) {
            continue;
        }
        k += 1;
        // The root triangle holding p, then its leaf there.
        let t = tris
            .iter()
            .copied()
            .find(|&t| {
                let v = scene.tri_vertices(t as usize);
                let c = |a: Vec3, b: Vec3| (b - a).cross(p - a).x >= -1e-6;
                c(v[0], v[1]) && c(v[1], v[2]) && c(v[2], v[0])
            })
            .expect("a wall triangle holds the point");
        let leaf = el.leaf_at(el.first_root + t, p);
        let e = &el.elems[leaf as usize];
        solver += (el.b[leaf as usize].x - e.emission.x as f64) / e.rho.x as f64;
        let d = cosine_dir(Vec3::X, rng.next_f32(), rng.next_f32());
        path += std::f64::consts::PI * pt.radiance(p + Vec3::X * 1e-4, d, &mut rng).x as f64;
    }
    (solver / n as f64, path / n as f64)
}

/// The hung-panel scene of the test below.
fn hung_panel() -> Scene {
    let (mut q, mats) = room_parts(false);
    let o = Vec3::new(0.03, 0.5, 0.5);
    q.push(rect(o, Vec3::Y, Vec3::Z, GREY, 24));
    q.push(rect(o, Vec3::Z, Vec3::Y, GREY, 25));
    quads_scene(&q, mats)
}

#[test]
fn surface_links_deliver_what_monte_carlo_finds_between_their_ends() {
    // Every link between two surfaces, its delivered power (receiver area × open fraction ×
    // K·B) against Monte Carlo between its ends with exact visibility and the radiosity of
    // the source leaf each sample lands on, summed. On the hung panel many links are split
    // or kept on the outcome of their own rays; a kept link keeping the outcome it was
    // chosen for (all its rays open, or all blocked) delivers 0.4% too much in all (256
    // samples per link: three seeds of the sum agree within 0.02%).
    use hirad::radiosity::element::Kind;
    use hirad::radiosity::overlap::Covers;
    use rayon::prelude::*;
    let scene = hung_panel();
    let tree = ClusterTree::build(&scene, Strategy::Proxi, &ClusterConfig::default());
    let sol = solve_with(&scene, &tree, SolverConfig::default());
    let caster = RayCaster::new(&scene, &tree);
    let covers = Covers::build(&scene, &tree, false);
    let el = &sol.elements;
    let (got, want): (f64, f64) = sol
        .links
        .links
        .par_iter()
        .enumerate()
        .filter(|(_, l)| {
            el.elems[l.recv as usize].kind == Kind::Surface
                && el.elems[l.src as usize].kind == Kind::Surface
        })
        .map(|(i, l)| {
            let (re, se) = (&el.elems[l.recv as usize], &el.elems[l.src as usize]);
            let got = re.area as f64
                * el.open[l.recv as usize] as f64
                * sol.links.gather(l, el).element_sum();
            let mut leaves = Vec::new();
            el.leaves_of(l.src, &mut leaves);
            let cdf: Vec<f64> = leaves
                .iter()
                .scan(0.0, |a, &s| {
                    *a += el.elems[s as usize].area as f64;
                    Some(*a)
                })
                .collect();
            let src_area = se.area as f64;
            let mut rng = SplitMix64::new(i as u64 * 977 + 5);
            let n = 256;
            let mut acc = 0.0;
            for _ in 0..n {
                let x = sample_triangle(&re.verts, rng.next_f32(), rng.next_f32());
                let u = rng.next_f64() * cdf[cdf.len() - 1];
                let sid = leaves[cdf.partition_point(|&c| c < u).min(leaves.len() - 1)];
                let es = &el.elems[sid as usize];
                let y = sample_triangle(&es.verts, rng.next_f32(), rng.next_f32());
                let d = y - x;
                let r2 = d.length_squared();
                let w = d / r2.sqrt();
                let (cx, cy) = (re.normal.dot(w), -es.normal.dot(w));
                if cx <= 0.0
                    || cy <= 0.0
                    || covers.covered(re.tri, re.normal, x)
                    || covers.covered(es.tri, es.normal, y)
                {
                    continue;
                }
                let (a, b) = (x + re.normal * 2e-6, y + es.normal * 2e-6);
                let t = b - a;
                let tl = t.length();
                if caster.occluded(a, t / tl, 0.0, tl * (1.0 - 1e-5)) {
                    continue;
                }
                let g = (cx * cy) as f64 / (std::f64::consts::PI * r2 as f64) * src_area;
                acc += el.b[sid as usize].element_sum() * g;
            }
            (got, re.area as f64 * acc / n as f64)
        })
        .reduce(|| (0.0, 0.0), |a, b| (a.0 + b.0, a.1 + b.1));
    eprintln!("surface links: delivered {got:.4} W, Monte Carlo {want:.4} W");
    assert!(
        (got / want - 1.0).abs() < 0.0025,
        "delivered {got} against Monte Carlo {want}"
    );
}

#[test]
#[ignore = "issue 19, not met: behind the panel the solver is off by 5.2% of the open wall's \
            irradiance (the target is 5%), where the path tracer finds 0.5%"]
fn the_wall_behind_a_hung_panel_gets_only_what_comes_through_the_gap() {
    // A 1 m panel hung 3 cm in front of the 2 m wall at x = 0, like a mirror in its frame: its
    // front faces the room, its back faces the wall. The wall is two big triangles whose links
    // straddle the panel's outline; the panel's back lights the wall behind it, but it is dark
    // (lit only through the gap), so its open rays must not draw the room's light there.
    let scene = hung_panel();
    let tree = ClusterTree::build(&scene, Strategy::Proxi, &ClusterConfig::default());
    let sol = solve_with(&scene, &tree, SolverConfig::default());
    let caster = RayCaster::new(&scene, &tree);
    let pt = PathTracer::new(&scene, &caster, &ReferenceOptions::default());
    // Behind the panel, 10 cm in from its edges; in the open, 10 cm out from them.
    let inside = |a: f32| (0.6..1.4).contains(&a);
    let outside = |a: f32| !(0.4..1.6).contains(&a);
    let hidden = wall_irradiance(&sol, &scene, &pt, |y, z| inside(y) && inside(z), 40_000);
    let open = wall_irradiance(&sol, &scene, &pt, |y, z| outside(y) || outside(z), 40_000);
    eprintln!(
        "wall irradiance, solver / path tracer: behind the panel {:.4} / {:.4}, in the open \
         {:.4} / {:.4}",
        hidden.0, hidden.1, open.0, open.1
    );
    assert!(
        (hidden.0 - hidden.1).abs() < 0.05 * open.1,
        "behind the panel: {hidden:?}, open: {open:?}"
    );
    assert!(
        (open.0 / open.1 - 1.0).abs() < 0.05,
        "in the open: {open:?}"
    );
}
