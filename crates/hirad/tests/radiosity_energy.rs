//! Energy audit against independent ray casting, for every clustering strategy:
//! - the power each surface gathers in the first iteration (from the emitters alone) equals
//!   what rays shot from the emitters deliver to it;
//! - the escaping power of a solution (its emitted − absorbed: what no front face gathers)
//!   equals the power that rays shot from its leaves (cosine-distributed, weighted by `A·B`)
//!   carry out of the scene or onto the backs of one-sided surfaces.
//!
//! The room has the configurations that made kernels over- or under-count: a lamp 5 cm below
//! the ceiling facing it (near field), a poster lying on a wall (coplanar overlap), a table
//! and clutter. `ENERGY_TABLE=1` prints the ratios of every strategy.

use glam::Vec3;
use hirad::cluster::{ClusterConfig, ClusterTree, Strategy};
use hirad::progress::NoProgress;
use hirad::radiosity::{solve, SolverConfig};
use hirad::ray::RayCaster;
use hirad::rng::SplitMix64;
use hirad::scene::{Material, Scene};

mod radiosity_common;
use hirad::radiosity::formfactor::sample_triangle;
use radiosity_common::{box_inward, cosine_dir, quads_scene, rect, Quad};

const WALL: u32 = 0;
const LAMP: u32 = 1;
const POSTER: u32 = 2;

/// Groups: 0–5 the room (floor, ceiling, y = 0, y = 3, x = 0, x = 4), 6 the lamp, 7 the
/// poster on the x = 0 wall, 8 the table, 9 clutter. `open`: no x = 4 wall.
fn room(open: bool) -> Scene {
    let (lo, hi) = (Vec3::ZERO, Vec3::new(4.0, 3.0, 2.5));
    let mut q: Vec<Quad> = box_inward(lo, hi, WALL, 0);
    if open {
        q.pop();
    }
    let (x, y) = (Vec3::X, Vec3::Y);
    // Lamp strip 1.2 m × 0.1 m, 5 cm below the ceiling, facing it.
    q.push(rect(Vec3::new(1.4, 1.45, 2.45), x * 1.2, y * 0.1, LAMP, 6));
    // Poster in the plane of the x = 0 wall, facing +x.
    let z = Vec3::Z;
    q.push(rect(Vec3::new(0.0, 1.0, 1.0), y * 0.8, z * 0.6, POSTER, 7));
    // Table top, both faces.
    q.push(rect(Vec3::new(2.0, 0.5, 0.75), x * 1.2, y * 0.8, WALL, 8));
    q.push(rect(Vec3::new(2.0, 0.5, 0.75), y * 0.8, x * 1.2, WALL, 8));
    let mut rng = SplitMix64::new(3);
    for _ in 0..40 {
        let mut r = || rng.next_f32();
        let c = Vec3::new(0.5 + 3.0 * r(), 0.5 + 2.0 * r(), 0.2 + 1.8 * r());
        let u = Vec3::new(r() - 0.5, r() - 0.5, r() - 0.5).normalize() * 0.15;
        let w = Vec3::new(r() - 0.5, r() - 0.5, r() - 0.5).normalize() * 0.15;
        q.push(rect(c, u, w, WALL, 9));
    }
    let mats = vec![
        Material::diffuse("wall", Vec3::splat(0.7)),
        Material {
            name: "lamp".into(),
            rho: Vec3::ZERO,
            emission: Vec3::splat(10.0),
        },
        Material::diffuse("poster", Vec3::new(0.6, 0.3, 0.2)),
    ];
    quads_scene(&q, mats)
}

/// Shoot `n` rays carrying the powers (channel sums) of the triangles `srcs` (geometry, normal,
/// power) and return the power arriving on the front of each group, and the power no front
/// face receives: leaving the scene, or absorbed by the back of a one-sided surface.
fn shoot(
    scene: &Scene,
    caster: &RayCaster,
    srcs: &[([Vec3; 3], Vec3, f64)],
    n: usize,
) -> (Vec<f64>, f64) {
    let total: f64 = srcs.iter().map(|s| s.2).sum();
    let mut cdf = Vec::with_capacity(srcs.len());
    let mut acc = 0.0;
    for s in srcs {
        acc += s.2;
        cdf.push(acc);
    }
    let mut groups = vec![0.0; scene.objects.len()];
    let mut out = 0.0;
    let mut rng = SplitMix64::new(17);
    let w = total / n as f64;
    for _ in 0..n {
        let x = rng.next_f64() * total;
        let i = cdf.partition_point(|&c| c <= x).min(srcs.len() - 1);
        let (v, nrm, _) = &srcs[i];
        let o = sample_triangle(v, rng.next_f32(), rng.next_f32()) + *nrm * 1e-5;
        let d = cosine_dir(*nrm, rng.next_f32(), rng.next_f32());
        match caster.closest(o, d, 0.0, f32::INFINITY) {
            Some(h) if scene.normals[h.tri as usize].dot(d) < 0.0 => {
                groups[scene.tri_object[h.tri as usize] as usize] += w;
            }
            Some(_) | None => out += w,
        }
    }
    (groups, out)
}

