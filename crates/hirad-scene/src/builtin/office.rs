//! OFFICE: an office interior in the spirit of the paper's OFFICE scene (about 8,000 triangles).
//!
//! An 8 × 6 m room, 3 m high (walls, floor and ceiling split into 0.5 m cells, facing into the
//! room), three window openings with reveals and frames in the +Z wall (no glass: the openings
//! look onto nothing), a door with casing and handle, six desks with monitors, keyboards and
//! mugs, six swivel chairs, three bookcases filled with books and archive boxes, a whiteboard,
//! a filing cabinet, a plant and six ceiling lights. Every piece of furniture and every book is
//! an object of its own. Closed solids face outwards, the room faces inwards.
//!
//! Lighting: each ceiling light is a 1.2 × 0.3 m panel facing down with L_e = (24, 23, 20)
//! W/(m²·sr), Φ ≈ 6 × π·L_e·0.36 ≈ 163 W in total, which puts the radiance of lit walls and desks
//! around 0.2–1 (images need no exposure correction). Generated in a +Y-up frame and stored
//! +Z up (like most architectural models, e.g. `graz_office`). Random choices (book sizes and
//! colours, chair turns) come from the seed.

use super::mesh::{camera, MeshBuilder};
use crate::{RawScene, UpAxis};
use glam::{Affine3A, Vec3};
use hirad_core::rng::SplitMix64;

/// Room size (x, height, z), metres.
pub const ROOM: Vec3 = Vec3::new(8.0, 3.0, 6.0);
/// Emitted radiance of the ceiling lights, W/(m²·sr).
pub const LIGHT_EMISSION: Vec3 = Vec3::new(24.0, 23.0, 20.0);
/// Number of ceiling lights.
pub const NUM_LIGHTS: usize = 6;
/// Size of one ceiling light panel (x, z), metres.
pub const LIGHT_SIZE: (f32, f32) = (1.2, 0.3);

const CELL: f32 = 0.5;
const WALL_THICKNESS: f32 = 0.25;
/// Windows in the z = 6 wall: x ranges (in cells), all at y cells 2..5 (1.0–2.5 m).
const WINDOWS: [(u32, u32); 3] = [(2, 5), (7, 10), (12, 15)];
const WINDOW_ROWS: (u32, u32) = (2, 5);

fn uniform(r: &mut SplitMix64, lo: f32, hi: f32) -> f32 {
    lo + (hi - lo) * r.next_f32()
}

struct Office {
    b: MeshBuilder,
    rng: SplitMix64,
}

impl Office {
    fn mat(&mut self, name: &str, rho: [f32; 3]) {
        self.b.use_material(name, Vec3::from_array(rho), Vec3::ZERO);
    }

    fn boxed(&mut self, xf: &Affine3A, min: Vec3, max: Vec3) {
        self.b.cuboid(xf, min, max, false, 0);
    }

