//! Loaders and exporters: golden statistics of the real scenes, fast OBJ parser vs tobj, glTF
//! scene graphs, PLY, TOML scene files, and scene → file → scene round trips.

use glam::Vec3;
use hirad::scene::export::{write_scene, write_scene_glb};
use hirad::scene::{obj, Scene, SceneOptions, UpAxis};
use std::path::{Path, PathBuf};

fn real(name: &str) -> PathBuf {
    PathBuf::from(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../../shared/scenes"
    ))
    .join(format!("{name}/{name}.obj"))
}

fn load(p: &Path) -> Scene {
    Scene::load(p.to_str().unwrap(), &SceneOptions::default()).unwrap_or_else(|e| panic!("{e}"))
}

fn close(a: f64, b: f64, rel: f64) -> bool {
    (a - b).abs() <= rel * a.abs().max(b.abs()).max(1e-12)
}

/// Counts, bounding boxes and emitters as listed in `shared/scenes/README.md`.
#[test]
fn real_scenes_golden_statistics() {
    struct G {
        name: &'static str,
        tris: usize,
        verts: usize,
        mats: usize,
        emit_tris: usize,
        up: UpAxis,
        min: [f32; 3],
        max: [f32; 3],
    }
    let golden = [
        G {
            name: "bathroom",
            tris: 379_844,
            verts: 192_684,
            mats: 30,
            emit_tris: 1280,
            up: UpAxis::Y,
            min: [-2.659, -0.011, -2.500],
            max: [2.500, 2.792, -0.050],
        },
        G {
            name: "franka_panda",
            tris: 134_853,
            verts: 69_472,
            mats: 5,
            emit_tris: 0,
            up: UpAxis::Z,
            min: [-0.154, -0.129, 0.000],
            max: [0.655, 0.130, 0.813],
        },
        G {
            name: "copper_beech",
            tris: 187_308,
            verts: 115_528,
            mats: 3,
            emit_tris: 0,
            up: UpAxis::Y,
            min: [-3.991, 0.000, -3.530],
            max: [3.522, 8.000, 3.771],
        },
        G {
            name: "graz_office",
            tris: 26_928,
            verts: 16_949,
            mats: 52,
            emit_tris: 16,
            up: UpAxis::Z,
            min: [-0.300, -0.300, -0.012],
            max: [5.320, 4.730, 2.650],
        },
    ];
    for g in golden {
        let s = load(&real(g.name));
        assert_eq!(s.num_triangles(), g.tris, "{}", g.name);
        assert_eq!(s.positions.len(), g.verts, "{}", g.name);
        assert_eq!(s.materials.len(), g.mats, "{}", g.name);
        assert_eq!(s.emitters().len(), g.emit_tris, "{}", g.name);
        assert_eq!(s.report.degenerate_dropped, 0, "{}", g.name);
        assert_eq!(s.up, g.up, "{}", g.name);
        assert!(
            (s.bbox.min - Vec3::from(g.min)).abs().max_element() < 1.5e-3
                && (s.bbox.max - Vec3::from(g.max)).abs().max_element() < 1.5e-3,
            "{}: {:?}",
            g.name,
            s.bbox
        );
        // Every triangle's normal is unit and its area positive.
        assert!(s.areas.iter().all(|&a| a > 0.0));
        assert!(s.normals.iter().all(|n| (n.length() - 1.0).abs() < 1e-4));
    }
}

#[test]
fn emitters_of_real_scenes() {
    let s = load(&real("graz_office"));
    let lamp = s
        .materials
        .iter()
        .find(|m| m.name == "light_light")
        .unwrap();
    assert!((lamp.emission - Vec3::new(1873.752, 1874.009, 1874.639)).length() < 1e-2);
    assert_eq!(
        s.report.clamped_materials,
        vec![
            "room_l_chair_metal_red",
            "room_l_shadow",
            "room_l_table_wood_brown"
        ]
    );
    // Φ = π · L_e · A over the 16 luminaire triangles.
    let area: f64 = s
        .emitters()
        .iter()
        .map(|&i| s.areas[i as usize] as f64)
        .sum();
    let p = s.emitted_power();
    assert!(close(p.x, std::f64::consts::PI * 1873.751963 * area, 1e-5));
    let s = load(&real("franka_panda"));
    assert_eq!(s.report.clamped_materials, vec!["white", "green"]);
    assert_eq!(s.objects.len(), 58);
}

