//! Writing scenes and per-vertex results (OBJ, glTF binary, PLY), atomically.
//!
//! Coloured meshes ([`ColoredMesh`], the solver's output; colours are radiosity B in W/m²) are
//! written by [`write_colored_mesh`] with both the linear B (what [`read_colored_mesh`] returns)
//! and a tone-mapped display colour (white point [`tonemap_white`]) where the format allows,
//! so that viewers show the solution as the images do. Whole scenes are written by
//! [`write_scene`] (OBJ + MTL, GLB, or a TOML description that keeps sun, sky and cameras).
//! Each function documents its file layout.

use super::Scene;
use glam::Vec3;
use hirad_core::io::{write_atomic, write_bytes_atomic};
use hirad_core::{Error, Result};
use serde_json::{json, Value};
use std::collections::HashMap;
use std::path::Path;

/// A triangle mesh with one linear RGB colour per vertex: the exported form of a radiosity
/// solution (colours are radiosity B in W/m²; images show B/π).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ColoredMesh {
    /// Vertex positions.
    pub positions: Vec<Vec3>,
    /// Vertex indices per triangle.
    pub triangles: Vec<[u32; 3]>,
    /// Linear RGB per vertex (radiosity B, W/m², for a solution).
    pub colors: Vec<Vec3>,
}

fn ext_of(path: &Path) -> String {
    path.extension()
        .and_then(|e| e.to_str())
        .unwrap_or("")
        .to_ascii_lowercase()
}

fn check_mesh(path: &Path, mesh: &ColoredMesh) -> Result<()> {
    if mesh.colors.len() != mesh.positions.len() {
        return Err(Error::Config(format!(
            "{}: {} colours for {} vertices",
            path.display(),
            mesh.colors.len(),
            mesh.positions.len()
        )));
    }
    let nv = mesh.positions.len() as u32;
    if mesh.triangles.iter().flatten().any(|&v| v >= nv) {
        return Err(Error::Config(format!(
            "{}: triangle index out of range",
            path.display()
        )));
    }
    Ok(())
}

/// White point of the display variant: the 99th percentile of the per-vertex maximum channel
/// over vertices with a positive maximum (1 when there are none).
pub fn tonemap_white(colors: &[Vec3]) -> f32 {
    let mut m: Vec<f32> = colors
        .iter()
        .map(|c| c.max_element())
        .filter(|&v| v > 0.0 && v.is_finite())
        .collect();
    if m.is_empty() {
        return 1.0;
    }
    let k = ((m.len() - 1) as f64 * 0.99).round() as usize;
    let (_, w, _) = m.select_nth_unstable_by(k, |a, b| a.total_cmp(b));
    *w
}

/// The display colour clamp(c / white, 0, 1) (linear).
fn display_linear(c: Vec3, white: f32) -> Vec3 {
    let v = c / white;
    if v.is_finite() {
        v.clamp(Vec3::ZERO, Vec3::ONE)
    } else {
        Vec3::ZERO
    }
}

/// sRGB encoding of a linear value in [0, 1], as a byte.
pub fn srgb_u8(x: f32) -> u8 {
    let x = x.clamp(0.0, 1.0);
    let s = if x <= 0.003_130_8 {
        12.92 * x
    } else {
        1.055 * x.powf(1.0 / 2.4) - 0.055
    };
    (s * 255.0 + 0.5) as u8
}

/// Write a coloured mesh; the format follows the extension (`.glb`, `.ply`, `.obj`):
/// - `.glb`: one mesh with `POSITION`, `COLOR_0` = the display colour clamp(B / white, 0, 1)
///   (float RGB, linear, within glTF's 0..1 for colours: a viewer's sRGB output encoding turns
///   it into the tone-mapped sRGB image) and `_RADIOSITY` = linear B (float RGB, unclamped; an
///   application attribute, which [`read_colored_mesh`] returns), with an unlit material
///   (`KHR_materials_unlit`) so viewers show the vertex colours. `white` is the 99th percentile
///   of the per-vertex maximum channel ([`tonemap_white`]), recorded as `radiosity_white` in
///   the asset's `extras`.
/// - `.ply`: binary little endian; per vertex `float x y z`, `uchar red green blue` = sRGB of the
///   tone-mapped colour (what viewers display) and `float radiosity_r radiosity_g radiosity_b`
///   = linear B (what [`read_colored_mesh`] returns); `list uchar uint vertex_indices`.
/// - `.obj`: `v x y z r g b` with linear B, `f a b c`.
pub fn write_colored_mesh(path: &Path, mesh: &ColoredMesh) -> Result<()> {
    write_colored_mesh_up(path, mesh, super::UpAxis::Y)
}

