//! Light-leak suite: scenes whose geometry forbids light somewhere (walls, closed boxes,
//! one-sided surfaces facing away). Each runs for every clustering strategy × visibility
//! {rays, volume} × cluster emission {directional, isotropic} × oracle {bf, error}; the
//! radiosity of every surface that no light path reaches must be 0 (≤ [`LEAK_MAX`] of the
//! lamp's exitance). `LEAK_TABLE=1` prints the worst leak of every scene and strategy with
//! rays and volumes.

use glam::Vec3;
use hirad::cluster::{ClusterConfig, ClusterTree, Strategy};
use hirad::progress::NoProgress;
use hirad::radiosity::{solve, ClusterEmission, Oracle, SolverConfig, VisibilityMode};
use hirad::rng::SplitMix64;
use hirad::scene::{Material, Scene};

mod radiosity_common;
use radiosity_common::{quads_scene, rect, Quad};

/// Lamp radiance: exitance E = π·10 W/m².
const LAMP_LE: f32 = 10.0;

fn grey() -> Material {
    Material::diffuse("grey", Vec3::splat(0.5))
}

fn lamp() -> Material {
    Material {
        name: "lamp".into(),
        rho: Vec3::ZERO,
        emission: Vec3::splat(LAMP_LE),
    }
}

const GREY: u32 = 0;
const LAMP: u32 = 1;

/// The six inward-facing grey walls of the box `[lo, hi]`, each in its own group from `g0`.
fn box_inward(lo: Vec3, hi: Vec3, g0: u32) -> Vec<Quad> {
    radiosity_common::box_inward(lo, hi, GREY, g0)
}

/// The six inward-facing grey walls of the box `[lo, hi]`, each cut into `n × n` tiles (separate
/// quads, as a soup has them), each wall in its own group from `g0`.
fn tiled_box_inward(lo: Vec3, hi: Vec3, n: usize, g0: u32) -> Vec<Quad> {
    let mut out = Vec::new();
    for q in box_inward(lo, hi, g0) {
        let [a, b, _, d] = q.p;
        let (u, w) = ((b - a) / n as f32, (d - a) / n as f32);
        for i in 0..n {
            for j in 0..n {
                out.push(rect(a + u * i as f32 + w * j as f32, u, w, q.mat, q.group));
            }
        }
    }
    out
}

/// Small randomly oriented grey triangles (as degenerate quads) inside `[lo, hi]`.
fn clutter(lo: Vec3, hi: Vec3, n: usize, seed: u64, group: u32) -> Vec<Quad> {
    let mut rng = SplitMix64::new(seed);
    let mut r = || rng.next_f32();
    (0..n)
        .map(|_| {
            let c = lo + (hi - lo) * Vec3::new(0.1 + 0.8 * r(), 0.1 + 0.8 * r(), 0.1 + 0.8 * r());
            let s = 0.04 * (hi - lo).min_element();
            let u = Vec3::new(r() - 0.5, r() - 0.5, r() - 0.5).normalize() * s;
            let w = Vec3::new(r() - 0.5, r() - 0.5, r() - 0.5).normalize() * s;
            rect(c, u, w, GREY, group)
        })
        .collect()
}

/// A leak scene: its quads, and the groups that no light may reach.
struct LeakScene {
    name: &'static str,
    quads: Vec<Quad>,
    dark: Vec<u32>,
}

