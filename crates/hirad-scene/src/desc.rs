//! TOML scene description files: combine mesh files, add lights, sun, sky, cameras and material
//! overrides. This is how a mesh without emitters (e.g. `franka_panda`, `copper_beech`) is lit.
//!
//! The format (keys, defaults, units) is documented for users in `docs/scene-format.md`.
//! Materials of different mesh files with the same name are merged (the first definition wins).
//! Negative-determinant transforms (mirroring) reverse the winding so faces keep facing out.
//! Errors name the TOML file and line (syntax errors, unknown keys, missing mesh files, unknown
//! material names in overrides).

use super::{Camera, Material, RawScene, Scene, SceneOptions, Sun, UpAxis};
use glam::{Mat4, Quat, Vec3};
use hirad_core::{Error, Result};
use serde::Deserialize;
use std::collections::{BTreeMap, HashMap};
use std::path::Path;
use toml::Spanned;

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct Desc {
    name: Option<String>,
    up: Option<UpAxis>,
    sky: Option<[f32; 3]>,
    #[serde(default)]
    mesh: Vec<MeshDesc>,
    #[serde(default)]
    light: Vec<LightDesc>,
    sun: Option<SunDesc>,
    #[serde(default)]
    camera: Vec<CameraDesc>,
    #[serde(default)]
    materials: BTreeMap<Spanned<String>, MaterialDesc>,
}