/// [`write_colored_mesh`] of a mesh whose coordinates are `up`: a Z-up mesh's `.glb` puts its
/// mesh (still in its own coordinates, which [`read_colored_mesh`] returns) under a root node
/// named `z_up_to_y_up` that turns it to glTF's +Y up, so that any viewer shows it upright.
/// `.ply` and `.obj` keep the coordinates as they are.
pub fn write_colored_mesh_up(path: &Path, mesh: &ColoredMesh, up: super::UpAxis) -> Result<()> {
    check_mesh(path, mesh)?;
    match ext_of(path).as_str() {
        "glb" => write_colored_glb(path, mesh, up),
        "ply" => write_colored_ply(path, mesh),
        "obj" => write_colored_obj(path, mesh),
        e => Err(Error::Config(format!(
            "{}: cannot write meshes as '.{e}' (use .glb, .ply or .obj)",
            path.display()
        ))),
    }
}

fn write_colored_ply(path: &Path, mesh: &ColoredMesh) -> Result<()> {
    let white = tonemap_white(&mesh.colors);
    write_atomic(path, |w| {
        write!(
            w,
            "ply\nformat binary_little_endian 1.0\ncomment hirad radiosity: radiosity_* = linear B \
             (W/m2), red/green/blue = sRGB of clamp(B/{white})\nelement vertex {}\n\
             property float x\nproperty float y\nproperty float z\n\
             property uchar red\nproperty uchar green\nproperty uchar blue\n\
             property float radiosity_r\nproperty float radiosity_g\nproperty float radiosity_b\n\
             element face {}\nproperty list uchar uint vertex_indices\nend_header\n",
            mesh.positions.len(),
            mesh.triangles.len()
        )?;
        let mut buf = Vec::with_capacity(mesh.positions.len() * 27);
        for (p, c) in mesh.positions.iter().zip(&mesh.colors) {
            for x in p.to_array() {
                buf.extend_from_slice(&x.to_le_bytes());
            }
            let d = display_linear(*c, white);
            buf.extend([srgb_u8(d.x), srgb_u8(d.y), srgb_u8(d.z)]);
            for x in c.to_array() {
                buf.extend_from_slice(&x.to_le_bytes());
            }
        }
        for t in &mesh.triangles {
            buf.push(3);
            for i in t {
                buf.extend_from_slice(&i.to_le_bytes());
            }
        }
        w.write_all(&buf)
    })
}

fn write_colored_obj(path: &Path, mesh: &ColoredMesh) -> Result<()> {
    write_atomic(path, |w| {
        writeln!(
            w,
            "# hirad radiosity: v x y z r g b, colours = linear B (W/m2)"
        )?;
        for (p, c) in mesh.positions.iter().zip(&mesh.colors) {
            writeln!(w, "v {} {} {} {} {} {}", p.x, p.y, p.z, c.x, c.y, c.z)?;
        }
        for t in &mesh.triangles {
            writeln!(w, "f {} {} {}", t[0] + 1, t[1] + 1, t[2] + 1)?;
        }
        Ok(())
    })
}

/// Accumulates the binary chunk, buffer views and accessors of a GLB.
#[derive(Default)]
struct GlbBuilder {
    bin: Vec<u8>,
    views: Vec<Value>,
    accessors: Vec<Value>,
}

impl GlbBuilder {
    fn view(&mut self, bytes: &[u8], target: u32) -> usize {
        while !self.bin.len().is_multiple_of(4) {
            self.bin.push(0);
        }
        let off = self.bin.len();
        self.bin.extend_from_slice(bytes);
        self.views.push(json!({
            "buffer": 0, "byteOffset": off, "byteLength": bytes.len(), "target": target
        }));
        self.views.len() - 1
    }