/// Power (channel sum) gathered on the front faces of each group: Σ A·H.
fn gathered(sol: &hirad::radiosity::Solution, scene: &Scene) -> Vec<f64> {
    let mut g = vec![0.0; scene.objects.len()];
    for t in 0..scene.num_triangles() {
        let h = sol.triangle_irradiance(t as u32, false).element_sum();
        g[scene.tri_object[t] as usize] += scene.areas[t] as f64 * h;
    }
    g
}

#[test]
fn first_gather_matches_shooting_from_the_lamps() {
    let scene = room(false);
    let lamps: Vec<_> = scene
        .emitters()
        .iter()
        .map(|&t| {
            let e = scene.material_of(t as usize).emission;
            let p =
                std::f64::consts::PI * scene.areas[t as usize] as f64 * (e.x + e.y + e.z) as f64;
            (scene.tri_vertices(t as usize), scene.normals[t as usize], p)
        })
        .collect();
    let emitted: f64 = lamps.iter().map(|l| l.2).sum();
    for strategy in Strategy::ALL {
        let tree = ClusterTree::build(&scene, strategy, &ClusterConfig::default());
        let caster = RayCaster::new(&scene, &tree);
        let (mut want, out) = shoot(&scene, &caster, &lamps, 400_000);
        assert!(out < 0.01 * emitted, "the lamp faces the ceiling: {out}");
        let cfg = SolverConfig {
            max_iters: 1,
            ..Default::default()
        };
        let sol = solve(&scene, &tree, &cfg, &NoProgress).unwrap();
        let mut got = gathered(&sol, &scene);
        // The poster's overlap with its wall belongs to the poster in the solver and to
        // whichever a ray meets first here: compare them together.
        for v in [&mut want, &mut got] {
            v[4] += v[7];
            v[7] = 0.0;
        }
        let (tw, tg): (f64, f64) = (want.iter().sum(), got.iter().sum());
        if std::env::var_os("ENERGY_TABLE").is_some() {
            eprintln!("{:8} first gather / rays: {:.4}", strategy.name(), tg / tw);
        }
        assert!(
            (tg / tw - 1.0).abs() < 0.02,
            "{}: gathered {tg:.2} W, rays deliver {tw:.2} W",
            strategy.name()
        );
        for (g, (w, s)) in want.iter().zip(&got).enumerate() {
            if *w > 0.02 * emitted {
                assert!(
                    (s / w - 1.0).abs() < 0.06,
                    "{}: group {g} gathered {s:.2} W, rays deliver {w:.2} W",
                    strategy.name()
                );
            }
        }
    }
}

#[test]
fn escaping_power_matches_rays_from_the_leaves() {
    for open in [false, true] {
        let scene = room(open);
        let emitted = scene.emitted_power().element_sum();
        for strategy in Strategy::ALL {
            let tree = ClusterTree::build(&scene, strategy, &ClusterConfig::default());
            let sol = solve(&scene, &tree, &SolverConfig::default(), &NoProgress).unwrap();
            let caster = RayCaster::new(&scene, &tree);
            let el = &sol.elements;
            let leaves: Vec<_> = sol
                .leaves()
                .into_iter()
                .map(|id| {
                    let e = &el.elems[id as usize];
                    (
                        e.verts,
                        e.normal,
                        e.area as f64 * el.b[id as usize].element_sum(),
                    )
                })
                .filter(|l| l.2 > 0.0)
                .collect();
            let (_, out) = shoot(&scene, &caster, &leaves, 400_000);
            let esc = sol.stats.power.escaping;
            if std::env::var_os("ENERGY_TABLE").is_some() {
                eprintln!(
                    "open {open} {:8} emitted − absorbed {esc:.3} W, rays {out:.3} W of {emitted:.3} W",
                    strategy.name()
                );
                continue;
            }
            // Known: the solver gathers up to 4.1% of the emitted power more than the rays
            // (kdt, closed room; the table's back-to-back faces gather 0.68 W against 0.49 W).
            assert!(
                (esc - out).abs() < 0.045 * emitted,
                "{} (open {open}): emitted − absorbed {esc:.2} W, rays from the leaves reach no \
                 front face with {out:.2} W (emitted {emitted:.2} W)",
                strategy.name()
            );
        }
    }
}

