//! SOUP: a finely tessellated industrial hall delivered as a polygon soup.
//!
//! The hall is a row of 6 m bays (24 m deep, 12 m high): I-beam columns and roof girders,
//! purlins, a vertical tank on legs with a conical top, a machine, stacked crates, a mezzanine
//! walkway of grating bars with railings, pipe runs with flanges, and hanging light panels
//! (1.2 × 0.6 m facing down, L_e = (60, 58, 52) W/(m²·sr): floor irradiance of a few W/m²,
//! pixel radiances about 0.1–1, no exposure correction needed).
//!
//! `soup:N` asks for about N triangles: `clamp(round(N / 25000), 1, 12)` bays, then one edge
//! length h (primitives tessellated into cells of edge ≤ h, the hall shell ≤ 4h) chosen so the
//! triangle count, computed exactly before building, is as close to N as possible (one bay at
//! its coarsest has 1,916 triangles). Triangles and vertices are then shuffled and all get
//! object id 0; the winding stays consistent (closed solids face outwards, the hall inwards).
//! Random choices come from the seed. +Y up.

use super::mesh::{camera, MeshBuilder};
use crate::{RawScene, UpAxis};
use glam::{Affine3A, Vec3};
use hirad_core::rng::SplitMix64;

/// Default triangle count of `soup`.
pub const DEFAULT_TRIANGLES: u64 = 200_000;
/// Emitted radiance of the light panels, W/(m²·sr).
pub const LIGHT_EMISSION: Vec3 = Vec3::new(60.0, 58.0, 52.0);
/// Size of one light panel (x, z), metres.
pub const LIGHT_SIZE: (f32, f32) = (1.2, 0.6);
/// Light panels per bay.
pub const LIGHTS_PER_BAY: usize = 4;
/// Bay length along x, metres.
pub const BAY: f32 = 6.0;
/// Hall depth along z, metres.
pub const DEPTH: f32 = 24.0;
/// Hall height along y, metres.
pub const HEIGHT: f32 = 12.0;
/// Height of the emitting face of the light panels.
pub const LIGHT_Y: f32 = 10.4;

/// Number of bays for a requested triangle count.
pub fn bays_for(n: u64) -> u32 {
    ((n as f64 / 25_000.0).round() as u32).clamp(1, 12)
}

#[derive(Clone, Debug)]
enum Shape {
    /// Parallelogram facing u × v.
    Grid { o: Vec3, u: Vec3, v: Vec3 },
    /// Box under a rigid transform.
    Box {
        xf: Affine3A,
        min: Vec3,
        max: Vec3,
        inward: bool,
    },
    /// Truncated cone, capped.
    Cone { a: Vec3, b: Vec3, ra: f32, rb: f32 },
    /// Sphere.
    Sphere { c: Vec3, r: f32 },
}

#[derive(Clone, Debug)]
struct Prim {
    shape: Shape,
    mat: u32,
    /// Multiplier of the edge length h (the hall shell is coarser).
    coarse: f32,
}

fn cells(len: f32, h: f32) -> u32 {
    ((len / h).ceil() as u32).max(1)
}

fn segments(r: f32, h: f32) -> u32 {
    ((std::f32::consts::TAU * r / h).ceil() as u32).max(6)
}

impl Prim {
    fn box_cells(min: Vec3, max: Vec3, h: f32) -> [u32; 3] {
        let e = max - min;
        [cells(e.x, h), cells(e.y, h), cells(e.z, h)]
    }

    fn count(&self, h: f32) -> u64 {
        let h = h * self.coarse;
        match &self.shape {
            Shape::Grid { u, v, .. } => {
                2 * cells(u.length(), h) as u64 * cells(v.length(), h) as u64
            }
            Shape::Box { min, max, .. } => {
                let [a, b, c] = Self::box_cells(*min, *max, h).map(|x| x as u64);
                4 * (a * b + b * c + a * c)
            }
            Shape::Cone { a, b, ra, rb } => {
                let s = segments(ra.max(*rb), h) as u64;
                let rings = cells((*b - *a).length(), h) as u64;
                let apex = (*ra <= 0.0) as u64 + (*rb <= 0.0) as u64;
                2 * s * rings - apex * s + (2 - apex) * s
            }
            Shape::Sphere { r, .. } => {
                let s = segments(*r, h) as u64;
                let stacks = (s / 2).max(3);
                2 * s + 2 * s * (stacks - 2)
            }
        }
    }