    fn vec3(&mut self, v: &[Vec3], minmax: bool) -> usize {
        let mut bytes = Vec::with_capacity(v.len() * 12);
        for p in v {
            for x in p.to_array() {
                bytes.extend_from_slice(&x.to_le_bytes());
            }
        }
        let view = self.view(&bytes, 34962);
        let mut acc = json!({
            "bufferView": view, "componentType": 5126, "count": v.len(), "type": "VEC3"
        });
        if minmax {
            let mut lo = Vec3::splat(f32::INFINITY);
            let mut hi = Vec3::splat(f32::NEG_INFINITY);
            for p in v {
                lo = lo.min(*p);
                hi = hi.max(*p);
            }
            if v.is_empty() {
                lo = Vec3::ZERO;
                hi = Vec3::ZERO;
            }
            acc["min"] = json!(lo.to_array());
            acc["max"] = json!(hi.to_array());
        }
        self.accessors.push(acc);
        self.accessors.len() - 1
    }

    fn indices(&mut self, idx: &[u32]) -> usize {
        let mut bytes = Vec::with_capacity(idx.len() * 4);
        for i in idx {
            bytes.extend_from_slice(&i.to_le_bytes());
        }
        let view = self.view(&bytes, 34963);
        self.accessors.push(json!({
            "bufferView": view, "componentType": 5125, "count": idx.len(), "type": "SCALAR"
        }));
        self.accessors.len() - 1
    }

    /// Assemble the GLB container around `doc` (which gets buffers, views, accessors).
    fn finish(mut self, mut doc: Value) -> Vec<u8> {
        while !self.bin.len().is_multiple_of(4) {
            self.bin.push(0);
        }
        let extras = doc.get("asset").and_then(|a| a.get("extras")).cloned();
        doc["asset"] =
            json!({"version": "2.0", "generator": format!("hirad {}", hirad_core::VERSION)});
        if let Some(e) = extras {
            doc["asset"]["extras"] = e;
        }
        doc["buffers"] = json!([{"byteLength": self.bin.len()}]);
        doc["bufferViews"] = Value::Array(self.views);
        doc["accessors"] = Value::Array(self.accessors);
        let mut js = serde_json::to_vec(&doc).unwrap_or_default();
        while !js.len().is_multiple_of(4) {
            js.push(b' ');
        }
        let total = 12 + 8 + js.len() + 8 + self.bin.len();
        let mut out = Vec::with_capacity(total);
        out.extend_from_slice(b"glTF");
        out.extend_from_slice(&2u32.to_le_bytes());
        out.extend_from_slice(&(total as u32).to_le_bytes());
        out.extend_from_slice(&(js.len() as u32).to_le_bytes());
        out.extend_from_slice(b"JSON");
        out.extend_from_slice(&js);
        out.extend_from_slice(&(self.bin.len() as u32).to_le_bytes());
        out.extend_from_slice(b"BIN\0");
        out.extend_from_slice(&self.bin);
        out
    }
}

fn write_colored_glb(path: &Path, mesh: &ColoredMesh, up: super::UpAxis) -> Result<()> {
    let white = tonemap_white(&mesh.colors);
    let mut b = GlbBuilder::default();
    let pos = b.vec3(&mesh.positions, true);
    let radiosity = b.vec3(&mesh.colors, false);
    let display: Vec<Vec3> = mesh
        .colors
        .iter()
        .map(|&c| display_linear(c, white))
        .collect();
    let c0 = b.vec3(&display, false);
    let flat: Vec<u32> = mesh.triangles.iter().flatten().copied().collect();
    let ind = b.indices(&flat);
    let mut doc = json!({
        "asset": {"extras": {"radiosity_white": white}},
        "extensionsUsed": ["KHR_materials_unlit"],
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0, "name": "radiosity"}],
        "meshes": [{"name": "radiosity", "primitives": [{
            "attributes": {"POSITION": pos, "COLOR_0": c0},
            "indices": ind, "material": 0, "mode": 4
        }]}],
        "materials": [{
            "name": "vertex_colors",
            "pbrMetallicRoughness": {"baseColorFactor": [1.0, 1.0, 1.0, 1.0],
                                     "metallicFactor": 0.0, "roughnessFactor": 1.0},
            "extensions": {"KHR_materials_unlit": {}}
        }],
    });
    doc["meshes"][0]["primitives"][0]["attributes"][RADIOSITY] = json!(radiosity);
    if up == super::UpAxis::Z {
        doc["nodes"] = json!([{"mesh": 0, "name": "radiosity"}, z_up_to_y_up(vec![0])]);
        doc["scenes"] = json!([{"nodes": [1]}]);
    }
    write_bytes_atomic(path, &b.finish(doc))
}