/// A lamp panel flush with a ceiling tessellated into cells smaller than the panel: the
/// overlap belongs to the emitter, so in the closed room (walls ρ = 0.7) everything emitted is
/// absorbed and the walls gather close to `Φ / (1 − ρ)` (less what the black lamp absorbs:
/// its 0.36 m² take about 0.6% of each bounce). Giving the overlap to the smaller triangle,
/// the ceiling cell, left the lamp covered: it emitted nothing.
#[test]
fn lamp_flush_with_a_tessellated_ceiling_shines() {
    let (lo, hi) = (Vec3::ZERO, Vec3::new(4.0, 3.0, 2.5));
    let mut q: Vec<Quad> = box_inward(lo, hi, WALL, 0);
    q.swap_remove(1);
    let (x, y) = (Vec3::X, Vec3::Y);
    let n = 8;
    for i in 0..n {
        for j in 0..n {
            let o = Vec3::new(4.0 * i as f32 / n as f32, 3.0 * j as f32 / n as f32, 2.5);
            q.push(rect(o, y * (3.0 / n as f32), x * (4.0 / n as f32), WALL, 1));
        }
    }
    q.push(rect(Vec3::new(1.7, 1.2, 2.5), y * 0.6, x * 0.6, LAMP, 6));
    let scene = quads_scene(
        &q,
        vec![
            Material::diffuse("wall", Vec3::splat(0.7)),
            Material {
                name: "lamp".into(),
                rho: Vec3::ZERO,
                emission: Vec3::splat(10.0),
            },
        ],
    );
    let emitted = scene.emitted_power().element_sum();
    for strategy in Strategy::ALL {
        let tree = ClusterTree::build(&scene, strategy, &ClusterConfig::default());
        let sol = solve(&scene, &tree, &SolverConfig::default(), &NoProgress).unwrap();
        let esc = sol.stats.power.escaping;
        assert!(
            esc.abs() < 0.01 * emitted,
            "{}: {esc:.2} W of {emitted:.2} W not absorbed",
            strategy.name()
        );
        let got: f64 = gathered(&sol, &scene).iter().sum();
        let want = emitted / (1.0 - 0.7);
        assert!(
            (got / want - 0.99).abs() < 0.02,
            "{}: the walls gather {got:.2} W, Φ/(1 − ρ) = {want:.2} W",
            strategy.name()
        );
    }
}

/// The six faces of the box `[lo, hi]`, facing out (one group).
fn box_outward(lo: Vec3, hi: Vec3, mat: u32, group: u32) -> Vec<Quad> {
    let d = hi - lo;
    let (x, y, z) = (Vec3::X * d.x, Vec3::Y * d.y, Vec3::Z * d.z);
    vec![
        rect(lo, y, x, mat, group),
        rect(lo + z, x, y, mat, group),
        rect(lo, x, z, mat, group),
        rect(lo + y, z, x, mat, group),
        rect(lo, z, y, mat, group),
        rect(lo + x, y, z, mat, group),
    ]
}

fn furnished_room(gap: f32) -> Scene {
    let (lo, hi) = (Vec3::ZERO, Vec3::new(4.0, 3.0, 2.5));
    let mut q: Vec<Quad> = box_inward(lo, hi, WALL, 0);
    let b = |l: [f32; 3], h: [f32; 3], g: u32| {
        box_outward(Vec3::from(l) + gap, Vec3::from(h) - gap, WALL, g)
    };
    // Lamp box 5 cm under the ceiling; its underside emits.
    let lamp = box_outward(
        Vec3::new(1.4, 1.35, 2.4),
        Vec3::new(2.6, 1.65, 2.45),
        WALL,
        6,
    );
    q.extend(lamp.into_iter().skip(1));
    q.push(rect(
        Vec3::new(1.4, 1.35, 2.4),
        Vec3::Y * 0.3,
        Vec3::X * 1.2,
        LAMP,
        6,
    ));
    q.extend(b([0.0, 0.0, 0.0], [0.8, 0.6, 0.6], 7));
    q.extend(b([0.1, 0.1, 0.6], [0.6, 0.5, 1.0], 7));
    q.extend(b([0.8, 0.0, 0.0], [1.2, 0.4, 0.4], 7));
    q.extend(b([2.0, 1.0, 0.72], [3.2, 1.8, 0.75], 8));
    for (x, y) in [(2.0, 1.0), (3.15, 1.0), (2.0, 1.75), (3.15, 1.75)] {
        q.extend(b([x, y, 0.0], [x + 0.05, y + 0.05, 0.72], 8));
    }
    q.extend(b([3.7, 0.5, 1.2], [4.0, 2.5, 1.22], 9));
    for k in 0..24 {
        let y = 0.55 + 0.08 * k as f32;
        q.extend(b([3.72, y, 1.22], [3.97, y + 0.075, 1.47], 9));
    }
    quads_scene(
        &q,
        vec![
            Material::diffuse("wall", Vec3::splat(0.7)),
            Material {
                name: "lamp".into(),
                rho: Vec3::splat(0.7),
                emission: Vec3::splat(10.0),
            },
        ],
    )
}

