//! The Cornell box: geometry measured by the Cornell University Program of Computer Graphics
//! ("Cornell Box Data", <https://www.graphics.cornell.edu/online/box/data.html>), millimetres
//! scaled to metres, +Y up, the camera looking along +Z into the open side.
//!
//! Reflectances are the RGB values commonly used for this box (e.g. the Mitsuba / PBRT / LuxCore
//! RGB scenes): white (0.725, 0.71, 0.68), red (0.63, 0.065, 0.05), green (0.14, 0.45, 0.091);
//! the light emits L_e = (17, 12, 4) W/(m²·sr) over 0.130 × 0.105 m, i.e. Φ = π·L_e·A ≈
//! (0.729, 0.515, 0.172) W, which with the camera below gives pixel radiances of about 0.1–1 on
//! the walls (exposure 1 is sensible) and (17, 12, 4) on the light itself. The light is a
//! separate quad 0.1 mm below the ceiling, facing down. Every quad is two triangles; walls face
//! into the box and blocks face outwards, so every surface faces the space where the light is.

use super::mesh::{camera, MeshBuilder};
use crate::{RawScene, UpAxis};
use glam::Vec3;

/// Emitted radiance of the light, W/(m²·sr).
pub const LIGHT_EMISSION: Vec3 = Vec3::new(17.0, 12.0, 4.0);
/// Reflectance of the white surfaces.
pub const WHITE: Vec3 = Vec3::new(0.725, 0.71, 0.68);
/// Reflectance of the red (left, +X) wall.
pub const RED: Vec3 = Vec3::new(0.63, 0.065, 0.05);
/// Reflectance of the green (right, x = 0) wall.
pub const GREEN: Vec3 = Vec3::new(0.14, 0.45, 0.091);
/// Reflectance of the light fixture.
pub const LIGHT_RHO: Vec3 = Vec3::new(0.78, 0.78, 0.78);

