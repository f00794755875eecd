//! Resolution where the hierarchy stops at the minimum element area: a shadow boundary
//! crossing a receiver whose light the oracle would still refine (`shadow_levels`), and a
//! source much closer to a receiver than the receiver's size (the near-field kernel). Both are
//! checked leaf by leaf against brute-force direct light (analytic form factors, visibility
//! in closed form), so either would fail if the solver averaged the light over too coarse
//! elements or integrated the kernel too coarsely. And weak links that no oracle refines,
//! whose light must land where their rays see the source ([`Deposit`]).
//!
//! [`Deposit`]: hirad::radiosity::link::Deposit

use glam::{DVec3, Vec3};
use hirad::progress::NoProgress;
use hirad::radiosity::element::Kind;
use hirad::radiosity::formfactor::point_to_polygon;
use hirad::radiosity::{solve, Solution, SolverConfig};
use hirad::scene::{Material, Scene};

mod radiosity_common;
use radiosity_common::{quads_scene, rect, tree_by_object, Quad};

const GREY: u32 = 0;
const LAMP: u32 = 1;
const BLACK: u32 = 2;

fn materials() -> Vec<Material> {
    vec![
        Material::diffuse("grey", Vec3::splat(0.5)),
        Material {
            name: "lamp".into(),
            rho: Vec3::ZERO,
            emission: Vec3::splat(1.0),
        },
        Material::diffuse("black", Vec3::ZERO),
    ]
}

/// Front-face leaves of `group` with their mean irradiance (red, from `B = ρ H` on grey).
fn leaves(sol: &Solution, scene: &Scene, group: u32) -> Vec<([Vec3; 3], f32, f64)> {
    let el = &sol.elements;
    let mut out = Vec::new();
    for l in sol.leaves() {
        let e = &el.elems[l as usize];
        if e.kind == Kind::Surface && !e.back && scene.tri_object[e.tri as usize] == group {
            out.push((e.verts, e.area, el.b[l as usize].x / 0.5));
        }
    }
    out
}

/// Mean over triangle `v` (normal `n`) of the irradiance from the unit-radiance lamp
/// polygon `lamp`, on a `k × k` grid of points, `vis(x, y)` the visibility of lamp point `y`
/// from `x` (`None`: unoccluded, analytic form factor).
fn brute(
    v: &[Vec3; 3],
    n: Vec3,
    lamp: &[DVec3; 4],
    lamp_n: DVec3,
    k: usize,
    vis: Option<&dyn Fn(DVec3, DVec3) -> bool>,
) -> f64 {
    let (mut sum, mut cnt) = (0.0, 0);
    for i in 0..k {
        for j in 0..k {
            let (u1, u2) = ((i as f32 + 0.5) / k as f32, (j as f32 + 0.5) / k as f32);
            let s = u1.sqrt();
            let x = (v[0] * (1.0 - s) + v[1] * (s * (1.0 - u2)) + v[2] * (s * u2)).as_dvec3();
            cnt += 1;
            sum += match vis {
                None => std::f64::consts::PI * point_to_polygon(x, n.as_dvec3(), lamp, lamp_n),
                Some(vis) => {
                    // Lamp points on a 16 × 16 grid: radiance 1 × cos cos / r² × area.
                    let m = 16;
                    let (a, b) = (lamp[1] - lamp[0], lamp[3] - lamp[0]);
                    let da = a.cross(b).length() / (m * m) as f64;
                    let mut e = 0.0;
                    for p in 0..m {
                        for q in 0..m {
                            let y = lamp[0]
                                + a * ((p as f64 + 0.5) / m as f64)
                                + b * ((q as f64 + 0.5) / m as f64);
                            let d = y - x;
                            let r2 = d.length_squared();
                            let c = n.as_dvec3().dot(d) * -lamp_n.dot(d) / (r2 * r2);
                            if c > 0.0 && vis(x, y) {
                                e += c * da;
                            }
                        }
                    }
                    e
                }
            };
        }
    }
    sum / cnt as f64
}