    fn build(&self, b: &mut MeshBuilder, h: f32) {
        let h = h * self.coarse;
        b.mat = self.mat;
        match &self.shape {
            Shape::Grid { o, u, v } => {
                b.grid(*o, *u, *v, cells(u.length(), h), cells(v.length(), h));
            }
            Shape::Box {
                xf,
                min,
                max,
                inward,
            } => b.cuboid_subdiv(xf, *min, *max, *inward, 0, Self::box_cells(*min, *max, h)),
            Shape::Cone { a, b: e, ra, rb } => {
                let s = segments(ra.max(*rb), h);
                b.cone(*a, *e, *ra, *rb, s, cells((*e - *a).length(), h), true);
            }
            Shape::Sphere { c, r } => {
                let s = segments(*r, h);
                b.sphere(*c, *r, s, (s / 2).max(3), false);
            }
        }
    }
}

struct Layout {
    b: MeshBuilder,
    prims: Vec<Prim>,
    rng: SplitMix64,
}

impl Layout {
    fn uniform(&mut self, lo: f32, hi: f32) -> f32 {
        lo + (hi - lo) * self.rng.next_f32()
    }

    fn mat(&mut self, name: &str, rho: [f32; 3]) -> u32 {
        self.b.material(name, Vec3::from_array(rho), Vec3::ZERO)
    }

    fn push(&mut self, shape: Shape, mat: u32) {
        self.prims.push(Prim {
            shape,
            mat,
            coarse: 1.0,
        });
    }

    fn cuboid(&mut self, min: Vec3, max: Vec3, mat: u32) {
        self.push(
            Shape::Box {
                xf: Affine3A::IDENTITY,
                min,
                max,
                inward: false,
            },
            mat,
        );
    }

    fn cyl(&mut self, a: Vec3, b: Vec3, r: f32, mat: u32) {
        self.push(Shape::Cone { a, b, ra: r, rb: r }, mat);
    }

    /// I-beam along the axis-aligned segment `a`–`b`: flanges of width `w` along the positive
    /// axis vector `side`, depth `d` along the positive axis vector `up`.
    #[allow(clippy::too_many_arguments)]
    fn ibeam(&mut self, a: Vec3, b: Vec3, side: Vec3, up: Vec3, w: f32, d: f32, mat: u32) {
        let t = 0.02;
        let parts = [
            ((-w / 2.0, w / 2.0), (d / 2.0 - t, d / 2.0)),
            ((-w / 2.0, w / 2.0), (-d / 2.0, -d / 2.0 + t)),
            ((-t / 2.0, t / 2.0), (-d / 2.0 + t, d / 2.0 - t)),
        ];
        for ((s0, s1), (u0, u1)) in parts {
            let lo = a.min(b) + side * s0 + up * u0;
            let hi = a.max(b) + side * s1 + up * u1;
            self.cuboid(lo, hi, mat);
        }
    }
}