    fn room(&mut self) {
        let b = &mut self.b;
        b.begin_object("floor");
        b.use_material("carpet", Vec3::new(0.25, 0.22, 0.2), Vec3::ZERO);
        let (nx, ny, nz) = (
            (ROOM.x / CELL) as u32,
            (ROOM.y / CELL) as u32,
            (ROOM.z / CELL) as u32,
        );
        b.grid(Vec3::ZERO, Vec3::Z * ROOM.z, Vec3::X * ROOM.x, nz, nx);
        b.begin_object("ceiling");
        b.use_material("ceiling", Vec3::new(0.8, 0.8, 0.78), Vec3::ZERO);
        b.grid(Vec3::Y * ROOM.y, Vec3::X * ROOM.x, Vec3::Z * ROOM.z, nx, nz);
        b.use_material("wall_paint", Vec3::new(0.7, 0.68, 0.62), Vec3::ZERO);
        b.begin_object("wall_west");
        b.grid(Vec3::ZERO, Vec3::Y * ROOM.y, Vec3::Z * ROOM.z, ny, nz);
        b.begin_object("wall_east");
        b.grid(Vec3::X * ROOM.x, Vec3::Z * ROOM.z, Vec3::Y * ROOM.y, nz, ny);
        b.begin_object("wall_south");
        b.grid(Vec3::ZERO, Vec3::X * ROOM.x, Vec3::Y * ROOM.y, nx, ny);
        b.begin_object("wall_north");
        b.grid_masked(
            Vec3::Z * ROOM.z,
            Vec3::Y * ROOM.y,
            Vec3::X * ROOM.x,
            ny,
            nx,
            |i, j| {
                let in_rows = (WINDOW_ROWS.0..WINDOW_ROWS.1).contains(&i);
                !(in_rows && WINDOWS.iter().any(|&(a, c)| (a..c).contains(&j)))
            },
        );
        // Reveals of the window openings, facing into the openings.
        let d = Vec3::Z * WALL_THICKNESS;
        for (k, &(a, c)) in WINDOWS.iter().enumerate() {
            let (x0, x1) = (a as f32 * CELL, c as f32 * CELL);
            let (y0, y1) = (WINDOW_ROWS.0 as f32 * CELL, WINDOW_ROWS.1 as f32 * CELL);
            let (w, h) = (Vec3::X * (x1 - x0), Vec3::Y * (y1 - y0));
            let o = Vec3::new(x0, y0, ROOM.z);
            b.begin_object(format!("window_{k}_reveal"));
            b.use_material("wall_paint", Vec3::ZERO, Vec3::ZERO);
            b.grid(o, d, w, 1, 3);
            b.grid(o + h, w, d, 3, 1);
            b.grid(o, h, d, 3, 1);
            b.grid(o + w, d, h, 1, 3);
            // Frame: four bars, a mullion and a transom, set into the middle of the wall.
            b.begin_object(format!("window_{k}_frame"));
            b.use_material("window_frame", Vec3::new(0.85, 0.85, 0.85), Vec3::ZERO);
            let (z0, z1) = (ROOM.z + 0.09, ROOM.z + 0.16);
            let t = 0.06;
            let xm = 0.5 * (x0 + x1);
            let ym = 0.5 * (y0 + y1) + 0.15;
            let bars = [
                (Vec3::new(x0, y0, z0), Vec3::new(x1, y0 + t, z1)),
                (Vec3::new(x0, y1 - t, z0), Vec3::new(x1, y1, z1)),
                (Vec3::new(x0, y0 + t, z0), Vec3::new(x0 + t, y1 - t, z1)),
                (Vec3::new(x1 - t, y0 + t, z0), Vec3::new(x1, y1 - t, z1)),
                (
                    Vec3::new(xm - t / 2.0, y0 + t, z0),
                    Vec3::new(xm + t / 2.0, ym - t / 2.0, z1),
                ),
                (
                    Vec3::new(x0 + t, ym - t / 2.0, z0),
                    Vec3::new(x1 - t, ym + t / 2.0, z1),
                ),
            ];
            for (lo, hi) in bars {
                b.cuboid(&Affine3A::IDENTITY, lo, hi, false, 0);
            }
            // Sill board inside the room.
            b.use_material("sill", Vec3::new(0.75, 0.74, 0.72), Vec3::ZERO);
            b.cuboid(
                &Affine3A::IDENTITY,
                Vec3::new(x0 - 0.1, y0 - 0.03, ROOM.z - 0.2),
                Vec3::new(x1 + 0.1, y0, ROOM.z),
                false,
                0,
            );
        }
    }

    fn door(&mut self) {
        let id = Affine3A::IDENTITY;
        self.b.begin_object("door");
        self.mat("door_wood", [0.45, 0.3, 0.18]);
        let (z0, z1) = (4.3, 5.2);
        self.b.cuboid(
            &id,
            Vec3::new(0.0, 0.0, z0),
            Vec3::new(0.04, 2.1, z1),
            false,
            0,
        );
        self.b.begin_object("door_casing");
        self.mat("door_casing", [0.8, 0.78, 0.74]);
        for (lo, hi) in [
            (Vec3::new(0.0, 0.0, z0 - 0.08), Vec3::new(0.02, 2.18, z0)),
            (Vec3::new(0.0, 0.0, z1), Vec3::new(0.02, 2.18, z1 + 0.08)),
            (Vec3::new(0.0, 2.1, z0), Vec3::new(0.02, 2.18, z1)),
        ] {
            self.b.cuboid(&id, lo, hi, false, 0);
        }
        self.b.begin_object("door_handle");
        self.mat("steel", [0.55, 0.55, 0.57]);
        self.b.cylinder(
            Vec3::new(0.04, 1.05, z0 + 0.12),
            Vec3::new(0.1, 1.05, z0 + 0.12),
            0.012,
            8,
            1,
            true,
        );
        self.boxed(
            &id,
            Vec3::new(0.1, 1.04, z0 + 0.1),
            Vec3::new(0.12, 1.06, z0 + 0.24),
        );
    }