/// Floor 1 × 1 (grey) under a 0.2 × 0.2 lamp at height 1; a black plate at height 0.5
/// covers x < 0.5, so the floor's shadow boundary runs along x = 0.5 with a penumbra from
/// x = 0.4 to 0.6.
fn shadow_scene() -> (Scene, [DVec3; 4]) {
    let lamp = [
        Vec3::new(0.4, 0.4, 1.0),
        Vec3::new(0.4, 0.6, 1.0),
        Vec3::new(0.6, 0.6, 1.0),
        Vec3::new(0.6, 0.4, 1.0),
    ];
    let quads = vec![
        rect(Vec3::ZERO, Vec3::X, Vec3::Y, GREY, 0),
        Quad {
            p: lamp,
            mat: LAMP,
            group: 1,
        },
        rect(Vec3::new(-0.5, -0.5, 0.5), Vec3::X, Vec3::Y * 2.0, BLACK, 2),
    ];
    (quads_scene(&quads, materials()), lamp.map(|p| p.as_dvec3()))
}

/// Σ area × |H − brute| over the floor's leaves, and the smallest leaf area.
fn shadow_error(levels: u32) -> (f64, f32) {
    let (scene, lamp) = shadow_scene();
    let tree = tree_by_object(&scene);
    let cfg = SolverConfig {
        eps: Some(1e-9),
        min_area: Some(0.05),
        shadow_levels: levels,
        shadow_rays: 16,
        ..SolverConfig::default()
    };
    let sol = solve(&scene, &tree, &cfg, &NoProgress).unwrap();
    // The segment x → y passes the plate's plane z = 0.5 at x < 0.5: blocked.
    let vis = |x: DVec3, y: DVec3| {
        let t = (0.5 - x.z) / (y.z - x.z);
        x.x + (y.x - x.x) * t >= 0.5
    };
    let mut err = 0.0;
    let mut smallest = f32::INFINITY;
    for (v, a, h) in leaves(&sol, &scene, 0) {
        let want = brute(&v, Vec3::Z, &lamp, -DVec3::Z, 8, Some(&vis));
        err += a as f64 * (h - want).abs();
        smallest = smallest.min(a);
    }
    (err, smallest)
}

#[test]
fn a_shadow_boundary_splits_below_the_minimum_area_and_sharpens() {
    let (coarse, coarse_min) = shadow_error(0);
    let (fine, fine_min) = shadow_error(2);
    // Without shadow levels no leaf is below a quarter of the minimum area; with two, the
    // penumbra's leaves are down to a sixteenth of it.
    assert!(coarse_min >= 0.05 / 4.0 - 1e-6, "{coarse_min}");
    assert!(fine_min < 0.05 / 4.0, "{fine_min}");
    assert!(
        fine < 0.6 * coarse,
        "leaf error with shadow levels {fine:.5} against {coarse:.5} without"
    );
}

#[test]
fn a_lamp_close_under_a_ceiling_lights_each_leaf_as_the_analytic_form_factor() {
    // Ceiling 1 × 1 (grey, facing down) at z = 1, a lamp strip 0.8 × 0.1 facing up 8 cm
    // under it; the ceiling's triangles (0.5) are at the minimum area.
    let lamp = [
        Vec3::new(0.1, 0.45, 0.92),
        Vec3::new(0.9, 0.45, 0.92),
        Vec3::new(0.9, 0.55, 0.92),
        Vec3::new(0.1, 0.55, 0.92),
    ];
    let quads = vec![
        rect(Vec3::new(0.0, 0.0, 1.0), Vec3::Y, Vec3::X, GREY, 0),
        Quad {
            p: lamp,
            mat: LAMP,
            group: 1,
        },
    ];
    let scene = quads_scene(&quads, materials());
    let tree = tree_by_object(&scene);
    let lamp = lamp.map(|p| p.as_dvec3());
    // Every leaf here is wider than its distance to the lamp (its area above 0.08² m²), so
    // each goes one level below the shadow levels' area, and no further: without shadow
    // levels the two triangles at the minimum area split once (8 leaves of 0.125 m², below a
    // quarter of 0.6); with two, the 32 leaves split once more (128 of 0.0078 m²). Without
    // that rule: 2 and 32.
    for (levels, n) in [(0, 8), (2, 128)] {
        let cfg = SolverConfig {
            eps: Some(1e-9),
            min_area: Some(0.6),
            shadow_levels: levels,
            ..SolverConfig::default()
        };
        let sol = solve(&scene, &tree, &cfg, &NoProgress).unwrap();
        let ls = leaves(&sol, &scene, 0);
        assert_eq!(ls.len(), n);
        let want: Vec<f64> = ls
            .iter()
            .map(|(v, _, _)| brute(v, -Vec3::Z, &lamp, DVec3::Z, 64, None))
            .collect();
        // Within 2% of the brightest leaf (dim leaves far from the lamp take 4 samples).
        let top = want.iter().cloned().fold(0.0, f64::max);
        for ((_, _, h), w) in ls.iter().zip(&want) {
            assert!(
                (h - w).abs() < 0.02 * top,
                "shadow levels {levels}: leaf irradiance {h:.5}, analytic {w:.5}"
            );
        }
    }
}