#[derive(Deserialize)]
#[serde(untagged)]
enum Scale {
    Uniform(f32),
    Axes([f32; 3]),
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct MeshDesc {
    file: Spanned<String>,
    scale: Option<Scale>,
    rotate: Option<[f32; 3]>,
    translate: Option<[f32; 3]>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct LightDesc {
    name: Option<String>,
    corner: [f32; 3],
    edge1: [f32; 3],
    edge2: [f32; 3],
    radiance: [f32; 3],
    rho: Option<[f32; 3]>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct SunDesc {
    direction: Spanned<[f32; 3]>,
    irradiance: [f32; 3],
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct CameraDesc {
    name: String,
    eye: [f32; 3],
    target: [f32; 3],
    up: Option<[f32; 3]>,
    fov: Option<f32>,
    width: Option<u32>,
    height: Option<u32>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct MaterialDesc {
    rho: Option<[f32; 3]>,
    emission: Option<[f32; 3]>,
}

fn line_of(text: &str, offset: usize) -> usize {
    text.as_bytes()[..offset.min(text.len())]
        .iter()
        .filter(|&&b| b == b'\n')
        .count()
        + 1
}

/// Load a TOML scene description and validate the combined scene.
pub fn load(path: &Path, opts: &SceneOptions) -> Result<Scene> {
    let mut raw = load_raw(path, opts.mgf_divisions)?;
    if let Some(up) = opts.up {
        raw.up = up;
    }
    Scene::from_raw(raw, opts)
}

/// Load a TOML scene description into raw (unvalidated) scene data; MGF meshes are
/// tessellated with `mgf_divisions` ([`super::mgf::load_with`]).
pub fn load_raw(path: &Path, mgf_divisions: usize) -> Result<RawScene> {
    let bytes = hirad_core::io::read_input(path)?;
    let text = String::from_utf8(bytes)
        .map_err(|_| Error::input(path, "not UTF-8 text (TOML scene description expected)"))?;
    let desc: Desc = toml::from_str(&text).map_err(|e| match e.span() {
        Some(s) => Error::input_at(path, line_of(&text, s.start), e.message().to_string()),
        None => Error::input(path, e.message().to_string()),
    })?;
    let at = |span: std::ops::Range<usize>, msg: String| {
        Error::input_at(path, line_of(&text, span.start), msg)
    };
    let dir = path.parent().unwrap_or(Path::new(""));
    let mut raw = RawScene {
        name: desc.name.clone().unwrap_or_else(|| {
            path.file_stem()
                .map(|s| s.to_string_lossy().into_owned())
                .unwrap_or_else(|| "scene".into())
        }),
        source: Some(path.to_path_buf()),
        ..Default::default()
    };
    let mut mat_ids: HashMap<String, u32> = HashMap::new();
    let mut first_up = None;
    // Two-sided when every mesh file says so (MGF `sides 2`).
    raw.two_sided = !desc.mesh.is_empty();
    for m in &desc.mesh {
        let file = dir.join(m.file.get_ref());
        if !file.is_file() {
            return Err(at(
                m.file.span(),
                format!("mesh file {} not found", file.display()),
            ));
        }
        let ext = file
            .extension()
            .and_then(|e| e.to_str())
            .unwrap_or("")
            .to_ascii_lowercase();
        let part = match ext.as_str() {
            "obj" => super::obj::load(&file)?,
            "gltf" | "glb" => super::gltf_io::load(&file)?,
            "ply" => super::ply::load(&file)?,
            "mgf" => super::mgf::load_with(&file, mgf_divisions)?.raw,
            _ => {
                return Err(at(
                    m.file.span(),
                    format!(
                        "mesh file {} is not .obj, .gltf, .glb, .ply or .mgf",
                        file.display()
                    ),
                ))
            }
        };
        first_up.get_or_insert(part.up);
        raw.two_sided &= part.two_sided;
        let scale = match m.scale {
            None => Vec3::ONE,
            Some(Scale::Uniform(s)) => Vec3::splat(s),
            Some(Scale::Axes(a)) => Vec3::from(a),
        };
        let r = Vec3::from(m.rotate.unwrap_or([0.0; 3])) * (std::f32::consts::PI / 180.0);
        let rot =
            Quat::from_rotation_z(r.z) * Quat::from_rotation_y(r.y) * Quat::from_rotation_x(r.x);
        let xf = Mat4::from_scale_rotation_translation(
            scale,
            rot,
            Vec3::from(m.translate.unwrap_or([0.0; 3])),
        );
        merge(&mut raw, part, xf, &mut mat_ids);
    }
    raw.up = desc.up.or(first_up).unwrap_or_default();
    for (k, l) in desc.light.iter().enumerate() {
        let name = l.name.clone().unwrap_or_else(|| format!("light{k}"));
        let mat = Material {
            name: format!("light_{name}"),
            rho: Vec3::from(l.rho.unwrap_or([0.0; 3])),
            emission: Vec3::from(l.radiance),
        };
        let m = raw.materials.len() as u32;
        mat_ids.insert(mat.name.clone(), m);
        raw.materials.push(mat);
        raw.objects.push(name);
        let o = raw.objects.len() as u32 - 1;
        let c = Vec3::from(l.corner);
        let (e1, e2) = (Vec3::from(l.edge1), Vec3::from(l.edge2));
        let b = raw.positions.len() as u32;
        raw.positions.extend([c, c + e1, c + e1 + e2, c + e2]);
        raw.triangles.extend([[b, b + 1, b + 2], [b, b + 2, b + 3]]);
        raw.tri_material.extend([m, m]);
        raw.tri_object.extend([o, o]);
    }
    if let Some(s) = &desc.sun {
        let d = Vec3::from(*s.direction.get_ref());
        if !d.is_finite() || d.length() == 0.0 {
            return Err(at(
                s.direction.span(),
                "sun direction must be a non-zero vector".into(),
            ));
        }
        raw.sun = Some(Sun {
            direction: d.normalize(),
            irradiance: Vec3::from(s.irradiance),
        });
    }
    raw.sky = desc.sky.map(Vec3::from);
    for c in &desc.camera {
        raw.cameras.push(Camera {
            name: c.name.clone(),
            eye: Vec3::from(c.eye),
            target: Vec3::from(c.target),
            up: c.up.map(Vec3::from).unwrap_or(raw.up.vector()),
            fov_deg: c.fov.unwrap_or(45.0),
            width: c.width.unwrap_or(512),
            height: c.height.unwrap_or(512),
        });
    }
    for (name, o) in &desc.materials {
        let Some(&id) = mat_ids.get(name.get_ref()) else {
            let mut known: Vec<&String> = mat_ids.keys().collect();
            known.sort();
            return Err(at(
                name.span(),
                format!(
                    "material '{}' is not in the meshes (materials: {})",
                    name.get_ref(),
                    known
                        .iter()
                        .map(|s| s.as_str())
                        .collect::<Vec<_>>()
                        .join(", ")
                ),
            ));
        };
        let m = &mut raw.materials[id as usize];
        if let Some(r) = o.rho {
            m.rho = Vec3::from(r);
        }
        if let Some(e) = o.emission {
            m.emission = Vec3::from(e);
        }
    }
    Ok(raw)
}

/// Append `part`, transformed by `xf`, to `raw`, merging materials by name.
fn merge(raw: &mut RawScene, part: RawScene, xf: Mat4, mat_ids: &mut HashMap<String, u32>) {
    let vbase = raw.positions.len() as u32;
    let obase = raw.objects.len() as u32;
    let sided = |i: usize| part.two_sided || part.two_sided_materials.get(i) == Some(&true);
    let sides: Vec<bool> = (0..part.materials.len()).map(sided).collect();
    let mat_map: Vec<u32> = part
        .materials
        .into_iter()
        .zip(sides)
        .map(|(m, two)| {
            let id = *mat_ids.entry(m.name.clone()).or_insert_with(|| {
                raw.materials.push(m);
                raw.materials.len() as u32 - 1
            });
            raw.two_sided_materials.resize(raw.materials.len(), false);
            raw.two_sided_materials[id as usize] |= two;
            id
        })
        .collect();
    let objects = if part.objects.is_empty() {
        vec!["default".to_string()]
    } else {
        part.objects
    };
    raw.objects.extend(objects);
    raw.positions
        .extend(part.positions.iter().map(|&p| xf.transform_point3(p)));
    let flip = xf.determinant() < 0.0;
    for (i, t) in part.triangles.iter().enumerate() {
        let t = if flip { [t[0], t[2], t[1]] } else { *t };
        raw.triangles.push(t.map(|v| v.saturating_add(vbase)));
        // Out-of-range ids are left out of range for `Scene::from_raw` to report.
        raw.tri_material.push(
            mat_map
                .get(part.tri_material[i] as usize)
                .copied()
                .unwrap_or(u32::MAX),
        );
        raw.tri_object.push(
            part.tri_object
                .get(i)
                .copied()
                .unwrap_or(0)
                .saturating_add(obase),
        );
    }
    raw.cameras.extend(part.cameras);
    if part.sun.is_some() {
        raw.sun = part.sun;
    }
    if part.sky.is_some() {
        raw.sky = part.sky;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn combines_meshes_lights_and_overrides() {
        let d = tempfile::tempdir().unwrap();
        std::fs::write(d.path().join("m.mtl"), "newmtl grey\nKd 0.5 0.5 0.5\n").unwrap();
        std::fs::write(
            d.path().join("q.obj"),
            "mtllib m.mtl\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nusemtl grey\nf 1 2 3 4\n",
        )
        .unwrap();
        let toml = d.path().join("s.toml");
        std::fs::write(
            &toml,
            r#"up = "z"
sky = [0.1, 0.2, 0.3]
[[mesh]]
file = "q.obj"
scale = 2.0
translate = [0.0, 0.0, 1.0]
[[mesh]]
file = "q.obj"
scale = [1.0, 1.0, -1.0]
rotate = [0.0, 0.0, 90.0]
[[light]]
name = "lamp"
corner = [0.0, 0.0, 3.0]
edge1 = [0.0, 0.5, 0.0]
edge2 = [0.5, 0.0, 0.0]
radiance = [4.0, 4.0, 4.0]
[sun]
direction = [0.0, 0.0, 2.0]
irradiance = [100.0, 100.0, 100.0]
[[camera]]
name = "top"
eye = [0.0, 0.0, 5.0]
target = [0.0, 0.0, 0.0]
[materials.grey]
rho = [0.25, 0.5, 0.75]
"#,
        )
        .unwrap();
        let s = load(&toml, &SceneOptions::default()).unwrap();
        assert_eq!(s.num_triangles(), 6);
        assert_eq!(s.up, UpAxis::Z);
        assert_eq!(s.materials.len(), 2);
        assert_eq!(s.materials[0].rho, Vec3::new(0.25, 0.5, 0.75));
        // Areas: 4 (scaled quad) + 1 (mirrored quad) + 0.25 (light).
        assert!((s.total_area() - 5.25).abs() < 1e-5);
        // The mirror image (z → -z) of an up-facing quad faces down (the winding is flipped
        // so the normal transforms like a normal); the light faces -z.
        assert!((s.normals[0] - Vec3::Z).length() < 1e-6);
        assert!((s.normals[2] + Vec3::Z).length() < 1e-6, "{}", s.normals[2]);
        assert!((s.normals[4] + Vec3::Z).length() < 1e-6);
        // Φ = π · L_e · A.
        let p = s.emitted_power();
        assert!((p.x - std::f64::consts::PI * 4.0 * 0.25).abs() < 1e-5);
        assert_eq!(s.sun.unwrap().direction, Vec3::Z);
        assert_eq!(s.cameras[0].up, Vec3::Z);
        assert_eq!(s.sky, Some(Vec3::new(0.1, 0.2, 0.3)));
    }
}