/// The fast parser and tobj produce the same triangles, materials and objects.
#[test]
fn fast_parser_agrees_with_tobj() {
    for name in ["graz_office", "franka_panda"] {
        let p = real(name);
        let a = obj::load(&p).unwrap();
        let b = obj::load_with_tobj(&p).unwrap();
        assert_eq!(a.triangles.len(), b.triangles.len(), "{name}");
        assert_eq!(a.materials, b.materials, "{name}");
        assert_eq!(a.objects, b.objects, "{name}");
        for i in 0..a.triangles.len() {
            let ta = a.triangles[i].map(|v| a.positions[v as usize]);
            let tb = b.triangles[i].map(|v| b.positions[v as usize]);
            assert_eq!(ta, tb, "{name} triangle {i}");
            assert_eq!(a.tri_material[i], b.tri_material[i], "{name} triangle {i}");
            assert_eq!(a.tri_object[i], b.tri_object[i], "{name} triangle {i}");
        }
    }
}

fn same_materials(a: &Scene, b: &Scene, rel: f32) {
    assert_eq!(a.materials.len(), b.materials.len());
    for (x, y) in a.materials.iter().zip(&b.materials) {
        assert_eq!(x.name, y.name);
        assert_eq!(x.rho, y.rho, "{}", x.name);
        assert!(
            (x.emission - y.emission).abs().max_element() <= rel * x.emission.max_element(),
            "{}: {} vs {}",
            x.name,
            x.emission,
            y.emission
        );
    }
}

#[test]
fn scene_obj_round_trip() {
    let d = tempfile::tempdir().unwrap();
    let scenes = [load(&real("graz_office")), {
        Scene::load("cornell", &SceneOptions::default()).unwrap()
    }];
    for s in scenes {
        let p = d.path().join(format!("{}.obj", s.name));
        write_scene(&p, &s).unwrap();
        assert!(p.with_extension("mtl").is_file());
        let r = load(&p);
        assert_eq!(r.num_triangles(), s.num_triangles(), "{}", s.name);
        assert_eq!(r.positions, s.positions);
        assert_eq!(r.triangles, s.triangles);
        assert_eq!(r.areas, s.areas);
        assert_eq!(r.objects, s.objects);
        assert_eq!(r.tri_object, s.tri_object);
        assert_eq!(r.tri_material, s.tri_material);
        assert_eq!(r.up, s.up);
        same_materials(&s, &r, 0.0);
        assert!(r.report.clamped_materials.is_empty());
        assert_eq!(r.total_area(), s.total_area());
    }
}

#[test]
fn scene_glb_round_trip() {
    let d = tempfile::tempdir().unwrap();
    let scenes = [load(&real("graz_office")), {
        Scene::load("cornell", &SceneOptions::default()).unwrap()
    }];
    for s in scenes {
        let p = d.path().join(format!("{}.glb", s.name));
        write_scene_glb(&p, &s).unwrap();
        let r = load(&p);
        assert_eq!(r.num_triangles(), s.num_triangles(), "{}", s.name);
        assert_eq!(r.objects.len(), s.objects.len());
        assert!(close(r.total_area(), s.total_area(), 1e-5));
        same_materials(&s, &r, 1e-6);
        assert!(close(r.emitted_power().x, s.emitted_power().x, 1e-5));
        for i in 0..s.num_triangles() {
            assert_eq!(
                s.materials[s.tri_material[i] as usize].name,
                r.material_of(i).name
            );
        }
        // glTF is +Y up: a Z-up scene comes back rotated, (x, y, z) → (x, z, -y).
        assert_eq!(r.up, UpAxis::Y);
        let want = if s.up == UpAxis::Z {
            let (lo, hi) = (s.bbox.min, s.bbox.max);
            (Vec3::new(lo.x, lo.z, -hi.y), Vec3::new(hi.x, hi.z, -lo.y))
        } else {
            (s.bbox.min, s.bbox.max)
        };
        assert!(
            (r.bbox.min - want.0).abs().max_element() < 1e-5,
            "{:?}",
            r.bbox
        );
        assert!(
            (r.bbox.max - want.1).abs().max_element() < 1e-5,
            "{:?}",
            r.bbox
        );
    }
}

