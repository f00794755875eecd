//! Helpers shared by the radiosity integration tests: small scenes built from quads and
//! hand-made cluster trees, so that the tests do not depend on any clustering strategy.
#![allow(dead_code)]

use glam::Vec3;
use hirad::cluster::{BuildNode, BuildTree, ClusterConfig, ClusterTree, Prims, Strategy};
use hirad::geom::Aabb;
use hirad::scene::{Material, RawScene, Scene, SceneOptions};

/// Quad (counter-clockwise around its front normal) with a material index and a group.
pub struct Quad {
    pub p: [Vec3; 4],
    pub mat: u32,
    pub group: u32,
}

/// Build a scene of quads (2 triangles each), objects = groups.
pub fn quads_scene(quads: &[Quad], materials: Vec<Material>) -> Scene {
    let mut raw = RawScene {
        name: "test".into(),
        materials,
        ..Default::default()
    };
    let ngroups = quads.iter().map(|q| q.group).max().unwrap_or(0) + 1;
    raw.objects = (0..ngroups).map(|g| format!("g{g}")).collect();
    for q in quads {
        let b = raw.positions.len() as u32;
        raw.positions.extend_from_slice(&q.p);
        raw.triangles.push([b, b + 1, b + 2]);
        raw.triangles.push([b, b + 2, b + 3]);
        raw.tri_material.extend([q.mat, q.mat]);
        raw.tri_object.extend([q.group, q.group]);
    }
    Scene::from_raw(raw, &SceneOptions::default()).unwrap()
}

/// Unit emitter material: L_e = 1/π so that E = 1 W/m², black (ρ = 0).
pub fn emitter() -> Material {
    Material {
        name: "light".into(),
        rho: Vec3::ZERO,
        emission: Vec3::splat(std::f32::consts::FRAC_1_PI),
    }
}

/// A cluster tree with one child cluster per object (group) of the scene under the root.
pub fn tree_by_object(scene: &Scene) -> ClusterTree {
    let prims = Prims::from_scene(scene);
    let mut b = BuildTree::default();
    let ng = scene.objects.len();
    let mut kids = Vec::new();
    for g in 0..ng as u32 {
        let surfaces: Vec<u32> = (0..scene.num_triangles() as u32)
            .filter(|&t| scene.tri_object[t as usize] == g)
            .collect();
        if surfaces.is_empty() {
            continue;
        }
        let mut bbox = Aabb::EMPTY;
        for &s in &surfaces {
            bbox.grow_box(&prims.bbox[s as usize]);
        }
        kids.push(b.push(BuildNode {
            bbox,
            children: vec![],
            surfaces,
        }));
    }
    let root = b.push(BuildNode {
        bbox: scene.bbox,
        children: kids,
        surfaces: vec![],
    });
    b.root = root;
    let t = ClusterTree::from_build(
        b,
        scene.num_triangles(),
        Strategy::Sah,
        ClusterConfig::default(),
    );
    t.validate(&prims).unwrap();
    t
}

/// Axis-aligned unit square in the plane z = `z`, facing +z (`up`) or −z.
pub fn square_z(z: f32, up: bool, mat: u32, group: u32) -> Quad {
    let mut p = [
        Vec3::new(0.0, 0.0, z),
        Vec3::new(1.0, 0.0, z),
        Vec3::new(1.0, 1.0, z),
        Vec3::new(0.0, 1.0, z),
    ];
    if !up {
        p.reverse();
    }
    Quad { p, mat, group }
}

/// Area-weighted mean irradiance over the front faces of the triangles of `group`.
pub fn group_irradiance(sol: &hirad::radiosity::Solution, scene: &Scene, group: u32) -> f64 {
    face_irradiance(sol, scene, group, false)
}

/// Area-weighted mean irradiance (red) over the front, or `back`, faces of `group`.
pub fn face_irradiance(
    sol: &hirad::radiosity::Solution,
    scene: &Scene,
    group: u32,
    back: bool,
) -> f64 {
    let (mut num, mut den) = (0.0, 0.0);
    for t in 0..scene.num_triangles() {
        if scene.tri_object[t] == group {
            let a = scene.areas[t] as f64;
            num += a * sol.triangle_irradiance(t as u32, back).x;
            den += a;
        }
    }
    num / den
}

/// Path of a real scene file.
pub fn shared_scene(rel: &str) -> String {
    format!(
        "{}/../../../shared/scenes/{rel}",
        env!("CARGO_MANIFEST_DIR")
    )
}

/// Quad `o, o+u, o+u+v, o+v`, facing `u × v`.
pub fn rect(o: Vec3, u: Vec3, v: Vec3, mat: u32, group: u32) -> Quad {
    Quad {
        p: [o, o + u, o + u + v, o + v],
        mat,
        group,
    }
}

/// The six inward-facing walls of the box `[lo, hi]` in material `mat`, each in its own group
/// from `g0`: floor, ceiling, y = lo, y = hi, x = lo, x = hi.
pub fn box_inward(lo: Vec3, hi: Vec3, mat: u32, g0: u32) -> Vec<Quad> {
    let d = hi - lo;
    let (x, y, z) = (Vec3::X * d.x, Vec3::Y * d.y, Vec3::Z * d.z);
    vec![
        rect(lo, x, y, mat, g0),         // floor, facing +z
        rect(lo + z, y, x, mat, g0 + 1), // ceiling, facing −z
        rect(lo, z, x, mat, g0 + 2),     // y = lo, facing +y
        rect(lo + y, x, z, mat, g0 + 3), // y = hi, facing −y
        rect(lo, y, z, mat, g0 + 4),     // x = lo, facing +x
        rect(lo + x, z, y, mat, g0 + 5), // x = hi, facing −x
    ]
}

/// Cosine-distributed direction around the unit normal `n` from two uniform numbers.
pub fn cosine_dir(n: Vec3, u1: f32, u2: f32) -> Vec3 {
    let a = if n.x.abs() > 0.9 { Vec3::Y } else { Vec3::X };
    let t = n.cross(a).normalize();
    let b = n.cross(t);
    let r = u1.sqrt();
    let phi = 2.0 * std::f32::consts::PI * u2;
    (t * (r * phi.cos()) + b * (r * phi.sin()) + n * (1.0 - u1).max(0.0).sqrt()).normalize()
}