/// Name of the root node that turns a Z-up model to glTF's +Y up.
pub const Z_UP_NODE: &str = "z_up_to_y_up";

/// The root node turning Z-up `children` to glTF's +Y up: `(x, y, z) → (x, z, −y)`, a
/// rotation of −90° about X.
fn z_up_to_y_up(children: Vec<usize>) -> serde_json::Value {
    let h = std::f32::consts::FRAC_1_SQRT_2;
    json!({"name": Z_UP_NODE, "rotation": [-h, 0.0, 0.0, h], "children": children})
}

/// The glTF attribute holding linear radiosity B.
const RADIOSITY: &str = "_RADIOSITY";

/// Read back a coloured mesh written by [`write_colored_mesh`] (`.glb` or `.ply`). Colours are
/// the linear ones (`_RADIOSITY`, `radiosity_*`), or the display colours (`COLOR_0`, the PLY's
/// bytes) when a file has only those.
pub fn read_colored_mesh(path: &Path) -> Result<ColoredMesh> {
    match ext_of(path).as_str() {
        "ply" => {
            let m = super::ply::read(path)?;
            let n = m.positions.len();
            let colors = m
                .linear_colors
                .or(m.colors)
                .unwrap_or_else(|| vec![Vec3::ZERO; n]);
            Ok(ColoredMesh {
                positions: m.positions,
                triangles: m.triangles,
                colors,
            })
        }
        "glb" | "gltf" => read_colored_gltf(path),
        e => Err(Error::Config(format!(
            "{}: cannot read meshes from '.{e}' (use .glb or .ply)",
            path.display()
        ))),
    }
}

fn read_colored_gltf(path: &Path) -> Result<ColoredMesh> {
    let bytes = hirad_core::io::read_input(path)?;
    let base = path.parent().map(Path::to_path_buf);
    let r = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| -> Result<ColoredMesh> {
        let bad = |e: gltf::Error| Error::input(path, format!("malformed glTF: {e}"));
        let g = gltf::Gltf::from_slice(&bytes).map_err(bad)?;
        super::gltf_io::check_buffer_files(path, &g.document, base.as_deref())?;
        let buffers = gltf::import_buffers(&g.document, base.as_deref(), g.blob).map_err(bad)?;
        let mut out = ColoredMesh::default();
        for mesh in g.document.meshes() {
            for prim in mesh.primitives() {
                let reader = prim.reader(|b| buffers.get(b.index()).map(|d| &d.0[..]));
                let base = out.positions.len() as u32;
                let Some(p) = reader.read_positions() else {
                    continue;
                };
                out.positions.extend(p.map(Vec3::from));
                let n = out.positions.len() - base as usize;
                let radiosity = prim
                    .get(&gltf::Semantic::Extras(RADIOSITY[1..].into()))
                    .filter(|a| {
                        a.data_type() == gltf::accessor::DataType::F32
                            && a.dimensions() == gltf::accessor::Dimensions::Vec3
                    })
                    .and_then(|a| {
                        gltf::accessor::Iter::<[f32; 3]>::new(a, |b: gltf::Buffer| {
                            buffers.get(b.index()).map(|d| &d.0[..])
                        })
                    });
                match (radiosity, reader.read_colors(0)) {
                    (Some(r), _) => out.colors.extend(r.map(Vec3::from)),
                    (None, Some(c)) => out.colors.extend(c.into_rgb_f32().map(Vec3::from)),
                    (None, None) => out.colors.extend(std::iter::repeat_n(Vec3::ZERO, n)),
                }
                let idx: Vec<u32> = match reader.read_indices() {
                    Some(i) => i.into_u32().collect(),
                    None => (0..n as u32).collect(),
                };
                if idx.iter().any(|&i| i as usize >= n) || out.colors.len() != out.positions.len() {
                    return Err(Error::input(path, "index or colour count out of range"));
                }
                out.triangles.extend(
                    idx.chunks_exact(3)
                        .map(|t| [base + t[0], base + t[1], base + t[2]]),
                );
            }
        }
        Ok(out)
    }));
    r.unwrap_or_else(|_| Err(Error::input(path, "malformed glTF (the reader panicked)")))
}