/// Place the primitives of a hall of `bays` bays.
fn layout(bays: u32, seed: u64) -> Layout {
    let mut l = Layout {
        b: MeshBuilder::new(),
        prims: Vec::new(),
        rng: SplitMix64::new(seed),
    };
    let len = bays as f32 * BAY;
    let concrete = l.mat("concrete", [0.35, 0.34, 0.32]);
    l.prims.push(Prim {
        shape: Shape::Box {
            xf: Affine3A::IDENTITY,
            min: Vec3::ZERO,
            max: Vec3::new(len, HEIGHT, DEPTH),
            inward: true,
        },
        mat: concrete,
        coarse: 4.0,
    });
    let steel = l.mat("painted_steel", [0.6, 0.35, 0.1]);
    let tank_m = l.mat("tank", [0.5, 0.55, 0.6]);
    let grating = l.mat("grating", [0.3, 0.3, 0.3]);
    let railing = l.mat("railing", [0.8, 0.65, 0.1]);
    let wood = l.mat("crate_wood", [0.55, 0.4, 0.25]);
    let machine = l.mat("machine", [0.2, 0.4, 0.3]);
    let cabinet = l.mat("cabinet", [0.7, 0.7, 0.68]);
    let housing = l.mat("light_housing", [0.7, 0.7, 0.7]);
    let panel =
        l.b.material("light_panel", Vec3::splat(0.8), LIGHT_EMISSION);
    let pipe_mats = [
        l.mat("pipe_red", [0.7, 0.15, 0.1]),
        l.mat("pipe_blue", [0.2, 0.4, 0.6]),
        l.mat("pipe_yellow", [0.7, 0.7, 0.2]),
        l.mat("pipe_grey", [0.5, 0.5, 0.5]),
    ];
    // Pipe runs along the hall: (height, z, radius, material).
    let pipes: Vec<(f32, f32, f32, u32)> = (0..6)
        .map(|_| {
            let y = l.uniform(6.0, 9.5);
            let z = l.uniform(1.5, 22.5);
            let r = l.uniform(0.06, 0.3);
            let m = pipe_mats[(l.rng.next_u64() % 4) as usize];
            (y, z, r, m)
        })
        .collect();
    let (lw, ld) = LIGHT_SIZE;
    for bay in 0..bays {
        let x0 = bay as f32 * BAY;
        let xc = x0 + BAY / 2.0;
        // Columns (and the closing pair after the last bay) with their roof girders.
        let mut cols = vec![x0];
        if bay + 1 == bays {
            cols.push(len);
        }
        for cx in cols {
            let cx = cx.clamp(0.2, len - 0.2);
            for cz in [0.25, DEPTH - 0.25] {
                l.ibeam(
                    Vec3::new(cx, 0.0, cz),
                    Vec3::new(cx, 11.0, cz),
                    Vec3::X,
                    Vec3::Z,
                    0.3,
                    0.4,
                    steel,
                );
            }
            l.ibeam(
                Vec3::new(cx, 11.3, 0.0),
                Vec3::new(cx, 11.3, DEPTH),
                Vec3::X,
                Vec3::Y,
                0.3,
                0.6,
                steel,
            );
        }
        for pz in [6.0, 12.0, 18.0] {
            l.cuboid(
                Vec3::new(x0, 11.6, pz - 0.05),
                Vec3::new(x0 + BAY, 11.75, pz + 0.05),
                steel,
            );
        }
        // Hanging light panels.
        for k in 0..LIGHTS_PER_BAY {
            let z = 4.0 + k as f32 * (16.0 / (LIGHTS_PER_BAY - 1) as f32);
            l.cuboid(
                Vec3::new(xc - lw / 2.0 - 0.05, LIGHT_Y + 0.001, z - ld / 2.0 - 0.05),
                Vec3::new(xc + lw / 2.0 + 0.05, LIGHT_Y + 0.12, z + ld / 2.0 + 0.05),
                housing,
            );
            l.push(
                Shape::Grid {
                    o: Vec3::new(xc - lw / 2.0, LIGHT_Y, z - ld / 2.0),
                    u: Vec3::X * lw,
                    v: Vec3::Z * ld,
                },
                panel,
            );
            for dx in [-0.4, 0.4] {
                l.cyl(
                    Vec3::new(xc + dx, LIGHT_Y + 0.12, z),
                    Vec3::new(xc + dx, 11.0, z),
                    0.01,
                    steel,
                );
            }
        }
        // A vertical tank on legs, with a riser pipe.
        let r = l.uniform(1.0, 1.8);
        let h = l.uniform(3.0, 5.5);
        let c = Vec3::new(xc + l.uniform(-0.5, 0.5), 0.0, l.uniform(3.5, 6.5));
        for (sx, sz) in [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)] {
            let p = c + Vec3::new(sx * 0.65 * r, 0.0, sz * 0.65 * r);
            l.cuboid(
                p - Vec3::new(0.08, 0.0, 0.08),
                p + Vec3::new(0.08, 0.85, 0.08),
                steel,
            );
        }
        let top = c + Vec3::Y * (0.8 + h);
        l.cyl(c + Vec3::Y * 0.8, top, r, tank_m);
        l.push(
            Shape::Cone {
                a: top,
                b: top + Vec3::Y * 0.6 * r,
                ra: r,
                rb: 0.15 * r,
            },
            tank_m,
        );
        let riser_r = 0.12 * r.min(1.2);
        let elbow = Vec3::new(c.x, 9.8, c.z);
        l.cyl(top + Vec3::Y * 0.6 * r, elbow, riser_r, pipe_mats[0]);
        l.push(
            Shape::Sphere {
                c: elbow,
                r: riser_r,
            },
            pipe_mats[0],
        );
        l.cyl(elbow, Vec3::new(c.x, 9.8, 16.0), riser_r, pipe_mats[0]);
        // A machine: base, motor with end bell, fan housing, feet, control cabinet.
        l.cuboid(
            Vec3::new(xc - 1.2, 0.0, 10.5),
            Vec3::new(xc + 1.2, 0.4, 12.5),
            machine,
        );
        let my = 0.9;
        l.cyl(
            Vec3::new(xc - 1.0, my, 11.5),
            Vec3::new(xc + 0.2, my, 11.5),
            0.5,
            machine,
        );
        l.push(
            Shape::Sphere {
                c: Vec3::new(xc - 1.0, my, 11.5),
                r: 0.3,
            },
            machine,
        );
        l.cyl(
            Vec3::new(xc + 0.2, my, 11.5),
            Vec3::new(xc + 0.9, my, 11.5),
            0.55,
            steel,
        );
        for fx in [-0.8, 0.0] {
            l.cuboid(
                Vec3::new(xc + fx - 0.1, 0.4, 11.1),
                Vec3::new(xc + fx + 0.1, 0.5, 11.9),
                steel,
            );
        }
        l.cuboid(
            Vec3::new(xc - 0.5, 0.0, 13.0),
            Vec3::new(xc + 0.5, 2.0, 13.5),
            cabinet,
        );
        // Crates, some stacked.
        let mut cx = x0 + 0.3;
        loop {
            let s = l.uniform(0.6, 1.2);
            if cx + s > x0 + BAY - 0.3 {
                break;
            }
            let z = l.uniform(14.2, 16.6 - s);
            l.cuboid(Vec3::new(cx, 0.0, z), Vec3::new(cx + s, s, z + s), wood);
            if l.rng.next_f32() < 0.4 {
                let t = s * l.uniform(0.5, 0.8);
                let o = (s - t) * l.rng.next_f32();
                l.cuboid(
                    Vec3::new(cx + o, s, z + o),
                    Vec3::new(cx + o + t, s + t, z + o + t),
                    wood,
                );
            }
            cx += s + l.uniform(0.1, 0.5);
        }
        // Mezzanine walkway: grating bars, cross bars, a deck beam, a post, railings.
        let (zm, y) = (18.0, 4.0);
        let n_bars = (BAY / 0.25) as u32;
        for k in 0..n_bars {
            let x = x0 + 0.125 + k as f32 * 0.25;
            l.cuboid(
                Vec3::new(x - 0.015, y - 0.05, zm),
                Vec3::new(x + 0.015, y, DEPTH - 0.05),
                grating,
            );
        }
        for k in 0..5 {
            let z = zm + 0.2 + k as f32 * 1.4;
            l.cuboid(
                Vec3::new(x0, y - 0.1, z - 0.02),
                Vec3::new(x0 + BAY, y - 0.05, z + 0.02),
                grating,
            );
        }
        l.ibeam(
            Vec3::new(x0, y - 0.25, zm + 0.1),
            Vec3::new(x0 + BAY, y - 0.25, zm + 0.1),
            Vec3::Z,
            Vec3::Y,
            0.2,
            0.3,
            steel,
        );
        l.cuboid(
            Vec3::new(xc - 0.075, 0.0, zm + 0.1),
            Vec3::new(xc + 0.075, y - 0.4, zm + 0.25),
            steel,
        );
        for k in 0..4 {
            let x = x0 + 0.75 + 1.5 * k as f32;
            l.cyl(
                Vec3::new(x, y, zm + 0.05),
                Vec3::new(x, y + 1.1, zm + 0.05),
                0.025,
                railing,
            );
        }
        for ry in [y + 0.55, y + 1.1] {
            l.cyl(
                Vec3::new(x0, ry, zm + 0.05),
                Vec3::new(x0 + BAY, ry, zm + 0.05),
                0.025,
                railing,
            );
        }
        l.cuboid(
            Vec3::new(x0, y, zm),
            Vec3::new(x0 + BAY, y + 0.15, zm + 0.02),
            railing,
        );
        // Pipe runs with a flange per bay.
        for &(py, pz, pr, pm) in &pipes {
            l.cyl(Vec3::new(x0, py, pz), Vec3::new(x0 + BAY, py, pz), pr, pm);
            let fx = x0 + 0.3;
            l.cyl(
                Vec3::new(fx, py, pz),
                Vec3::new(fx + 0.06, py, pz),
                pr * 1.35,
                pm,
            );
        }
    }
    // Stairs up to the mezzanine in the first bay.
    let steps = 16;
    for k in 0..steps {
        let x = 0.5 + k as f32 * 0.25;
        let top = 4.0 * (k + 1) as f32 / steps as f32;
        l.cuboid(
            Vec3::new(x, 0.0, 16.8),
            Vec3::new(x + 0.25, top, 17.9),
            steel,
        );
    }
    l
}