    fn lights(&mut self) {
        let id = Affine3A::IDENTITY;
        let (w, d) = LIGHT_SIZE;
        let mut k = 0;
        for &x in &[1.6f32, 4.0, 6.4] {
            for &z in &[2.0f32, 4.2] {
                self.b.begin_object(format!("ceiling_light_{k}"));
                self.mat("light_housing", [0.8, 0.8, 0.8]);
                let (x0, x1, z0, z1) = (
                    x - w / 2.0 - 0.03,
                    x + w / 2.0 + 0.03,
                    z - d / 2.0 - 0.03,
                    z + d / 2.0 + 0.03,
                );
                self.b.cuboid(
                    &id,
                    Vec3::new(x0, ROOM.y - 0.08, z0),
                    Vec3::new(x1, ROOM.y, z1),
                    false,
                    0,
                );
                self.b
                    .use_material("ceiling_light", Vec3::splat(0.8), LIGHT_EMISSION);
                let y = ROOM.y - 0.081;
                let (x0, x1, z0, z1) = (x - w / 2.0, x + w / 2.0, z - d / 2.0, z + d / 2.0);
                self.b.quad([
                    Vec3::new(x0, y, z0),
                    Vec3::new(x1, y, z0),
                    Vec3::new(x1, y, z1),
                    Vec3::new(x0, y, z1),
                ]);
                k += 1;
            }
        }
    }