/// Write a whole scene (geometry, objects, materials) as `.obj` (+ `.mtl`), `.glb`, or `.toml`
/// (a scene description next to `<stem>.obj` + `<stem>.mtl`, keeping sun, sky, cameras and up
/// axis, which OBJ and glTF files do not carry).
///
/// `.obj` + `.mtl` next to it: `Kd` = ρ, `Ke` = L_e, one `o` per object, a `# +Z up` header
/// comment when the scene is Z-up. `.glb`: one node and mesh per object with its own vertices,
/// one primitive per material, `baseColorFactor` = ρ, `emissiveFactor` ×
/// `KHR_materials_emissive_strength` = L_e; a Z-up scene is put under a root node rotating it
/// to glTF's +Y up.
pub fn write_scene(path: &Path, scene: &Scene) -> Result<()> {
    match ext_of(path).as_str() {
        "obj" => write_scene_obj(path, scene),
        "glb" => write_scene_glb(path, scene),
        "toml" => write_scene_toml(path, scene),
        e => Err(Error::Config(format!(
            "{}: cannot write scenes as '.{e}' (use .obj, .glb or .toml)",
            path.display()
        ))),
    }
}

fn toml_vec(v: Vec3) -> String {
    format!("[{:?}, {:?}, {:?}]", v.x, v.y, v.z)
}

/// Write `scene` as a TOML scene description (`super::desc`) plus `<stem>.obj` and `<stem>.mtl`
/// in the same directory.
pub fn write_scene_toml(path: &Path, scene: &Scene) -> Result<()> {
    let obj = path.with_extension("obj");
    write_scene_obj(&obj, scene)?;
    let obj_name = obj
        .file_name()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    let q = |s: &str| serde_json::to_string(s).unwrap_or_else(|_| "\"\"".into());
    let mut t = String::new();
    t += &format!("# hirad scene '{}'\n", scene.name);
    t += &format!("name = {}\n", q(&scene.name));
    t += match scene.up {
        super::UpAxis::Y => "up = \"y\"\n",
        super::UpAxis::Z => "up = \"z\"\n",
    };
    if let Some(sky) = scene.sky {
        t += &format!("sky = {}\n", toml_vec(sky));
    }
    t += &format!("\n[[mesh]]\nfile = {}\n", q(&obj_name));
    if let Some(sun) = scene.sun {
        t += &format!(
            "\n[sun]\ndirection = {}\nirradiance = {}\n",
            toml_vec(sun.direction),
            toml_vec(sun.irradiance)
        );
    }
    for c in &scene.cameras {
        t += &format!(
            "\n[[camera]]\nname = {}\neye = {}\ntarget = {}\nup = {}\nfov = {:?}\n\
             width = {}\nheight = {}\n",
            q(&c.name),
            toml_vec(c.eye),
            toml_vec(c.target),
            toml_vec(c.up),
            c.fov_deg,
            c.width,
            c.height
        );
    }
    write_bytes_atomic(path, t.as_bytes())
}

/// Write `scene` as OBJ with a material library `<stem>.mtl` in the same directory.
pub fn write_scene_obj(path: &Path, scene: &Scene) -> Result<()> {
    let mtl = path.with_extension("mtl");
    let mtl_name = mtl
        .file_name()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "scene.mtl".into());
    write_atomic(&mtl, |w| {
        writeln!(
            w,
            "# hirad scene '{}': Kd = rho, Ke = emitted radiance",
            scene.name
        )?;
        for m in &scene.materials {
            writeln!(w, "\nnewmtl {}", m.name)?;
            writeln!(w, "Kd {} {} {}", m.rho.x, m.rho.y, m.rho.z)?;
            if m.is_emitter() {
                writeln!(w, "Ke {} {} {}", m.emission.x, m.emission.y, m.emission.z)?;
            }
        }
        Ok(())
    })?;
    write_atomic(path, |w| {
        writeln!(w, "# hirad scene '{}'", scene.name)?;
        let up = match scene.up {
            super::UpAxis::Y => "+Y up",
            super::UpAxis::Z => "+Z up",
        };
        writeln!(w, "# {up}")?;
        writeln!(w, "mtllib {mtl_name}")?;
        for p in &scene.positions {
            writeln!(w, "v {} {} {}", p.x, p.y, p.z)?;
        }
        let (mut obj, mut mat) = (u32::MAX, u32::MAX);
        for (i, t) in scene.triangles.iter().enumerate() {
            if scene.tri_object[i] != obj {
                obj = scene.tri_object[i];
                writeln!(w, "o {}", scene.objects[obj as usize])?;
            }
            if scene.tri_material[i] != mat {
                mat = scene.tri_material[i];
                writeln!(w, "usemtl {}", scene.materials[mat as usize].name)?;
            }
            writeln!(w, "f {} {} {}", t[0] + 1, t[1] + 1, t[2] + 1)?;
        }
        Ok(())
    })
}

