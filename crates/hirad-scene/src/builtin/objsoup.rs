//! OBJSOUP: a few finely tessellated objects in a room, delivered as a polygon soup of the
//! paper's AIRCRAFT/CAR kind (issue 23).
//!
//! An 8 × 3 × 6 m room (+Y up; floor, walls and ceiling in three materials) lit by one ceiling
//! panel (1 × 1 m at y = 2.95 facing down, L_e = [`LIGHT_EMISSION`]) holds [`NUM_SOLIDS`]
//! closed solids, each in its own material and apart from the others: two spheres, a box on
//! the floor, a rotated tall box, a tilted torus, a capped cylinder and a cone. `objsoup:N`
//! asks for about N triangles (default [`DEFAULT_TRIANGLES`]): one edge length h for every
//! surface, chosen from a trial build. Then every triangle gets its own three vertices (no
//! vertex is shared), the corners of each triangle are rotated cyclically at random (the
//! winding, hence the facing, is kept), the triangles are shuffled and all get object id 0.
//! [`objsoup_truth`] also returns the object each triangle was tessellated from: the room's
//! floor, walls, ceiling, light and the solids, [`NUM_OBJECTS`] in all.

use super::mesh::{camera, MeshBuilder};
use crate::{RawScene, UpAxis};
use glam::{Affine3A, Quat, Vec3};
use hirad_core::rng::SplitMix64;
use std::f32::consts::TAU;

/// Default triangle count of `objsoup`.
pub const DEFAULT_TRIANGLES: u64 = 20_000;
/// Emitted radiance of the ceiling panel, W/(m²·sr).
pub const LIGHT_EMISSION: Vec3 = Vec3::new(30.0, 29.0, 26.0);
/// Room size (x, y, z), metres.
pub const ROOM: Vec3 = Vec3::new(8.0, 3.0, 6.0);
/// Closed solids in the room.
pub const NUM_SOLIDS: usize = 7;
/// Objects tessellated: floor, walls, ceiling, light and the solids.
pub const NUM_OBJECTS: usize = 4 + NUM_SOLIDS;

fn cells(len: f32, h: f32) -> u32 {
    ((len / h).ceil() as u32).max(1)
}

fn around(r: f32, h: f32) -> u32 {
    ((TAU * r / h).ceil() as u32).max(8)
}

/// Torus around `c` with axis `axis`, radii `big` and `small`, facing outwards.
fn torus(b: &mut MeshBuilder, c: Vec3, axis: Quat, big: f32, small: f32, h: f32) {
    let (nu, nv) = (around(big + small, h), around(small, h).max(6));
    let base = b.positions.len() as u32;
    for i in 0..nu {
        let u = TAU * i as f32 / nu as f32;
        for j in 0..nv {
            let v = TAU * j as f32 / nv as f32;
            let ring = big + small * v.cos();
            let p = Vec3::new(ring * u.cos(), small * v.sin(), ring * u.sin());
            b.vertex(c + axis * p);
        }
    }
    let idx = |i: u32, j: u32| base + (i % nu) * nv + (j % nv);
    for i in 0..nu {
        for j in 0..nv {
            let (a, bb, cc, d) = (idx(i, j), idx(i + 1, j), idx(i + 1, j + 1), idx(i, j + 1));
            // (u, v) runs so that ∂u × ∂v points into the tube: use the reverse winding.
            b.tri(a, cc, bb);
            b.tri(a, d, cc);
        }
    }
}