    /// A desk centred at (x, z), front edge towards −z, with monitor, keyboard and mug.
    fn desk(&mut self, k: usize, x: f32, z: f32) {
        let xf = Affine3A::from_translation(Vec3::new(x, 0.0, z));
        let (hw, hd) = (0.8, 0.4);
        self.b.begin_object(format!("desk_{k}"));
        self.mat("desk_wood", [0.55, 0.38, 0.22]);
        self.boxed(&xf, Vec3::new(-hw, 0.72, -hd), Vec3::new(hw, 0.75, hd));
        self.mat("desk_metal", [0.5, 0.5, 0.52]);
        for (sx, sz) in [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)] {
            let c = Vec3::new(sx * (hw - 0.06), 0.0, sz * (hd - 0.06));
            self.boxed(
                &xf,
                c - Vec3::new(0.025, 0.0, 0.025),
                c + Vec3::new(0.025, 0.72, 0.025),
            );
        }
        self.boxed(
            &xf,
            Vec3::new(-hw + 0.09, 0.35, hd - 0.08),
            Vec3::new(hw - 0.09, 0.7, hd - 0.06),
        );
        self.b.begin_object(format!("monitor_{k}"));
        self.mat("monitor_case", [0.06, 0.06, 0.07]);
        let mx = uniform(&mut self.rng, -0.15, 0.15);
        self.boxed(
            &xf,
            Vec3::new(mx - 0.12, 0.75, 0.12),
            Vec3::new(mx + 0.12, 0.765, 0.28),
        );
        self.boxed(
            &xf,
            Vec3::new(mx - 0.03, 0.765, 0.22),
            Vec3::new(mx + 0.03, 0.98, 0.25),
        );
        // Screen housing, with the screen as a separate dark face on its front.
        self.boxed(
            &xf,
            Vec3::new(mx - 0.3, 0.92, 0.15),
            Vec3::new(mx + 0.3, 1.27, 0.19),
        );
        self.mat("screen", [0.02, 0.02, 0.03]);
        self.boxed(
            &xf,
            Vec3::new(mx - 0.28, 0.94, 0.145),
            Vec3::new(mx + 0.28, 1.25, 0.15),
        );
        let p = |v: Vec3| xf.transform_point3(v);
        self.b.begin_object(format!("keyboard_{k}"));
        self.mat("keyboard", [0.15, 0.15, 0.16]);
        self.boxed(
            &xf,
            Vec3::new(mx - 0.22, 0.75, -0.25),
            Vec3::new(mx + 0.22, 0.775, -0.1),
        );
        self.b.begin_object(format!("mug_{k}"));
        let colours = [
            [0.7, 0.1, 0.1],
            [0.85, 0.85, 0.82],
            [0.1, 0.3, 0.6],
            [0.8, 0.6, 0.1],
        ];
        let ci = (self.rng.next_u64() % colours.len() as u64) as usize;
        self.mat(&format!("mug_{ci}"), colours[ci]);
        let mpos = p(Vec3::new(
            hw - 0.25,
            0.75,
            uniform(&mut self.rng, -0.3, 0.0),
        ));
        self.b
            .cylinder(mpos, mpos + Vec3::Y * 0.1, 0.04, 12, 1, true);
        self.b.begin_object(format!("papers_{k}"));
        self.mat("paper", [0.85, 0.85, 0.83]);
        let yaw = uniform(&mut self.rng, -0.3, 0.3);
        let pxf = xf
            * Affine3A::from_translation(Vec3::new(-hw + 0.3, 0.75, -0.1))
            * Affine3A::from_rotation_y(yaw);
        self.boxed(
            &pxf,
            Vec3::new(-0.105, 0.0, -0.15),
            Vec3::new(0.105, 0.02, 0.15),
        );
    }

    /// A swivel chair at (x, z) facing +z (turned by a random angle).
    fn chair(&mut self, k: usize, x: f32, z: f32) {
        let yaw = uniform(&mut self.rng, -0.5, 0.5);
        let xf = Affine3A::from_translation(Vec3::new(x, 0.0, z)) * Affine3A::from_rotation_y(yaw);
        self.b.begin_object(format!("chair_{k}"));
        self.mat("chair_plastic", [0.08, 0.08, 0.08]);
        let p = |v: Vec3| xf.transform_point3(v);
        self.b.cylinder(
            p(Vec3::new(0.0, 0.06, 0.0)),
            p(Vec3::new(0.0, 0.42, 0.0)),
            0.025,
            8,
            1,
            true,
        );
        for i in 0..5 {
            let leg = xf
                * Affine3A::from_rotation_y(i as f32 * std::f32::consts::TAU / 5.0)
                * Affine3A::from_translation(Vec3::new(0.0, 0.04, 0.0));
            self.b.cuboid(
                &leg,
                Vec3::new(-0.02, 0.0, 0.0),
                Vec3::new(0.02, 0.04, 0.3),
                false,
                0,
            );
        }
        // Back support.
        self.boxed(
            &xf,
            Vec3::new(-0.03, 0.42, -0.26),
            Vec3::new(0.03, 0.6, -0.22),
        );
        self.mat("chair_fabric", [0.1, 0.15, 0.35]);
        self.boxed(
            &xf,
            Vec3::new(-0.24, 0.42, -0.23),
            Vec3::new(0.24, 0.49, 0.22),
        );
        self.boxed(
            &xf,
            Vec3::new(-0.22, 0.55, -0.3),
            Vec3::new(0.22, 1.0, -0.24),
        );
    }

    /// A bookcase against the east wall, spanning z ∈ [z0, z0 + 1], filled with books.
    fn bookcase(&mut self, k: usize, z0: f32) {
        let id = Affine3A::IDENTITY;
        let (x0, x1) = (ROOM.x - 0.35, ROOM.x);
        let (w, h, t) = (1.0f32, 2.0f32, 0.02f32);
        let levels = 5;
        self.b.begin_object(format!("bookcase_{k}"));
        self.mat("shelf_wood", [0.6, 0.45, 0.3]);
        self.boxed(&id, Vec3::new(x0, 0.0, z0), Vec3::new(x1, h, z0 + t));
        self.boxed(
            &id,
            Vec3::new(x0, 0.0, z0 + w - t),
            Vec3::new(x1, h, z0 + w),
        );
        self.b.cuboid(
            &id,
            Vec3::new(x1 - t, 0.0, z0 + t),
            Vec3::new(x1, h - t, z0 + w - t),
            false,
            0,
        );
        let pitch = (h - t) / levels as f32;
        for l in 0..=levels {
            let y = l as f32 * pitch;
            self.boxed(
                &id,
                Vec3::new(x0, y, z0 + t),
                Vec3::new(x1 - t, y + t, z0 + w - t),
            );
        }
        let palette: [[f32; 3]; 8] = [
            [0.55, 0.08, 0.07],
            [0.08, 0.15, 0.45],
            [0.1, 0.35, 0.12],
            [0.75, 0.6, 0.15],
            [0.85, 0.83, 0.78],
            [0.08, 0.08, 0.08],
            [0.4, 0.25, 0.12],
            [0.5, 0.3, 0.5],
        ];
        for l in 0..levels {
            let y = l as f32 * pitch + t;
            let mut z = z0 + t + 0.005;
            let zend = z0 + w - t - 0.005;
            let mut n = 0;
            loop {
                if self.rng.next_f32() < 0.08 {
                    // An archive box instead of a book.
                    let bw = 0.1;
                    if z + bw > zend {
                        break;
                    }
                    self.b.begin_object(format!("box_{k}_{l}_{n}"));
                    self.mat("archive_box", [0.65, 0.55, 0.4]);
                    let bh = 0.26;
                    self.boxed(
                        &id,
                        Vec3::new(x1 - t - 0.3, y, z),
                        Vec3::new(x1 - t - 0.01, y + bh, z + bw),
                    );
                    z += bw + 0.004;
                } else {
                    let bw = uniform(&mut self.rng, 0.018, 0.05);
                    if z + bw > zend {
                        break;
                    }
                    let bh = uniform(&mut self.rng, 0.17, pitch - t - 0.04);
                    let bd = uniform(&mut self.rng, 0.14, 0.25);
                    let ci = (self.rng.next_u64() % palette.len() as u64) as usize;
                    self.b.begin_object(format!("book_{k}_{l}_{n}"));
                    self.mat(&format!("book_{ci}"), palette[ci]);
                    self.boxed(
                        &id,
                        Vec3::new(x1 - t - 0.01 - bd, y, z),
                        Vec3::new(x1 - t - 0.01, y + bh, z + bw),
                    );
                    z += bw + uniform(&mut self.rng, 0.0, 0.004);
                }
                n += 1;
                if self.rng.next_f32() < 0.03 {
                    z += uniform(&mut self.rng, 0.05, 0.15);
                }
            }
        }
    }

    fn extras(&mut self) {
        let id = Affine3A::IDENTITY;
        self.b.begin_object("whiteboard");
        self.mat("whiteboard", [0.88, 0.88, 0.88]);
        self.b.cuboid(
            &id,
            Vec3::new(0.0, 0.9, 1.2),
            Vec3::new(0.02, 2.1, 3.6),
            false,
            0,
        );
        self.mat("steel", [0.55, 0.55, 0.57]);
        self.b.cuboid(
            &id,
            Vec3::new(0.0, 0.86, 1.2),
            Vec3::new(0.08, 0.9, 3.6),
            false,
            0,
        );
        self.b.begin_object("filing_cabinet");
        self.mat("cabinet_grey", [0.45, 0.46, 0.48]);
        let (x0, z0) = (ROOM.x - 0.5, 4.3);
        self.boxed(
            &id,
            Vec3::new(x0, 0.0, z0),
            Vec3::new(ROOM.x, 1.3, z0 + 0.45),
        );
        for d in 0..4 {
            let y = 0.08 + d as f32 * 0.31;
            self.b.cuboid(
                &id,
                Vec3::new(x0 - 0.02, y, z0 + 0.03),
                Vec3::new(x0, y + 0.27, z0 + 0.42),
                false,
                0,
            );
            self.b.cuboid(
                &id,
                Vec3::new(x0 - 0.04, y + 0.2, z0 + 0.17),
                Vec3::new(x0 - 0.02, y + 0.22, z0 + 0.28),
                false,
                0,
            );
        }
        self.b.begin_object("plant");
        self.mat("terracotta", [0.55, 0.3, 0.2]);
        let base = Vec3::new(ROOM.x - 0.4, 0.0, ROOM.z - 0.4);
        self.b
            .cone(base, base + Vec3::Y * 0.4, 0.15, 0.2, 12, 1, true);
        self.mat("foliage", [0.1, 0.35, 0.08]);
        self.b.sphere(base + Vec3::Y * 0.75, 0.35, 12, 8, false);
    }
}