#[test]
fn perpendicular_squares_at_the_minimum_area() {
    // Receiver z = 0 facing +z; emitter (radiance 1) in the plane y = 0 facing +y, sharing
    // the edge y = z = 0: F = 0.20004 however coarse the elements (near-field kernels along
    // the shared edge).
    let wall = rect(Vec3::ZERO, Vec3::Z, Vec3::X, LAMP, 1);
    let floor = rect(Vec3::ZERO, Vec3::X, Vec3::Y, BLACK, 0);
    let scene = quads_scene(&[floor, wall], materials());
    let tree = tree_by_object(&scene);
    for min_area in [0.6, 0.2, 0.05] {
        let cfg = SolverConfig {
            eps: Some(1e-9),
            min_area: Some(min_area),
            ..SolverConfig::default()
        };
        let sol = solve(&scene, &tree, &cfg, &NoProgress).unwrap();
        let f = radiosity_common::group_irradiance(&sol, &scene, 0) / std::f64::consts::PI;
        assert!(
            (f - 0.20004).abs() < 0.005 * 0.20004,
            "min area {min_area}: F = {f:.5}"
        );
    }
}

#[test]
fn weak_links_land_where_their_rays_see_the_source() {
    // Floor 1 × 1 (grey); a black plate 2 cm above it hides x < 0.5. A dim ceiling (green,
    // 16 quads, 0.9 × 0.9 at z = 1) whose every link is far below ε, so its links stay on the
    // floor's two triangles; a bright lamp beside it (red) refines the floor to its minimum
    // area. Spread evenly, the dim light would reach the hidden half as much as the open one
    // (a triangle 75% hidden would give its open part a quarter of its light); shaped by
    // where the floor's links' rays saw their sources, the open half gets the brute-force
    // value and the hidden half almost nothing (spread evenly: the open half 0.63 of brute
    // force, the hidden half 0.58 of the open one). Midpoint subdivision puts a cell edge on
    // x = 0.5.
    let g = 0.1f32;
    let mut mats = materials();
    mats.push(Material {
        name: "dim".into(),
        rho: Vec3::ZERO,
        emission: Vec3::new(0.0, g, 0.0),
    });
    mats.push(Material {
        name: "red lamp".into(),
        rho: Vec3::ZERO,
        emission: Vec3::new(10.0, 0.0, 0.0),
    });
    let (dim, red) = (3, 4);
    let mut quads = vec![
        rect(Vec3::ZERO, Vec3::X, Vec3::Y, GREY, 0),
        // Facing the floor: the floor under it is open (dark), not inside a solid.
        rect(
            Vec3::new(-0.5, -0.5, 0.02),
            Vec3::Y * 2.0,
            Vec3::X,
            BLACK,
            1,
        ),
        rect(
            Vec3::new(1.2, 0.4, 1.0),
            Vec3::Y * 0.2,
            Vec3::X * 0.2,
            red,
            2,
        ),
    ];
    for i in 0..4 {
        for j in 0..4 {
            let o = Vec3::new(0.05 + 0.225 * i as f32, 0.05 + 0.225 * j as f32, 1.0);
            quads.push(rect(o, Vec3::Y * 0.225, Vec3::X * 0.225, dim, 3));
        }
    }
    let scene = quads_scene(&quads, mats);
    let tree = tree_by_object(&scene);
    let cfg = SolverConfig {
        eps: Some(0.01),
        min_area: Some(0.5 / 64.0),
        shadow_levels: 0,
        ..SolverConfig::default()
    };
    let sol = solve(&scene, &tree, &cfg, &NoProgress).unwrap();
    let ceiling = [
        DVec3::new(0.05, 0.05, 1.0),
        DVec3::new(0.05, 0.95, 1.0),
        DVec3::new(0.95, 0.95, 1.0),
        DVec3::new(0.95, 0.05, 1.0),
    ];
    // The segment x → y passes the plate's plane z = 0.02 at x < 0.5: blocked.
    let vis = |x: DVec3, y: DVec3| {
        let t = (0.02 - x.z) / (y.z - x.z);
        x.x + (y.x - x.x) * t >= 0.5
    };
    let el = &sol.elements;
    let (mut open, mut open_want, mut hidden, mut leaves) = (0.0, 0.0, 0.0, 0);
    for l in sol.leaves() {
        let e = &el.elems[l as usize];
        if e.back || scene.tri_object[e.tri as usize] != 0 {
            continue;
        }
        leaves += 1;
        let a = e.area as f64;
        let h = el.b[l as usize].y / 0.5;
        if e.centroid.x > 0.5 {
            open += a * h;
            open_want +=
                a * g as f64 * brute(&e.verts, Vec3::Z, &ceiling, -DVec3::Z, 4, Some(&vis));
        } else {
            hidden += a * h;
        }
    }
    assert_eq!(
        leaves, 128,
        "the lamp refines the floor to its minimum area"
    );
    assert!(
        (open / open_want - 1.0).abs() < 0.1,
        "open half: Σ A·H {open:.5}, brute force {open_want:.5}"
    );
    assert!(
        hidden < 0.1 * open,
        "hidden half: Σ A·H {hidden:.5} against {open:.5} on the open half"
    );
}