/// A closed room furnished with solids (crates stacked on the floor and against two walls, a
/// table on four legs, a row of books on a shelf fixed to a wall) and a lamp box, every face
/// of reflectance ρ = 0.7: all light ends on front faces, so the surfaces gather exactly
/// `Φ / (1 − ρ)` whatever the geometry. Run with the solids 5 mm apart and touching. Kernels
/// between neighbouring solids decide it: near cluster links judged on the cluster's centroid
/// (before `KernelCtx::near_bound`) left kdt 3.3% short with the gaps and proxi 5.2% with
/// contact; with contact, shut masks that took a solid's side pressed on a wall for an open
/// face (the wall's front met at the same distance) left 2.7–3.6% short.
#[test]
fn a_furnished_closed_room_gathers_what_its_reflectance_implies() {
    let table = std::env::var_os("ENERGY_TABLE").is_some();
    let mut bad = Vec::new();
    for (gap, tol) in [(0.005, 0.025), (0.0, 0.025)] {
        let scene = furnished_room(gap);
        let emitted = scene.emitted_power().element_sum();
        let want = emitted / (1.0 - 0.7);
        for strategy in Strategy::ALL {
            let tree = ClusterTree::build(&scene, strategy, &ClusterConfig::default());
            let sol = solve(&scene, &tree, &SolverConfig::default(), &NoProgress).unwrap();
            let got: f64 = gathered(&sol, &scene).iter().sum();
            if table {
                println!(
                    "gap {gap} {:8} Σ A·H / (Φ/(1 − ρ)) = {:.4}, escaping {:.3} of emitted, \
                     mean kernel sum {:.4}",
                    strategy.name(),
                    got / want,
                    sol.stats.power.escaping / emitted,
                    sol.stats.kernel_sum_mean
                );
            }
            // Every open point of a closed scene sees surfaces all round: its kernels sum to 1
            // (with contact, faces pressed on others see nothing through them).
            let k = sol.stats.kernel_sum_mean;
            bad.extend(
                (gap > 0.0 && (k - 1.0).abs() >= 0.01)
                    .then(|| format!("{} (gap {gap} m): mean kernel sum {k:.4}", strategy.name())),
            );
            bad.extend(((got / want - 1.0).abs() >= tol).then(|| {
                format!(
                    "{} (gap {gap} m): the surfaces gather {got:.2} W, Φ/(1 − ρ) = {want:.2} W",
                    strategy.name()
                )
            }));
        }
    }
    assert!(bad.is_empty(), "{}", bad.join("\n"));
}

/// The same closed room with one shadow ray per link (the `fast` preset's): fewer rays make
/// each link's visibility noisier, never its expectation, so the total stays `Φ / (1 − ρ)`.
/// Refinement that splits or keeps a link on its own rays' outcome (a cluster receiver whose
/// rays all saw the source goes down when a child of it is hidden, one whose rays all missed
/// stays dark) and receivers whose few points all fell under a cover (read as receiving
/// nothing) left the solids in contact 2.2–2.6% short here (proxi, kdt, sah).
#[test]
fn one_shadow_ray_per_link_gathers_what_the_reflectance_implies() {
    let mut bad = Vec::new();
    for gap in [0.005, 0.0] {
        let scene = furnished_room(gap);
        let want = scene.emitted_power().element_sum() / (1.0 - 0.7);
        for strategy in [Strategy::Proxi, Strategy::Kdt, Strategy::Sah] {
            let tree = ClusterTree::build(&scene, strategy, &ClusterConfig::default());
            let cfg = SolverConfig {
                shadow_rays: 1,
                ..SolverConfig::default()
            };
            let sol = solve(&scene, &tree, &cfg, &NoProgress).unwrap();
            let got: f64 = gathered(&sol, &scene).iter().sum();
            println!("gap {gap} {:8} {:.4}", strategy.name(), got / want);
            bad.extend(((got / want - 1.0).abs() >= 0.025).then(|| {
                format!(
                    "{} (gap {gap} m): the surfaces gather {got:.2} W, Φ/(1 − ρ) = {want:.2} W",
                    strategy.name()
                )
            }));
        }
    }
    assert!(bad.is_empty(), "{}", bad.join("\n"));
}