fn scenes() -> Vec<LeakScene> {
    let (x, y, z) = (Vec3::X, Vec3::Y, Vec3::Z);
    let mut out = Vec::new();
    // 1. A wall between a receiver and a lamp that shines at the wall's back.
    out.push(LeakScene {
        name: "wall",
        quads: vec![
            rect(Vec3::new(0.0, 0.1, 0.0), z, x, GREY, 0),
            rect(Vec3::new(0.0, 0.3, 0.0), x, z, GREY, 1),
            rect(Vec3::new(0.1, 0.85, 0.4), x * 0.2, z * 0.2, LAMP, 2),
        ],
        dark: vec![0, 1],
    });
    // 2. A closed room of inward-facing walls, the lamp outside shining at its ceiling.
    let mut q = box_inward(Vec3::ZERO, Vec3::ONE, 0);
    q.push(rect(Vec3::new(0.3, 0.3, 1.5), y * 0.4, x * 0.4, LAMP, 6));
    out.push(LeakScene {
        name: "room_lamp_outside",
        quads: q,
        dark: (0..6).collect(),
    });
    // 3. A lamp inside a closed box; a floor and a ceiling outside it.
    out.push(lamp_in_box(
        "lamp_in_box",
        box_inward(Vec3::splat(0.4), Vec3::splat(0.6), 0),
        Vec3::new(0.45, 0.45, 0.45),
    ));
    // 3b. The same box with tiled walls, the lamp off-centre near its floor: clusters hold
    //     pieces of walls that meet at an edge, not a whole wall nor the whole box.
    out.push(lamp_in_box(
        "lamp_in_tiled_box",
        tiled_box_inward(Vec3::splat(0.4), Vec3::splat(0.6), 2, 0),
        Vec3::new(0.43, 0.47, 0.41),
    ));
    // 4. A thin double wall: the lamp lights the back wall; the front wall and the receiver
    //    beyond it stay dark.
    out.push(LeakScene {
        name: "double_wall",
        quads: vec![
            rect(Vec3::new(0.0, 0.1, 0.0), z, x, GREY, 0),
            rect(Vec3::new(0.0, 0.3, 0.0), x, z, GREY, 1),
            rect(Vec3::new(0.0, 0.301, 0.0), z, x, GREY, 2),
            rect(Vec3::new(0.2, 0.85, 0.2), x * 0.6, z * 0.6, LAMP, 3),
        ],
        dark: vec![0, 1],
    });
    // 5. T-junctions: a closed box split in two by a wall; the lamp lights the left half.
    let (t_quads, t_dark) = split_box();
    out.push(LeakScene {
        name: "t_junction",
        quads: t_quads,
        dark: t_dark.clone(),
    });
    // 6. The same with clutter on both sides: cells and clusters that straddle the wall,
    //    which is attached to an ancestor of both (kdt, obt).
    let (mut q, mut dark) = split_box();
    q.extend(clutter(Vec3::ZERO, Vec3::new(1.0, 1.0, 1.0), 40, 5, 20));
    q.extend(clutter(
        Vec3::new(1.0, 0.0, 0.0),
        Vec3::new(2.0, 1.0, 1.0),
        40,
        6,
        21,
    ));
    dark.push(21);
    out.push(LeakScene {
        name: "cell_across_wall",
        quads: q,
        dark,
    });
    // 7. A cluster whose centroid lies behind the receiver's plane (a big grey panel far
    //    below it) while a lamp of the same cluster faces away from the receiver.
    out.push(LeakScene {
        name: "centroid_behind",
        quads: vec![
            rect(Vec3::ZERO, x, y, GREY, 0),
            rect(Vec3::new(0.0, 0.0, 1.0), x, y, LAMP, 1),
            rect(Vec3::new(-4.5, -4.5, -5.0), y * 10.0, x * 10.0, GREY, 1),
        ],
        dark: vec![0],
    });
    // 8. An emitter facing away from the receivers.
    out.push(LeakScene {
        name: "facing_away",
        quads: vec![
            rect(Vec3::ZERO, x, y, GREY, 0),
            rect(Vec3::new(1.2, 0.0, 0.0), x, y, GREY, 0),
            rect(Vec3::new(0.3, 0.3, 0.5), x * 0.4, y * 0.4, LAMP, 1),
        ],
        dark: vec![0],
    });
    out
}

/// The walls of a closed box (groups 0–5), a 0.1 × 0.1 lamp facing +z at `corner` inside it,
/// and a floor and a ceiling outside it, which stay dark.
fn lamp_in_box(name: &'static str, mut quads: Vec<Quad>, corner: Vec3) -> LeakScene {
    let (x, y) = (Vec3::X, Vec3::Y);
    quads.push(rect(corner, x * 0.1, y * 0.1, LAMP, 6));
    quads.push(rect(Vec3::new(-1.0, -1.0, 0.0), x * 3.0, y * 3.0, GREY, 7));
    quads.push(rect(Vec3::new(-1.0, -1.0, 1.5), y * 3.0, x * 3.0, GREY, 8));
    LeakScene {
        name,
        quads,
        dark: vec![7, 8],
    }
}