/// The objects of the box: name, material, quads in millimetres (counter-clockwise seen from
/// the side they face).
type Part = (&'static str, &'static str, &'static [[[f32; 3]; 4]]);

const PARTS: &[Part] = &[
    (
        "floor",
        "white",
        &[[
            [552.8, 0.0, 0.0],
            [0.0, 0.0, 0.0],
            [0.0, 0.0, 559.2],
            [549.6, 0.0, 559.2],
        ]],
    ),
    (
        "ceiling",
        "white",
        &[[
            [556.0, 548.8, 0.0],
            [556.0, 548.8, 559.2],
            [0.0, 548.8, 559.2],
            [0.0, 548.8, 0.0],
        ]],
    ),
    (
        "back_wall",
        "white",
        &[[
            [549.6, 0.0, 559.2],
            [0.0, 0.0, 559.2],
            [0.0, 548.8, 559.2],
            [556.0, 548.8, 559.2],
        ]],
    ),
    (
        "right_wall",
        "green",
        &[[
            [0.0, 0.0, 559.2],
            [0.0, 0.0, 0.0],
            [0.0, 548.8, 0.0],
            [0.0, 548.8, 559.2],
        ]],
    ),
    (
        "left_wall",
        "red",
        &[[
            [552.8, 0.0, 0.0],
            [549.6, 0.0, 559.2],
            [556.0, 548.8, 559.2],
            [556.0, 548.8, 0.0],
        ]],
    ),
    (
        "short_block",
        "white",
        &[
            [
                [130.0, 165.0, 65.0],
                [82.0, 165.0, 225.0],
                [240.0, 165.0, 272.0],
                [290.0, 165.0, 114.0],
            ],
            [
                [290.0, 0.0, 114.0],
                [290.0, 165.0, 114.0],
                [240.0, 165.0, 272.0],
                [240.0, 0.0, 272.0],
            ],
            [
                [130.0, 0.0, 65.0],
                [130.0, 165.0, 65.0],
                [290.0, 165.0, 114.0],
                [290.0, 0.0, 114.0],
            ],
            [
                [82.0, 0.0, 225.0],
                [82.0, 165.0, 225.0],
                [130.0, 165.0, 65.0],
                [130.0, 0.0, 65.0],
            ],
            [
                [240.0, 0.0, 272.0],
                [240.0, 165.0, 272.0],
                [82.0, 165.0, 225.0],
                [82.0, 0.0, 225.0],
            ],
        ],
    ),
    (
        "tall_block",
        "white",
        &[
            [
                [423.0, 330.0, 247.0],
                [265.0, 330.0, 296.0],
                [314.0, 330.0, 456.0],
                [472.0, 330.0, 406.0],
            ],
            [
                [423.0, 0.0, 247.0],
                [423.0, 330.0, 247.0],
                [472.0, 330.0, 406.0],
                [472.0, 0.0, 406.0],
            ],
            [
                [472.0, 0.0, 406.0],
                [472.0, 330.0, 406.0],
                [314.0, 330.0, 456.0],
                [314.0, 0.0, 456.0],
            ],
            [
                [314.0, 0.0, 456.0],
                [314.0, 330.0, 456.0],
                [265.0, 330.0, 296.0],
                [265.0, 0.0, 296.0],
            ],
            [
                [265.0, 0.0, 296.0],
                [265.0, 330.0, 296.0],
                [423.0, 330.0, 247.0],
                [423.0, 0.0, 247.0],
            ],
        ],
    ),
    (
        "light",
        "light",
        &[[
            [343.0, 548.7, 227.0],
            [343.0, 548.7, 332.0],
            [213.0, 548.7, 332.0],
            [213.0, 548.7, 227.0],
        ]],
    ),
];

/// The Cornell box scene (32 triangles).
pub fn cornell() -> RawScene {
    let mut b = MeshBuilder::new();
    b.material("white", WHITE, Vec3::ZERO);
    b.material("red", RED, Vec3::ZERO);
    b.material("green", GREEN, Vec3::ZERO);
    b.material("light", LIGHT_RHO, LIGHT_EMISSION);
    for &(object, material, quads) in PARTS {
        b.begin_object(object);
        b.mat = b.material(material, Vec3::ZERO, Vec3::ZERO);
        for q in quads {
            b.quad(q.map(|p| Vec3::from_array(p) * 1e-3));
        }
    }
    let cams = vec![
        // The measured camera: 35 mm focal length, 25 mm film → fov 2·atan(12.5/35) = 39.3°.
        camera(
            "default",
            Vec3::new(0.278, 0.273, -0.800),
            Vec3::new(0.278, 0.273, 0.0),
            39.3,
            512,
            512,
        ),
        // Looking down into the box from just below the ceiling, near the open side.
        camera(
            "top",
            Vec3::new(0.278, 0.50, 0.02),
            Vec3::new(0.278, 0.0, 0.40),
            70.0,
            512,
            512,
        ),
    ];
    b.finish("cornell", UpAxis::Y, cams)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn faces_point_into_the_box_and_blocks_outwards() {
        let raw = cornell();
        assert_eq!(raw.triangles.len(), 32);
        let centre_of = |name: &str| {
            let o = raw.objects.iter().position(|n| n == name).unwrap() as u32;
            let mut c = Vec3::ZERO;
            let mut k = 0.0;
            for (t, &obj) in raw.triangles.iter().zip(&raw.tri_object) {
                if obj == o {
                    c += t.iter().map(|&v| raw.positions[v as usize]).sum::<Vec3>();
                    k += 3.0;
                }
            }
            c / k
        };
        let room = Vec3::new(0.278, 0.274, 0.280);
        let short = centre_of("short_block");
        let tall = centre_of("tall_block");
        for (i, t) in raw.triangles.iter().enumerate() {
            let [a, b, c] = t.map(|v| raw.positions[v as usize]);
            let n = (b - a).cross(c - a).normalize();
            let g = (a + b + c) / 3.0;
            let name = &raw.objects[raw.tri_object[i] as usize];
            let ok = match name.as_str() {
                "short_block" => n.dot(g - short) > 0.0,
                "tall_block" => n.dot(g - tall) > 0.0,
                "light" => n.dot(Vec3::NEG_Y) > 0.999,
                _ => n.dot(room - g) > 0.0,
            };
            assert!(ok, "triangle {i} of {name} faces the wrong way: {n}");
        }
    }
}
