//! TREES: several trees on a ground plane under a sun and a uniform sky (paper Fig. 5).
//!
//! Each tree has a tapered trunk, 6–9 main branches with 2–3 twigs each (truncated cones,
//! closed, facing outwards) and a crown of [`LEAVES_PER_TREE`] leaves: small diamond quads
//! (two triangles, 0.12–0.2 m long) at random positions in the crown ellipsoid (denser towards its
//! surface) with uniformly random orientations. Leaves are one-sided surfaces like any other;
//! whether their back faces receive light is the solver's choice (`--two-sided`). The ground
//! is a 40 × 40 m plane of 0.5 m cells facing up. No surface emits.
//!
//! Light: a sun at 45° elevation (shadows fall towards +x and −z, towards the default
//! camera) with irradiance 800 W/m² on a surface facing it, and a uniform sky of radiance
//! (25, 30, 40) W/(m²·sr) (horizontal sky irradiance π·L ≈ (79, 94, 126) W/m²). These are
//! physical daylight values: sunlit ground has radiance ≈ 50, so images want an exposure of
//! about −6 stops. `trees:N` generates N trees (default 7); positions, sizes and leaves come
//! from the seed. +Y up.

use super::mesh::{camera, MeshBuilder};
use crate::{RawScene, Sun, UpAxis};
use glam::{Quat, Vec3};
use hirad_core::rng::SplitMix64;

/// Default number of trees.
pub const DEFAULT_TREES: u32 = 7;
/// Leaf quads per tree (two triangles each).
pub const LEAVES_PER_TREE: u32 = 3000;
/// Half the side of the square ground plane, metres.
pub const GROUND_HALF: f32 = 20.0;
/// Ground cells per side.
pub const GROUND_CELLS: u32 = 80;
/// Sun irradiance on a surface facing the sun, W/m².
pub const SUN_IRRADIANCE: Vec3 = Vec3::splat(800.0);
/// Sky radiance, W/(m²·sr).
pub const SKY_RADIANCE: Vec3 = Vec3::new(25.0, 30.0, 40.0);

/// Unit vector towards the sun: 45° elevation, from −x, +z.
pub fn sun_direction() -> Vec3 {
    let el = 45f32.to_radians();
    let h = Vec3::new(-0.8, 0.0, 0.6);
    (h * el.cos() + Vec3::Y * el.sin()).normalize()
}

fn uniform(r: &mut SplitMix64, lo: f32, hi: f32) -> f32 {
    lo + (hi - lo) * r.next_f32()
}

/// Uniform random unit vector.
fn unit(r: &mut SplitMix64) -> Vec3 {
    let z = uniform(r, -1.0, 1.0);
    let phi = uniform(r, 0.0, std::f32::consts::TAU);
    let s = (1.0 - z * z).max(0.0).sqrt();
    Vec3::new(s * phi.cos(), z, s * phi.sin())
}

/// Tree positions: rejection sampling in a disc of radius 12 m with a spacing of 5 m (relaxed
/// when the disc is full).
fn positions(n: u32, rng: &mut SplitMix64) -> Vec<Vec3> {
    let mut out: Vec<Vec3> = Vec::new();
    let radius = 12.0f32.max(2.5 * (n as f32).sqrt());
    let mut spacing = 5.0f32;
    let mut tries = 0;
    while out.len() < n as usize {
        let p = Vec3::new(uniform(rng, -1.0, 1.0), 0.0, uniform(rng, -1.0, 1.0)) * radius;
        if p.length() <= radius && out.iter().all(|q| q.distance(p) >= spacing) {
            out.push(p);
        }
        tries += 1;
        if tries % 500 == 0 {
            spacing *= 0.8;
        }
    }
    out
}