/// Total triangle count of the primitives at edge length `h`.
fn count(prims: &[Prim], h: f32) -> u64 {
    prims.iter().map(|p| p.count(h)).sum()
}

/// Edge length giving a triangle count closest to `n`.
fn edge_length_for(prims: &[Prim], n: u64) -> f32 {
    let (mut lo, mut hi) = (1e-3f64, 100.0f64);
    let mut best = (u64::MAX, hi as f32);
    for _ in 0..64 {
        let mid = (lo * hi).sqrt();
        let c = count(prims, mid as f32);
        let d = c.abs_diff(n);
        if d < best.0 {
            best = (d, mid as f32);
        }
        if c > n {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    best.1
}

/// The soup scene with about `n` triangles (see the module docs).
pub fn soup(n: u64, seed: u64) -> RawScene {
    let bays = bays_for(n);
    let mut l = layout(bays, seed);
    let h = edge_length_for(&l.prims, n);
    let total = count(&l.prims, h) as usize;
    l.b.begin_object("soup");
    l.b.positions.reserve(total * 2);
    l.b.triangles.reserve(total);
    for p in &l.prims {
        p.build(&mut l.b, h);
    }
    debug_assert_eq!(l.b.num_triangles(), total);
    let mut b = l.b;
    // Shuffle the triangles and renumber the vertices in a random order.
    let mut rng = SplitMix64::new(seed ^ 0x5348_5546_464C_4521);
    let nt = b.triangles.len();
    for i in (1..nt).rev() {
        let j = (rng.next_u64() % (i as u64 + 1)) as usize;
        b.triangles.swap(i, j);
        b.tri_material.swap(i, j);
    }
    let nv = b.positions.len();
    let mut perm: Vec<u32> = (0..nv as u32).collect();
    for i in (1..nv).rev() {
        let j = (rng.next_u64() % (i as u64 + 1)) as usize;
        perm.swap(i, j);
    }
    let mut positions = vec![Vec3::ZERO; nv];
    for (old, &new) in perm.iter().enumerate() {
        positions[new as usize] = b.positions[old];
    }
    b.positions = positions;
    for t in &mut b.triangles {
        *t = t.map(|v| perm[v as usize]);
    }
    let len = bays as f32 * BAY;
    let cams = vec![
        camera(
            "default",
            Vec3::new(0.6, 2.8, 9.0),
            Vec3::new(len * 0.7, 3.0, 11.0),
            65.0,
            640,
            480,
        ),
        camera(
            "mezzanine",
            Vec3::new(len - 1.0, 5.6, 19.5),
            Vec3::new(len * 0.3, 1.0, 8.0),
            65.0,
            640,
            480,
        ),
    ];
    b.finish("soup", UpAxis::Y, cams)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn predicted_count_matches_the_built_mesh() {
        let l = layout(2, 3);
        for h in [0.05f32, 0.3, 1.0, 5.0] {
            let mut b = MeshBuilder::new();
            for p in &l.prims {
                let before = b.num_triangles();
                p.build(&mut b, h);
                assert_eq!(
                    (b.num_triangles() - before) as u64,
                    p.count(h),
                    "{:?} at h = {h}",
                    p.shape
                );
            }
        }
    }

    #[test]
    fn size_parameter_controls_the_count() {
        for n in [20_000u64, 60_000] {
            let s = soup(n, 1);
            let got = s.triangles.len() as f64;
            assert!((got / n as f64 - 1.0).abs() < 0.03, "{n}: {got}");
        }
    }
}
