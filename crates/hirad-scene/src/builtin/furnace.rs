//! The furnace test scenes: closed enclosures of uniform ρ = 0.5 and emitted radiance
//! L_e = 1/π (exitance E = 1 W/m²), every surface facing inwards, so that the exact radiosity is
//! B = E / (1 − ρ) = 2 W/m² everywhere (`spec/radiosity.md`, correctness test 1).

use super::mesh::{camera, MeshBuilder};
use crate::{RawScene, UpAxis};
use glam::{Affine3A, Vec3};

/// Reflectance of every furnace surface.
pub const RHO: f32 = 0.5;
/// Emitted radiance of every furnace surface, W/(m²·sr): exitance π·L_e = 1 W/m².
pub const EMISSION: f32 = std::f32::consts::FRAC_1_PI;

fn material(b: &mut MeshBuilder) {
    b.use_material("furnace", Vec3::splat(RHO), Vec3::splat(EMISSION));
}

/// Unit cube [−0.5, 0.5]³, each face an `n × n` grid (12·n² triangles), welded so that every
/// edge is shared by exactly two triangles, all facing the centre.
pub fn cube(n: u32) -> RawScene {
    let mut b = MeshBuilder::new();
    material(&mut b);
    b.begin_object("cube");
    b.cuboid_subdiv(
        &Affine3A::IDENTITY,
        Vec3::splat(-0.5),
        Vec3::splat(0.5),
        true,
        0,
        [n, n, n],
    );
    b.weld(1e-5 / n as f32);
    let cams = vec![camera(
        "default",
        Vec3::new(0.0, 0.0, 0.45),
        Vec3::new(0.0, 0.0, -0.5),
        90.0,
        256,
        256,
    )];
    b.finish("furnace", UpAxis::Y, cams)
}

/// Sphere of radius 0.5 at the origin, `segments` around and `segments / 2` stacks, closed (the
/// poles are single vertices), all facing the centre.
pub fn sphere(segments: u32) -> RawScene {
    let mut b = MeshBuilder::new();
    material(&mut b);
    b.begin_object("sphere");
    b.sphere(Vec3::ZERO, 0.5, segments, (segments / 2).max(2), true);
    let cams = vec![camera(
        "default",
        Vec3::new(0.0, 0.0, 0.4),
        Vec3::new(0.0, 0.0, -0.5),
        90.0,
        256,
        256,
    )];
    b.finish("furnace-sphere", UpAxis::Y, cams)
}