fn tree(b: &mut MeshBuilder, rng: &mut SplitMix64, base: Vec3, k: usize, leaves: u32) {
    b.begin_object(format!("tree_{k}"));
    b.use_material("bark", Vec3::new(0.3, 0.22, 0.15), Vec3::ZERO);
    let height = uniform(rng, 6.0, 10.0);
    let crown_base = height * uniform(rng, 0.3, 0.4);
    let r0 = uniform(rng, 0.15, 0.3);
    let trunk_top = base + Vec3::Y * (0.85 * height);
    b.cone(base, trunk_top, r0, 0.25 * r0, 12, 6, true);
    let crown_r = uniform(rng, 2.2, 3.4);
    let crown_h = 0.5 * (height - crown_base);
    let crown_c = base + Vec3::Y * (crown_base + crown_h);
    // Main branches spiral up the trunk, each with a few twigs.
    let nb = 6 + (rng.next_u64() % 4) as u32;
    let phase = uniform(rng, 0.0, std::f32::consts::TAU);
    for i in 0..nb {
        let t = i as f32 / nb as f32;
        let y = crown_base + t * (0.8 * height - crown_base);
        let start = base + Vec3::Y * y;
        let az = phase + i as f32 * 2.39996 + uniform(rng, -0.3, 0.3);
        let el = uniform(rng, 0.5, 1.0);
        let dir = Vec3::new(az.cos() * el.cos(), el.sin(), az.sin() * el.cos());
        let len = crown_r * uniform(rng, 0.55, 0.85) * (1.0 - 0.4 * t);
        let rb = r0 * (1.0 - 0.75 * y / (0.85 * height)) * 0.6;
        let end = start + dir * len;
        b.cone(start, end, rb, 0.1 * rb, 6, 2, true);
        let nt = 2 + (rng.next_u64() % 2) as u32;
        for _ in 0..nt {
            let s = start + dir * len * uniform(rng, 0.35, 0.8);
            let d = (dir + unit(rng) * 0.8 + Vec3::Y * 0.3).normalize();
            let l = len * uniform(rng, 0.3, 0.5);
            b.cone(s, s + d * l, 0.35 * rb, 0.05 * rb, 5, 1, true);
        }
    }
    // Leaves in the crown ellipsoid, denser towards its surface.
    b.use_material("leaf", Vec3::new(0.12, 0.35, 0.08), Vec3::ZERO);
    let axes = Vec3::new(crown_r, crown_h, crown_r);
    for _ in 0..leaves {
        let s = rng.next_f32().powf(0.25);
        let c = crown_c + unit(rng) * axes * s;
        let n = unit(rng);
        let spin = Quat::from_axis_angle(n, uniform(rng, 0.0, std::f32::consts::TAU));
        let e1 = spin * n.any_orthonormal_vector();
        let e2 = n.cross(e1);
        let len = uniform(rng, 0.12, 0.2);
        let wid = len * uniform(rng, 0.45, 0.65);
        // Diamond p0 → p1 → p2 → p3 counter-clockwise about n (e1 × e2 = n).
        b.quad([
            c - e1 * (0.5 * len),
            c - e2 * (0.5 * wid),
            c + e1 * (0.5 * len),
            c + e2 * (0.5 * wid),
        ]);
    }
}

/// The trees scene with `n` trees (see the module docs).
pub fn trees(n: u32, seed: u64) -> RawScene {
    let mut b = MeshBuilder::new();
    let mut rng = SplitMix64::new(seed);
    b.begin_object("ground");
    b.use_material("ground", Vec3::new(0.18, 0.24, 0.1), Vec3::ZERO);
    let g = GROUND_HALF;
    b.grid(
        Vec3::new(-g, 0.0, -g),
        Vec3::Z * (2.0 * g),
        Vec3::X * (2.0 * g),
        GROUND_CELLS,
        GROUND_CELLS,
    );
    for (k, p) in positions(n, &mut rng).into_iter().enumerate() {
        let mut tr = SplitMix64::for_item(seed, k as u64);
        tree(&mut b, &mut tr, p, k, LEAVES_PER_TREE);
    }
    let cams = vec![
        camera(
            "default",
            Vec3::new(-4.0, 16.0, -26.0),
            Vec3::new(2.0, 0.0, 2.0),
            50.0,
            640,
            480,
        ),
        camera(
            "top",
            Vec3::new(0.0, 35.0, -8.0),
            Vec3::ZERO,
            55.0,
            640,
            480,
        ),
        camera(
            "ground",
            Vec3::new(-16.0, 1.7, -16.0),
            Vec3::new(0.0, 4.0, 0.0),
            60.0,
            640,
            480,
        ),
    ];
    let mut raw = b.finish("trees", UpAxis::Y, cams);
    raw.sun = Some(Sun {
        direction: sun_direction(),
        irradiance: SUN_IRRADIANCE,
    });
    raw.sky = Some(SKY_RADIANCE);
    raw
}