/// Write `scene` as binary glTF (layout: [`write_scene`]).
pub fn write_scene_glb(path: &Path, scene: &Scene) -> Result<()> {
    let mut b = GlbBuilder::default();
    // Triangles grouped per object, then per material, in input order.
    let mut by_obj: Vec<Vec<u32>> = vec![Vec::new(); scene.objects.len()];
    for (i, &o) in scene.tri_object.iter().enumerate() {
        by_obj[o as usize].push(i as u32);
    }
    let mut meshes = Vec::new();
    let mut nodes = Vec::new();
    for (o, tris) in by_obj.iter().enumerate() {
        if tris.is_empty() {
            continue;
        }
        let mut remap: HashMap<u32, u32> = HashMap::new();
        let mut verts: Vec<Vec3> = Vec::new();
        let mut per_mat: Vec<(u32, Vec<u32>)> = Vec::new();
        for &t in tris {
            let m = scene.tri_material[t as usize];
            let slot = match per_mat.iter().position(|(k, _)| *k == m) {
                Some(s) => s,
                None => {
                    per_mat.push((m, Vec::new()));
                    per_mat.len() - 1
                }
            };
            for v in scene.triangles[t as usize] {
                let id = *remap.entry(v).or_insert_with(|| {
                    verts.push(scene.positions[v as usize]);
                    verts.len() as u32 - 1
                });
                per_mat[slot].1.push(id);
            }
        }
        let pos = b.vec3(&verts, true);
        let prims: Vec<Value> = per_mat
            .iter()
            .map(|(m, idx)| {
                let ind = b.indices(idx);
                json!({"attributes": {"POSITION": pos}, "indices": ind, "material": m, "mode": 4})
            })
            .collect();
        meshes.push(json!({"name": scene.objects[o], "primitives": prims}));
        nodes.push(json!({"name": scene.objects[o], "mesh": meshes.len() - 1}));
    }
    let mut uses_strength = false;
    let materials: Vec<Value> = scene
        .materials
        .iter()
        .map(|m| {
            let mut v = json!({
                "name": m.name,
                "pbrMetallicRoughness": {
                    "baseColorFactor": [m.rho.x, m.rho.y, m.rho.z, 1.0],
                    "metallicFactor": 0.0, "roughnessFactor": 1.0
                }
            });
            if m.is_emitter() {
                let s = m.emission.max_element();
                if s > 1.0 {
                    uses_strength = true;
                    v["emissiveFactor"] = json!((m.emission / s).to_array());
                    v["extensions"] =
                        json!({"KHR_materials_emissive_strength": {"emissiveStrength": s}});
                } else {
                    v["emissiveFactor"] = json!(m.emission.to_array());
                }
            }
            v
        })
        .collect();
    let n = nodes.len();
    let roots: Vec<usize> = if scene.up == super::UpAxis::Z {
        nodes.push(z_up_to_y_up((0..n).collect()));
        vec![n]
    } else {
        (0..n).collect()
    };
    let mut doc = json!({
        "scene": 0,
        "scenes": [{"name": scene.name, "nodes": roots}],
        "nodes": nodes,
        "meshes": meshes,
        "materials": materials,
    });
    if uses_strength {
        doc["extensionsUsed"] = json!(["KHR_materials_emissive_strength"]);
    }
    write_bytes_atomic(path, &b.finish(doc))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn mesh() -> ColoredMesh {
        ColoredMesh {
            positions: vec![Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::new(1.0, 1.0, 0.5)],
            triangles: vec![[0, 1, 2], [1, 3, 2]],
            colors: vec![
                Vec3::new(0.0, 0.5, 1.0),
                Vec3::new(2.0, 3.0, 4.0),
                Vec3::new(10.0, 0.25, 0.0),
                Vec3::new(0.125, 7.5, 1e-3),
            ],
        }
    }

    #[test]
    fn ply_and_glb_round_trip_exactly() {
        let d = tempfile::tempdir().unwrap();
        for ext in ["ply", "glb"] {
            let p = d.path().join(format!("m.{ext}"));
            write_colored_mesh(&p, &mesh()).unwrap();
            assert_eq!(read_colored_mesh(&p).unwrap(), mesh(), "{ext}");
        }
    }

    #[test]
    fn z_up_glb_stands_upright_and_reads_back_in_its_own_coordinates() {
        let d = tempfile::tempdir().unwrap();
        let p = d.path().join("m.glb");
        write_colored_mesh_up(&p, &mesh(), super::super::UpAxis::Z).unwrap();
        assert_eq!(read_colored_mesh(&p).unwrap(), mesh());
        // The scene's +Z, seen through the node's transform, is glTF's +Y (and +Y is −Z).
        let (doc, _, _) = gltf::import(&p).unwrap();
        let root = doc.default_scene().unwrap().nodes().next().unwrap();
        assert_eq!(root.name(), Some(Z_UP_NODE));
        let (_, r, _) = root.transform().decomposed();
        let q = glam::Quat::from_array(r);
        assert!((q * Vec3::Z - Vec3::Y).length() < 1e-6, "{:?}", q * Vec3::Z);
        assert!((q * Vec3::Y + Vec3::Z).length() < 1e-6, "{:?}", q * Vec3::Y);
        assert_eq!(
            root.children().next().unwrap().mesh().map(|m| m.index()),
            Some(0)
        );
        // Y-up: the mesh node is the root.
        write_colored_mesh(&p, &mesh()).unwrap();
        let (doc, _, _) = gltf::import(&p).unwrap();
        let root = doc.default_scene().unwrap().nodes().next().unwrap();
        assert_eq!(root.name(), Some("radiosity"));
    }

    #[test]
    fn glb_colour_is_the_clamped_display_colour() {
        let d = tempfile::tempdir().unwrap();
        let p = d.path().join("m.glb");
        write_colored_mesh(&p, &mesh()).unwrap();
        let (doc, buffers, _) = gltf::import(&p).unwrap();
        let prim = doc.meshes().next().unwrap().primitives().next().unwrap();
        let r = prim.reader(|b| buffers.get(b.index()).map(|d| &d.0[..]));
        let c: Vec<[f32; 3]> = r.read_colors(0).unwrap().into_rgb_f32().collect();
        let white = tonemap_white(&mesh().colors);
        for (c, b) in c.iter().zip(mesh().colors) {
            assert_eq!(Vec3::from(*c), display_linear(b, white));
            assert!(c.iter().all(|v| (0.0..=1.0).contains(v)), "{c:?}");
        }
    }

    #[test]
    fn obj_with_vertex_colours_loads_as_scene_geometry() {
        let d = tempfile::tempdir().unwrap();
        let p = d.path().join("m.obj");
        write_colored_mesh(&p, &mesh()).unwrap();
        let text = std::fs::read_to_string(&p).unwrap();
        assert!(text.contains("v 1 0 0 2 3 4"), "{text}");
        let raw = super::super::obj::load(&p).unwrap();
        assert_eq!(raw.positions, mesh().positions);
        assert_eq!(raw.triangles, mesh().triangles);
    }

    #[test]
    fn tonemap_white_is_99th_percentile() {
        let c: Vec<Vec3> = (1..=200).map(|i| Vec3::splat(i as f32)).collect();
        assert_eq!(tonemap_white(&c), 198.0);
        assert_eq!(tonemap_white(&[]), 1.0);
        assert_eq!(srgb_u8(1.0), 255);
        assert_eq!(srgb_u8(0.0), 0);
        assert_eq!(srgb_u8(0.5), 188);
    }
}