/// A hand-written glTF with a node hierarchy, an indexed and a non-indexed primitive, a mirrored
/// node, an emissive material with `KHR_materials_emissive_strength` and a default material.
#[test]
fn gltf_scene_graph_and_materials() {
    let d = tempfile::tempdir().unwrap();
    let mut bin = Vec::new();
    let tri = [[0f32, 0., 0.], [1., 0., 0.], [0., 1., 0.]];
    let quad = [[0f32, 0., 0.], [1., 0., 0.], [1., 1., 0.], [0., 1., 0.]];
    for p in tri.iter().chain(&quad) {
        for x in p {
            bin.extend(x.to_le_bytes());
        }
    }
    for i in [0u16, 1, 2, 0, 2, 3] {
        bin.extend(i.to_le_bytes());
    }
    std::fs::write(d.path().join("g.bin"), &bin).unwrap();
    let h = std::f32::consts::FRAC_1_SQRT_2;
    let json = format!(
        r#"{{"asset": {{"version": "2.0"}},
        "extensionsUsed": ["KHR_materials_emissive_strength"],
        "buffers": [{{"uri": "g.bin", "byteLength": {len}}}],
        "bufferViews": [{{"buffer": 0, "byteOffset": 0, "byteLength": 84}},
                        {{"buffer": 0, "byteOffset": 84, "byteLength": 12}}],
        "accessors": [
          {{"bufferView": 0, "byteOffset": 0, "componentType": 5126, "count": 3, "type": "VEC3",
            "min": [0,0,0], "max": [1,1,0]}},
          {{"bufferView": 0, "byteOffset": 36, "componentType": 5126, "count": 4, "type": "VEC3",
            "min": [0,0,0], "max": [1,1,0]}},
          {{"bufferView": 1, "componentType": 5123, "count": 6, "type": "SCALAR"}}],
        "materials": [{{"name": "glow",
          "pbrMetallicRoughness": {{"baseColorFactor": [0.2, 0.4, 0.6, 1.0]}},
          "emissiveFactor": [1.0, 0.5, 0.25],
          "extensions": {{"KHR_materials_emissive_strength": {{"emissiveStrength": 4.0}}}}}}],
        "meshes": [{{"primitives": [{{"attributes": {{"POSITION": 0}}, "material": 0}}]}},
                   {{"primitives": [{{"attributes": {{"POSITION": 1}}, "indices": 2}}]}}],
        "nodes": [{{"name": "root", "translation": [0, 0, 5], "scale": [2, 2, 2], "children": [1, 2]}},
                  {{"name": "tri", "mesh": 0, "rotation": [{h}, 0, 0, {h}]}},
                  {{"name": "mirrored", "mesh": 1, "scale": [-1, 1, 1]}}],
        "scenes": [{{"nodes": [0]}}], "scene": 0}}"#,
        len = bin.len()
    );
    let p = d.path().join("g.gltf");
    std::fs::write(&p, json).unwrap();
    let s = load(&p);
    assert_eq!(s.num_triangles(), 3);
    assert_eq!(s.objects, vec!["tri".to_string(), "mirrored".to_string()]);
    // Triangle: rotated 90° about x, scaled by 2, lifted to z = 5.
    let [a, b, c] = s.tri_vertices(0);
    for (got, want) in [(a, [0., 0., 5.]), (b, [2., 0., 5.]), (c, [0., 0., 7.])] {
        assert!((got - Vec3::from(want)).length() < 1e-5, "{got}");
    }
    assert!((s.normals[0] - Vec3::new(0.0, -1.0, 0.0)).length() < 1e-5);
    assert!((s.areas[0] - 2.0).abs() < 1e-5);
    // Mirrored quad: area 4, winding flipped so the normal transforms as a normal (+z).
    assert!((s.areas[1] + s.areas[2] - 4.0).abs() < 1e-5);
    assert!((s.normals[1] - Vec3::Z).length() < 1e-5);
    let glow = s.material_of(0);
    assert_eq!(glow.rho, Vec3::new(0.2, 0.4, 0.6));
    assert_eq!(glow.emission, Vec3::new(4.0, 2.0, 1.0));
    assert_eq!(s.material_of(1).name, "default");
    assert_eq!(s.report.clamped_materials, vec!["default".to_string()]);
    assert!(close(
        s.emitted_power().x,
        std::f64::consts::PI * 4.0 * 2.0,
        1e-5
    ));
}

#[test]
fn ply_polygons_and_scene_load() {
    let d = tempfile::tempdir().unwrap();
    let p = d.path().join("p.ply");
    std::fs::write(
        &p,
        "ply\nformat ascii 1.0\ncomment Z-up\nelement vertex 5\nproperty float x\nproperty float y\n\
         property float z\nelement edge 1\nproperty int vertex1\nproperty int vertex2\n\
         element face 2\nproperty uchar flags\nproperty list uchar int vertex_indices\nend_header\n\
         0 0 0\n2 0 0\n2 1 0\n0 1 0\n1 2 0\n0 1\n7 4 0 1 2 3\n0 3 3 2 4\n",
    )
    .unwrap();
    let s = load(&p);
    assert_eq!(s.num_triangles(), 3);
    assert_eq!(s.up, UpAxis::Z);
    assert!(close(s.total_area(), 2.0 + 1.0, 1e-6));
    assert!(s.normals.iter().all(|n| *n == Vec3::Z));
}