/// A closed box [0,2]×[0,1]×[0,1] of inward-facing walls, cut in two at x = 1 by a wall of
/// two faces, each half's walls separate quads; a lamp under the left half's ceiling.
/// Returns the quads and the right half's groups.
fn split_box() -> (Vec<Quad>, Vec<u32>) {
    let mut q = box_inward(Vec3::ZERO, Vec3::new(1.0, 1.0, 1.0), 0);
    q.extend(box_inward(
        Vec3::new(1.0, 0.0, 0.0),
        Vec3::new(2.0, 1.0, 1.0),
        6,
    ));
    q.push(rect(
        Vec3::new(0.3, 0.3, 0.99),
        Vec3::Y * 0.4,
        Vec3::X * 0.4,
        LAMP,
        12,
    ));
    (q, (6..12).collect())
}

#[derive(Clone, Copy)]
struct Mode {
    vis: VisibilityMode,
    emission: ClusterEmission,
    refine: Oracle,
}

fn modes() -> Vec<Mode> {
    let mut m = Vec::new();
    for vis in [VisibilityMode::Rays, VisibilityMode::Volume] {
        for emission in [ClusterEmission::Directional, ClusterEmission::Isotropic] {
            for refine in [Oracle::Bf, Oracle::Error] {
                m.push(Mode {
                    vis,
                    emission,
                    refine,
                });
            }
        }
    }
    m
}

fn mode_name(m: Mode) -> String {
    format!("{}/{}/{}", m.vis.name(), m.emission.name(), m.refine.name())
}

/// The most light a dark surface may get, relative to the lamp's exitance. (What keeps it
/// dark: a mixed link into a cluster lands on the surfaces its samples saw, or splits an
/// isotropic cluster end; a directional cluster whose rays all saw the source tests each child
/// no sample landed on before handing light to it; sample points keep a margin from their
/// triangle's edges, which shadow segments, also through volumes, no longer leave out;
/// volumes are only media of small objects, never around an end point.)
const LEAK_MAX: f64 = 1e-9;

/// Largest radiosity of a dark group's surfaces relative to the lamp's exitance.
fn leak(scene: &Scene, dark: &[u32], strategy: Strategy, m: Mode) -> f64 {
    let tree = ClusterTree::build(scene, strategy, &ClusterConfig::default());
    let cfg = SolverConfig {
        visibility: m.vis,
        cluster_emission: m.emission,
        refine: m.refine,
        ..Default::default()
    };
    let sol = solve(scene, &tree, &cfg, &NoProgress).unwrap();
    let e = std::f64::consts::PI * LAMP_LE as f64;
    (0..scene.num_triangles())
        .filter(|&t| dark.contains(&scene.tri_object[t]))
        .map(|t| sol.triangle_radiosity(t as u32, false).max_element() / e)
        .fold(0.0, f64::max)
}

#[test]
fn no_light_where_geometry_forbids_it() {
    let table = std::env::var_os("LEAK_TABLE").is_some();
    let mut failures = Vec::new();
    for s in scenes() {
        let scene = quads_scene(&s.quads, vec![grey(), lamp()]);
        for strategy in Strategy::ALL {
            // Worst leak with rays and with volumes.
            let mut worst = [0.0f64; 2];
            for m in modes() {
                let l = leak(&scene, &s.dark, strategy, m);
                if l > LEAK_MAX {
                    failures.push(format!(
                        "{} {} {}: {l:.3e}",
                        s.name,
                        strategy.name(),
                        mode_name(m)
                    ));
                }
                let w = &mut worst[(m.vis == VisibilityMode::Volume) as usize];
                *w = w.max(l);
            }
            if table {
                eprintln!(
                    "| {} | {} | {:.1e} | {:.1e} |",
                    s.name,
                    strategy.name(),
                    worst[0],
                    worst[1]
                );
            }
        }
    }
    assert!(
        failures.is_empty(),
        "{} leaking runs:\n{}",
        failures.len(),
        failures.join("\n")
    );
}