#[test]
fn a_board_hung_a_millimetre_off_the_floor_closes_the_gap_under_it() {
    // Floor 1 × 1 (grey, facing up) under a 0.2 × 0.2 lamp at x 0.1..0.3, height 1; a black
    // board 1 cm thick hangs 1 mm above it over x > 0.4, which no cell edge of the midpoint
    // subdivision follows. The gap lets in almost no light, so a leaf straddling the board's
    // edge is lit as its open part is (brute force over the points left of x = 0.4), not at
    // the mean with the dark part under the board: spread over the whole leaf, a leaf half
    // under the board would read half its open part's light.
    for two_sided in [false, true] {
        let lamp = [
            Vec3::new(0.1, 0.4, 1.0),
            Vec3::new(0.1, 0.6, 1.0),
            Vec3::new(0.3, 0.6, 1.0),
            Vec3::new(0.3, 0.4, 1.0),
        ];
        let quads = vec![
            rect(Vec3::ZERO, Vec3::X, Vec3::Y, GREY, 0),
            rect(
                Vec3::new(0.4, -0.2, 0.001),
                Vec3::Y * 1.4,
                Vec3::X * 0.8,
                BLACK,
                1,
            ),
            rect(
                Vec3::new(0.4, -0.2, 0.011),
                Vec3::X * 0.8,
                Vec3::Y * 1.4,
                BLACK,
                1,
            ),
            Quad {
                p: lamp,
                mat: LAMP,
                group: 2,
            },
        ];
        let scene = quads_scene(&quads, materials());
        let tree = tree_by_object(&scene);
        let cfg = SolverConfig {
            min_area: Some(1.0 / 32.0),
            two_sided,
            shadow_levels: 0,
            ..SolverConfig::default()
        };
        let sol = solve(&scene, &tree, &cfg, &NoProgress).unwrap();
        let lamp = lamp.map(|p| p.as_dvec3());
        let mut straddling = 0;
        for (v, _, h) in leaves(&sol, &scene, 0) {
            let (lo, hi) = v.iter().fold((f32::INFINITY, f32::NEG_INFINITY), |a, p| {
                (a.0.min(p.x), a.1.max(p.x))
            });
            if !(lo < 0.38 && hi > 0.42) {
                continue;
            }
            straddling += 1;
            // Brute force over the leaf's open points (a 32 × 32 grid).
            let (mut sum, mut open) = (0.0, 0);
            for i in 0..32 {
                for j in 0..32 {
                    let (u1, u2) = ((i as f32 + 0.5) / 32.0, (j as f32 + 0.5) / 32.0);
                    let s = u1.sqrt();
                    let x = v[0] * (1.0 - s) + v[1] * (s * (1.0 - u2)) + v[2] * (s * u2);
                    if x.x < 0.4 {
                        open += 1;
                        sum += std::f64::consts::PI
                            * point_to_polygon(x.as_dvec3(), DVec3::Z, &lamp, -DVec3::Z);
                    }
                }
            }
            let want = sum / open as f64;
            assert!(
                (h / want - 1.0).abs() < 0.1,
                "two-sided {two_sided}: leaf {v:?} H {h:.5}, brute force over its open part {want:.5}"
            );
        }
        assert!(
            straddling >= 2,
            "{straddling} leaves straddle the board's edge"
        );
    }
}