/// `franka_panda` has no emitters: a TOML file lights it with a quad and a sun.
#[test]
fn toml_lights_a_real_scene() {
    let d = tempfile::tempdir().unwrap();
    let p = d.path().join("panda.toml");
    std::fs::write(
        &p,
        format!(
            r#"name = "lit_panda"
[[mesh]]
file = "{}"
[[light]]
name = "key"
corner = [-0.5, -0.5, 1.5]
edge1 = [0.0, 1.0, 0.0]
edge2 = [1.0, 0.0, 0.0]
radiance = [3.0, 3.0, 3.0]
[sun]
direction = [1.0, 0.0, 1.0]
irradiance = [500.0, 500.0, 500.0]
[[camera]]
name = "front"
eye = [1.5, -1.5, 0.8]
target = [0.25, 0.0, 0.4]
fov = 35.0
[materials.white]
rho = [0.8, 0.8, 0.8]
"#,
            real("franka_panda").display()
        ),
    )
    .unwrap();
    let s = load(&p);
    assert_eq!(s.name, "lit_panda");
    assert_eq!(s.num_triangles(), 134_853 + 2);
    assert_eq!(s.up, UpAxis::Z);
    assert_eq!(s.emitters().len(), 2);
    assert!(close(s.emitted_power().x, std::f64::consts::PI * 3.0, 1e-6));
    assert_eq!(s.cameras[0].up, Vec3::Z);
    assert!((s.sun.unwrap().direction.length() - 1.0).abs() < 1e-6);
    // The override replaced ρ = 1 so only `green` is clamped.
    assert_eq!(s.report.clamped_materials, vec!["green".to_string()]);
    assert_eq!(s.normals[s.num_triangles() - 1], -Vec3::Z);
}

mod props {
    use super::*;
    use proptest::prelude::*;

    /// A polygon soup: vertices and faces of 3 to 6 corners, with a style per corner
    /// (0: `v`, 1: `v/t`, 2: `v//n`, 3: `v/t/n`, 4: negative relative index).
    /// Vertices and faces of (vertex, corner style).
    type Soup = (Vec<[f32; 3]>, Vec<Vec<(u32, u8)>>);

    fn soup() -> impl Strategy<Value = Soup> {
        prop::collection::vec(prop::array::uniform3(-1e3f32..1e3), 3..40).prop_flat_map(|v| {
            let n = v.len() as u32;
            let face = prop::collection::vec((0..n, 0u8..5), 3..7);
            (Just(v), prop::collection::vec(face, 1..30))
        })
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(64))]
        /// The fast OBJ parser reads every corner style (mixed within a face, inline comments)
        /// and fan-triangulates polygons like a direct construction; tobj agrees on the
        /// triangles' corners of the same soup written with plain indices.
        #[test]
        fn obj_corner_styles_and_fans((verts, faces) in soup()) {
            let d = tempfile::tempdir().unwrap();
            let mut text = String::from("# soup\n");
            for v in &verts {
                text += &format!("v\t{} {}  {}\n", v[0], v[1], v[2]);
            }
            text += "vt 0 0\nvn 0 0 1\ng soup\n";
            let nv = verts.len() as i64;
            let mut want = Vec::new();
            for f in &faces {
                text += "f";
                for &(i, style) in f {
                    text += &match style {
                        0 => format!(" {}", i + 1),
                        1 => format!(" {}/1", i + 1),
                        2 => format!(" {}//1", i + 1),
                        3 => format!(" {}/1/1", i + 1),
                        _ => format!(" {}", i as i64 - nv),
                    };
                }
                text += " # face\n";
                for k in 1..f.len() - 1 {
                    want.push([f[0].0, f[k].0, f[k + 1].0]);
                }
            }
            let p = d.path().join("soup.obj");
            std::fs::write(&p, &text).unwrap();
            let raw = obj::load(&p).unwrap();
            prop_assert_eq!(&raw.triangles, &want);
            let got: Vec<[f32; 3]> = raw.positions.iter().map(|p| p.to_array()).collect();
            prop_assert_eq!(&got, &verts);
            prop_assert_eq!(raw.objects, vec!["soup".to_string()]);
            // tobj rejects faces mixing corner styles: give it plain indices.
            let mut plain = String::new();
            for v in &verts {
                plain += &format!("v {} {} {}\n", v[0], v[1], v[2]);
            }
            for f in &faces {
                let c: Vec<String> = f.iter().map(|(i, _)| (i + 1).to_string()).collect();
                plain += &format!("f {}\n", c.join(" "));
            }
            let p = d.path().join("plain.obj");
            std::fs::write(&p, &plain).unwrap();
            prop_assert_eq!(&obj::load(&p).unwrap().triangles, &want);
            let t = obj::load_with_tobj(&p).unwrap();
            prop_assert_eq!(t.triangles.len(), want.len());
            for (i, tri) in want.iter().enumerate() {
                let a = tri.map(|v| verts[v as usize]);
                let b = t.triangles[i].map(|v| t.positions[v as usize].to_array());
                prop_assert_eq!(a, b);
            }
        }
    }
}