/// The office scene (see the module docs).
pub fn office(seed: u64) -> RawScene {
    let mut o = Office {
        b: MeshBuilder::new(),
        rng: SplitMix64::new(seed),
    };
    o.room();
    o.door();
    o.lights();
    let mut k = 0;
    for &x in &[1.6f32, 3.9, 6.2] {
        for &z in &[2.0f32, 4.2] {
            o.desk(k, x, z);
            let dx = uniform(&mut o.rng, -0.2, 0.2);
            o.chair(k, x + dx, z - 0.75);
            k += 1;
        }
    }
    for (k, z0) in [0.3f32, 1.35, 2.4].into_iter().enumerate() {
        o.bookcase(k, z0);
    }
    o.extras();
    let cams = vec![
        camera(
            "default",
            Vec3::new(0.5, 1.65, 0.4),
            Vec3::new(5.5, 0.9, 4.6),
            60.0,
            640,
            480,
        ),
        camera(
            "window",
            Vec3::new(7.4, 1.7, 5.6),
            Vec3::new(2.0, 0.8, 1.0),
            60.0,
            640,
            480,
        ),
        camera(
            "bookcases",
            Vec3::new(3.0, 1.5, 3.0),
            Vec3::new(ROOM.x, 1.0, 1.4),
            55.0,
            640,
            480,
        ),
    ];
    o.b.finish("office", UpAxis::Z, cams)
}