/// The room and its objects at edge length `h`, one builder object per tessellated object.
fn layout(h: f32) -> MeshBuilder {
    let mut b = MeshBuilder::new();
    let (x, y, z) = (ROOM.x, ROOM.y, ROOM.z);
    let id = Affine3A::IDENTITY;
    let grey = |g: f32| Vec3::splat(g);
    b.begin_object("floor");
    b.use_material("floor", grey(0.45), Vec3::ZERO);
    b.grid(
        Vec3::ZERO,
        Vec3::Z * z,
        Vec3::X * x,
        cells(z, h),
        cells(x, h),
    );
    b.begin_object("walls");
    b.use_material("wall", grey(0.7), Vec3::ZERO);
    let n = [cells(x, h), cells(y, h), cells(z, h)];
    b.cuboid_subdiv(&id, Vec3::ZERO, ROOM, true, 4 | 8, n);
    b.begin_object("ceiling");
    b.use_material("ceiling", grey(0.8), Vec3::ZERO);
    b.grid(Vec3::Y * y, Vec3::X * x, Vec3::Z * z, n[0], n[2]);
    b.begin_object("light");
    b.use_material("light", grey(0.8), LIGHT_EMISSION);
    let lo = Vec3::new(x / 2.0 - 0.5, y - 0.05, z / 2.0 - 0.5);
    b.grid(lo, Vec3::X, Vec3::Z, cells(1.0, h), cells(1.0, h));

    let solid = |b: &mut MeshBuilder, name: &str, rho: [f32; 3]| {
        b.begin_object(name);
        b.use_material(name, Vec3::from_array(rho), Vec3::ZERO);
    };
    solid(&mut b, "sphere-red", [0.7, 0.15, 0.12]);
    let s = around(0.6, h);
    b.sphere(Vec3::new(2.0, 0.8, 2.0), 0.6, s, (s / 2).max(4), false);
    solid(&mut b, "sphere-blue", [0.15, 0.25, 0.7]);
    let s = around(0.4, h);
    b.sphere(Vec3::new(6.0, 0.5, 4.6), 0.4, s, (s / 2).max(4), false);
    solid(&mut b, "box", [0.6, 0.6, 0.55]);
    let (bmin, bmax) = (Vec3::new(3.5, 0.0, 3.0), Vec3::new(4.7, 0.9, 4.2));
    let e = bmax - bmin;
    b.cuboid_subdiv(
        &id,
        bmin,
        bmax,
        false,
        0,
        [cells(e.x, h), cells(e.y, h), cells(e.z, h)],
    );
    solid(&mut b, "tall-box", [0.55, 0.4, 0.25]);
    let xf =
        Affine3A::from_rotation_translation(Quat::from_rotation_y(0.5), Vec3::new(5.9, 0.0, 1.4));
    let (bmin, bmax) = (Vec3::new(-0.4, 0.0, -0.4), Vec3::new(0.4, 1.6, 0.4));
    let e = bmax - bmin;
    b.cuboid_subdiv(
        &xf,
        bmin,
        bmax,
        false,
        0,
        [cells(e.x, h), cells(e.y, h), cells(e.z, h)],
    );
    solid(&mut b, "torus", [0.75, 0.65, 0.15]);
    let tilt = Quat::from_rotation_x(0.6) * Quat::from_rotation_z(0.3);
    torus(&mut b, Vec3::new(2.6, 1.3, 4.5), tilt, 0.5, 0.15, h);
    solid(&mut b, "cylinder", [0.2, 0.6, 0.25]);
    let (a, c) = (Vec3::new(6.9, 0.0, 3.2), Vec3::new(6.9, 1.2, 3.2));
    b.cylinder(a, c, 0.3, around(0.3, h), cells(1.2, h), true);
    solid(&mut b, "cone", [0.8, 0.8, 0.78]);
    let (a, c) = (Vec3::new(1.0, 0.0, 4.8), Vec3::new(1.0, 1.0, 4.8));
    b.cone(a, c, 0.35, 0.0, around(0.35, h), cells(1.0, h), true);
    debug_assert_eq!(b.objects.len(), NUM_OBJECTS);
    b
}

/// The scene and, per triangle, the object it was tessellated from (see the module docs).
pub fn objsoup_truth(n: u64, seed: u64) -> (RawScene, Vec<u32>) {
    // Triangle counts scale as 1/h²: one trial build, then one rescaled.
    let trial = 0.2f32;
    let count = layout(trial).num_triangles() as f64;
    let h = trial * (count / n.max(1) as f64).sqrt() as f32;
    let b = layout(h.clamp(1e-3, 10.0));
    let mut rng = SplitMix64::new(seed ^ 0x4F42_4A53_4F55_5021);
    let nt = b.triangles.len();
    let mut order: Vec<usize> = (0..nt).collect();
    for i in (1..nt).rev() {
        let j = (rng.next_u64() % (i as u64 + 1)) as usize;
        order.swap(i, j);
    }
    let mut out = MeshBuilder::new();
    out.materials = b.materials.clone();
    out.begin_object("objsoup");
    out.positions.reserve(3 * nt);
    let mut truth = Vec::with_capacity(nt);
    for &t in &order {
        let [p, q, r] = b.triangles[t].map(|v| b.positions[v as usize]);
        let corners = match rng.next_u64() % 3 {
            0 => [p, q, r],
            1 => [q, r, p],
            _ => [r, p, q],
        };
        let v = corners.map(|c| out.vertex(c));
        out.mat = b.tri_material[t];
        out.tri(v[0], v[1], v[2]);
        truth.push(b.tri_object[t]);
    }
    let cams = vec![
        camera(
            "default",
            Vec3::new(0.4, 1.7, 0.4),
            Vec3::new(5.0, 0.7, 4.5),
            70.0,
            640,
            480,
        ),
        camera(
            "back",
            Vec3::new(7.6, 2.2, 5.6),
            Vec3::new(2.5, 0.6, 1.5),
            70.0,
            640,
            480,
        ),
    ];
    (out.finish("objsoup", UpAxis::Y, cams), truth)
}

/// The OBJSOUP scene with about `n` triangles.
pub fn objsoup(n: u64, seed: u64) -> RawScene {
    objsoup_truth(n, seed).0
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn size_and_soup_structure() {
        let (s, truth) = objsoup_truth(20_000, 1);
        let nt = s.triangles.len();
        assert!((nt as f64 / 20_000.0 - 1.0).abs() < 0.15, "{nt}");
        // No vertex shared, every object present, object ids all 0.
        assert_eq!(s.positions.len(), 3 * nt);
        assert!(s
            .triangles
            .iter()
            .flatten()
            .enumerate()
            .all(|(i, &v)| v as usize == i));
        assert!(s.tri_object.iter().all(|&o| o == 0));
        let mut seen = [false; NUM_OBJECTS];
        for &o in &truth {
            seen[o as usize] = true;
        }
        assert!(seen.iter().all(|&x| x));
        // Deterministic, and the seed changes the order.
        assert_eq!(objsoup_truth(20_000, 1).1, truth);
        assert_ne!(objsoup_truth(20_000, 2).1, truth);
    }
}