/// Scene → TOML (+ OBJ + MTL) → scene keeps geometry, materials, sun, sky, cameras and up.
#[test]
fn scene_toml_round_trip_keeps_lights_and_cameras() {
    let d = tempfile::tempdir().unwrap();
    for name in ["cornell", "trees"] {
        let s = Scene::load(name, &SceneOptions::default()).unwrap();
        let p = d.path().join(format!("{name}.toml"));
        write_scene(&p, &s).unwrap();
        let r = load(&p);
        assert_eq!(r.name, s.name);
        assert_eq!(r.num_triangles(), s.num_triangles());
        assert_eq!(r.triangles, s.triangles);
        assert_eq!(r.areas, s.areas);
        assert_eq!(r.up, s.up);
        assert_eq!(r.sun, s.sun);
        assert_eq!(r.sky, s.sky);
        assert_eq!(r.cameras, s.cameras);
        same_materials(&s, &r, 0.0);
    }
}

fn base64(data: &[u8]) -> String {
    const A: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut s = String::new();
    for c in data.chunks(3) {
        let n = (c[0] as u32) << 16
            | (*c.get(1).unwrap_or(&0) as u32) << 8
            | *c.get(2).unwrap_or(&0) as u32;
        for k in 0..4 {
            if k <= c.len() {
                s.push(A[(n >> (18 - 6 * k) & 63) as usize] as char);
            } else {
                s.push('=');
            }
        }
    }
    s
}

/// Embedded (data URI) buffer; `TRIANGLE_STRIP` and `TRIANGLE_FAN` primitives keep the
/// counter-clockwise orientation of the glTF spec; a file without scenes uses its root nodes.
#[test]
fn gltf_strips_fans_and_data_uri() {
    let d = tempfile::tempdir().unwrap();
    let mut bin = Vec::new();
    let strip = [[0f32, 0., 0.], [1., 0., 0.], [0., 1., 0.], [1., 1., 0.]];
    let fan = [[0f32, 0., 1.], [2., 0., 1.], [2., 2., 1.], [0., 2., 1.]];
    for p in strip.iter().chain(&fan) {
        for x in p {
            bin.extend(x.to_le_bytes());
        }
    }
    let json = format!(
        r#"{{"asset": {{"version": "2.0"}},
        "buffers": [{{"uri": "data:application/octet-stream;base64,{}", "byteLength": 96}}],
        "bufferViews": [{{"buffer": 0, "byteLength": 96}}],
        "accessors": [
          {{"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3",
            "min": [0,0,0], "max": [1,1,0]}},
          {{"bufferView": 0, "byteOffset": 48, "componentType": 5126, "count": 4, "type": "VEC3",
            "min": [0,0,1], "max": [2,2,1]}}],
        "meshes": [{{"name": "sheet", "primitives": [{{"attributes": {{"POSITION": 0}}, "mode": 5}},
                                   {{"attributes": {{"POSITION": 1}}, "mode": 6}}]}}],
        "nodes": [{{"mesh": 0}}]}}"#,
        base64(&bin)
    );
    let p = d.path().join("sf.gltf");
    std::fs::write(&p, json).unwrap();
    let s = load(&p);
    assert_eq!(s.num_triangles(), 4);
    assert_eq!(s.objects, vec!["sheet".to_string()]);
    assert!(s.normals.iter().all(|n| *n == Vec3::Z), "{:?}", s.normals);
    assert!(close(s.total_area(), 1.0 + 4.0, 1e-6));
}
