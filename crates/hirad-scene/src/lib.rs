#![warn(missing_docs)]
//! The scene model: flat arrays of f32 vertices and `u32` triangle indices, one material and one
//! object id per triangle, materials with diffuse reflectance ρ and emitted radiance L_e,
//! optional sun and sky, camera viewpoints.
//!
//! Conventions (`spec/radiosity.md`): surfaces are triangles (polygons are fan-triangulated at
//! load), one-sided, facing the geometric normal of counter-clockwise winding. Emitted exitance
//! is E = π·L_e. Every loader produces a [`RawScene`] and goes through [`Scene::from_raw`], which
//! is the one place where input is validated: non-finite coordinates, out-of-range indices and
//! reflectances outside [0, 1] are errors naming the file; channels above `max_reflectance`
//! (typically ρ = 1 exactly) are clamped to it with one warning listing the materials;
//! zero-area triangles are dropped and counted; an empty scene is an error. Loaders report
//! file and line themselves where the file has lines (OBJ, MTL, ASCII PLY, TOML). `SceneOptions`
//! `up` overrides the up axis a loader found.

use glam::Vec3;
use hirad_core::geom::Aabb;
use hirad_core::{Error, Result};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// A diffuse material.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Material {
    /// Name, unique within a scene.
    pub name: String,
    /// Diffuse reflectance ρ, linear RGB in [0, 1).
    pub rho: Vec3,
    /// Emitted radiance L_e (linear RGB, W/(m²·sr)); exitance is π·L_e. Front face only.
    pub emission: Vec3,
}

impl Material {
    /// Non-emitting material of reflectance `rho`.
    pub fn diffuse(name: &str, rho: Vec3) -> Self {
        Self {
            name: name.to_string(),
            rho,
            emission: Vec3::ZERO,
        }
    }

    /// True when the material emits.
    pub fn is_emitter(&self) -> bool {
        self.emission.max_element() > 0.0
    }
}

/// The up axis of a file.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum UpAxis {
    /// +Y up (the default).
    #[default]
    Y,
    /// +Z up.
    Z,
}

impl UpAxis {
    /// Unit vector of the axis.
    pub fn vector(self) -> Vec3 {
        match self {
            UpAxis::Y => Vec3::Y,
            UpAxis::Z => Vec3::Z,
        }
    }
}

/// A directional sun.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Sun {
    /// Unit vector pointing from the scene towards the sun.
    pub direction: Vec3,
    /// Irradiance on a surface facing the sun (W/m², RGB).
    pub irradiance: Vec3,
}

/// A pinhole camera viewpoint.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Camera {
    /// Name of the viewpoint.
    pub name: String,
    /// Eye position (scene units).
    pub eye: Vec3,
    /// Point looked at (scene units).
    pub target: Vec3,
    /// Up direction of the image.
    pub up: Vec3,
    /// Vertical field of view in degrees.
    pub fov_deg: f32,
    /// Image width, pixels.
    pub width: u32,
    /// Image height, pixels.
    pub height: u32,
}

/// What loading noticed and repaired.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct LoadReport {
    /// Zero-area triangles dropped.
    pub degenerate_dropped: usize,
    /// Materials whose ρ = 1 channel was clamped to `max_reflectance`.
    pub clamped_materials: Vec<String>,
    /// Wall time of loading, seconds.
    pub load_seconds: f64,
}

/// Unvalidated scene data, as a loader or generator produces it.
#[derive(Clone, Debug, Default)]
pub struct RawScene {
    /// Scene name (file stem or built-in name).
    pub name: String,
    /// File the data came from (for error messages); `None` for generated scenes.
    pub source: Option<PathBuf>,
    /// Vertex positions (scene units, usually metres).
    pub positions: Vec<Vec3>,
    /// Vertex indices per triangle, counter-clockwise seen from the front.
    pub triangles: Vec<[u32; 3]>,
    /// Material index per triangle.
    pub tri_material: Vec<u32>,
    /// Object (group) index per triangle.
    pub tri_object: Vec<u32>,
    /// Object (group) names, indexed by object id.
    pub objects: Vec<String>,
    /// Materials, indexed by material id.
    pub materials: Vec<Material>,
    /// Optional directional sun.
    pub sun: Option<Sun>,
    /// Uniform sky radiance (RGB).
    pub sky: Option<Vec3>,
    /// Named viewpoints; the first is the default.
    pub cameras: Vec<Camera>,
    /// Up axis of the data.
    pub up: UpAxis,
    /// The file gives every non-emitting surface a back face (MGF `sides 2`): solves and
    /// images are two-sided without `--two-sided`.
    pub two_sided: bool,
    /// Per material (indexed as `materials`, missing entries false): surfaces of it have a back
    /// face in every solve, as MGF `sides 2` in a file whose other materials are one-sided.
    pub two_sided_materials: Vec<bool>,
}

/// Options applied while validating a raw scene.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct SceneOptions {
    /// ρ = 1 channels are clamped to this value (spec default 0.95).
    pub max_reflectance: f32,
    /// Overrides the up axis a loader found in the file (`--up`).
    #[serde(default)]
    pub up: Option<UpAxis>,
    /// Quarter-circle divisions of MGF's curved primitives (`--mgf-divisions`, 1..=64).
    #[serde(default = "default_mgf_divisions")]
    pub mgf_divisions: usize,
}

fn default_mgf_divisions() -> usize {
    mgf::DEFAULT_DIVISIONS
}

impl Default for SceneOptions {
    fn default() -> Self {
        Self {
            max_reflectance: 0.95,
            up: None,
            mgf_divisions: mgf::DEFAULT_DIVISIONS,
        }
    }
}

/// A validated scene. All arrays indexed by triangle have `num_triangles()` entries.
#[derive(Clone, Debug)]
pub struct Scene {
    /// Scene name (file stem or built-in name).
    pub name: String,
    /// File the scene came from; `None` for built-in scenes.
    pub source: Option<PathBuf>,
    /// Vertex positions (scene units, usually metres).
    pub positions: Vec<Vec3>,
    /// Vertex indices per triangle (degenerate triangles dropped).
    pub triangles: Vec<[u32; 3]>,
    /// Material index per triangle.
    pub tri_material: Vec<u32>,
    /// Object index per triangle.
    pub tri_object: Vec<u32>,
    /// Object names; `["default"]` when the loader named none.
    pub objects: Vec<String>,
    /// Materials, reflectance clamped to `max_reflectance`.
    pub materials: Vec<Material>,
    /// Unit geometric normal per triangle (counter-clockwise winding faces the viewer).
    pub normals: Vec<Vec3>,
    /// Area per triangle.
    pub areas: Vec<f32>,
    /// Bounding box of the triangles kept.
    pub bbox: Aabb,
    /// Optional directional sun.
    pub sun: Option<Sun>,
    /// Uniform sky radiance (RGB).
    pub sky: Option<Vec3>,
    /// Named viewpoints; the first is the default.
    pub cameras: Vec<Camera>,
    /// Up axis (the loader's, or `SceneOptions::up`).
    pub up: UpAxis,
    /// Every non-emitting surface has a back face ([`RawScene::two_sided`]).
    pub two_sided: bool,
    /// Per material: its surfaces have a back face ([`RawScene::two_sided_materials`]).
    pub two_sided_materials: Vec<bool>,
    /// What loading noticed and repaired.
    pub report: LoadReport,
}

impl Scene {
    /// Bytes of the scene's arrays (positions, triangles, per-triangle data, names).
    pub fn memory_bytes(&self) -> usize {
        use std::mem::size_of;
        self.positions.capacity() * size_of::<Vec3>()
            + self.triangles.capacity() * size_of::<[u32; 3]>()
            + (self.tri_material.capacity() + self.tri_object.capacity() + self.areas.capacity())
                * 4
            + self.normals.capacity() * size_of::<Vec3>()
            + self.objects.capacity() * size_of::<String>()
            + self.objects.iter().map(|o| o.capacity()).sum::<usize>()
            + self.materials.capacity() * size_of::<Material>()
            + self
                .materials
                .iter()
                .map(|m| m.name.capacity())
                .sum::<usize>()
            + self.cameras.capacity() * size_of::<Camera>()
    }

    /// Validate raw data and build the scene (see the module docs for the rules).
    pub fn from_raw(raw: RawScene, opts: &SceneOptions) -> Result<Scene> {
        let file = raw
            .source
            .clone()
            .unwrap_or_else(|| PathBuf::from(format!("<{}>", raw.name)));
        let n = raw.triangles.len();
        if raw.tri_material.len() != n || raw.tri_object.len() != n {
            return Err(Error::input(&file, "per-triangle arrays differ in length"));
        }
        for (i, p) in raw.positions.iter().enumerate() {
            if !p.is_finite() {
                return Err(Error::input(
                    &file,
                    format!("vertex {} has a non-finite coordinate {p}", i + 1),
                ));
            }
        }
        let mut materials = raw.materials;
        let mut clamped = Vec::new();
        let maxr = opts.max_reflectance;
        if !(0.0..1.0).contains(&maxr) {
            return Err(Error::Config(format!(
                "max-reflectance must be in [0, 1), got {maxr}"
            )));
        }
        for m in &mut materials {
            if !m.rho.is_finite() || m.rho.min_element() < 0.0 || m.rho.max_element() > 1.0 {
                return Err(Error::input(
                    &file,
                    format!(
                        "material '{}': reflectance {} outside [0, 1]",
                        m.name, m.rho
                    ),
                ));
            }
            if !m.emission.is_finite() || m.emission.min_element() < 0.0 {
                return Err(Error::input(
                    &file,
                    format!(
                        "material '{}': emission {} must be finite and >= 0",
                        m.name, m.emission
                    ),
                ));
            }
            if m.rho.max_element() > maxr {
                m.rho = m.rho.min(Vec3::splat(maxr));
                clamped.push(m.name.clone());
            }
        }
        if !clamped.is_empty() {
            tracing::warn!(
                "{}: reflectance clamped to {maxr} in materials: {}",
                file.display(),
                clamped.join(", ")
            );
        }
        let nv = raw.positions.len() as u32;
        let nm = materials.len() as u32;
        let no = raw.objects.len().max(1) as u32;
        let mut triangles = Vec::with_capacity(n);
        let mut tri_material = Vec::with_capacity(n);
        let mut tri_object = Vec::with_capacity(n);
        let mut normals = Vec::with_capacity(n);
        let mut areas = Vec::with_capacity(n);
        let mut degenerate = 0usize;
        for i in 0..n {
            let t = raw.triangles[i];
            if let Some(bad) = t.iter().find(|&&v| v >= nv) {
                return Err(Error::input(
                    &file,
                    format!(
                        "triangle {} uses vertex {} but there are {nv} vertices",
                        i + 1,
                        bad + 1
                    ),
                ));
            }
            if raw.tri_material[i] >= nm {
                return Err(Error::input(
                    &file,
                    format!(
                        "triangle {} uses material {} but there are {nm}",
                        i + 1,
                        raw.tri_material[i]
                    ),
                ));
            }
            if raw.tri_object[i] >= no {
                return Err(Error::input(
                    &file,
                    format!("triangle {} uses an unknown object id", i + 1),
                ));
            }
            let [a, b, c] = t.map(|v| raw.positions[v as usize]);
            let cr = (b - a).cross(c - a);
            let area = 0.5 * cr.length();
            if area.is_nan() || area <= 0.0 || !cr.normalize_or_zero().is_normalized() {
                degenerate += 1;
                continue;
            }
            triangles.push(t);
            tri_material.push(raw.tri_material[i]);
            tri_object.push(raw.tri_object[i]);
            normals.push(cr.normalize());
            areas.push(area);
        }
        if triangles.is_empty() {
            return Err(Error::input(
                &file,
                if n == 0 {
                    "the scene has no triangles".to_string()
                } else {
                    format!("the scene has no triangles of non-zero area ({n} degenerate)")
                },
            ));
        }
        let mut bbox = Aabb::EMPTY;
        for t in &triangles {
            for &v in t {
                bbox.grow(raw.positions[v as usize]);
            }
        }
        let objects = if raw.objects.is_empty() {
            vec!["default".to_string()]
        } else {
            raw.objects
        };
        let mut two_sided_materials = raw.two_sided_materials;
        two_sided_materials.resize(materials.len(), false);
        Ok(Scene {
            name: raw.name,
            source: raw.source,
            positions: raw.positions,
            triangles,
            tri_material,
            tri_object,
            objects,
            materials,
            normals,
            areas,
            bbox,
            sun: raw.sun,
            sky: raw.sky,
            cameras: raw.cameras,
            up: raw.up,
            two_sided: raw.two_sided,
            two_sided_materials,
            report: LoadReport {
                degenerate_dropped: degenerate,
                clamped_materials: clamped,
                load_seconds: 0.0,
            },
        })
    }

    /// Number of triangles (surfaces).
    #[inline]
    pub fn num_triangles(&self) -> usize {
        self.triangles.len()
    }

    /// The three corners of triangle `i`.
    #[inline]
    pub fn tri_vertices(&self, i: usize) -> [Vec3; 3] {
        self.triangles[i].map(|v| self.positions[v as usize])
    }

    /// Bounding box of triangle `i`.
    #[inline]
    pub fn tri_bbox(&self, i: usize) -> Aabb {
        let [a, b, c] = self.tri_vertices(i);
        Aabb::new(a.min(b).min(c), a.max(b).max(c))
    }

    /// Centroid of triangle `i`.
    #[inline]
    pub fn tri_centroid(&self, i: usize) -> Vec3 {
        let [a, b, c] = self.tri_vertices(i);
        (a + b + c) / 3.0
    }

    /// Material of triangle `i`.
    #[inline]
    pub fn material_of(&self, i: usize) -> &Material {
        &self.materials[self.tri_material[i] as usize]
    }

    /// Surface area of each object (one entry when the scene names none).
    pub fn object_areas(&self) -> Vec<f64> {
        let mut a = vec![0.0f64; self.objects.len().max(1)];
        for (t, &o) in self.tri_object.iter().enumerate() {
            a[o as usize] += self.areas[t] as f64;
        }
        a
    }

    /// Triangle `i` has a back face in a solve that is two-sided when `two_sided` (the file's
    /// or `--two-sided`), or whose material is ([`Scene::two_sided_materials`]).
    #[inline]
    pub fn has_back(&self, i: usize, two_sided: bool) -> bool {
        two_sided
            || self
                .two_sided_materials
                .get(self.tri_material[i] as usize)
                .copied()
                .unwrap_or(false)
    }

    /// Some triangle has a back face ([`Scene::has_back`]).
    pub fn any_back(&self, two_sided: bool) -> bool {
        two_sided || (0..self.num_triangles()).any(|i| self.has_back(i, false))
    }

    /// Total surface area (f64 sum).
    pub fn total_area(&self) -> f64 {
        self.areas.iter().map(|&a| a as f64).sum()
    }

    /// Indices of emitting triangles.
    pub fn emitters(&self) -> Vec<u32> {
        (0..self.num_triangles() as u32)
            .filter(|&i| self.material_of(i as usize).is_emitter())
            .collect()
    }

    /// Total emitted power Φ = Σ π·L_e·A per channel (f64), surfaces only (not sun or sky).
    pub fn emitted_power(&self) -> glam::DVec3 {
        let mut p = glam::DVec3::ZERO;
        for i in 0..self.num_triangles() {
            let m = self.material_of(i);
            if m.is_emitter() {
                p += m.emission.as_dvec3() * (std::f64::consts::PI * self.areas[i] as f64);
            }
        }
        p
    }

    /// A default viewpoint: the first camera, or one looking at the bounding box.
    pub fn default_camera(&self) -> Camera {
        if let Some(c) = self.cameras.first() {
            return c.clone();
        }
        let up = self.up.vector();
        let c = self.bbox.center();
        let r = self.bbox.extent().length().max(1e-6) * 0.5;
        // Look from a diagonal direction, slightly above.
        let side = if up == Vec3::Z {
            Vec3::new(1.0, -1.4, 0.0)
        } else {
            Vec3::new(1.0, 0.0, 1.4)
        }
        .normalize();
        let eye = c + (side + up * 0.5).normalize() * r * 2.6;
        Camera {
            name: "default".into(),
            eye,
            target: c,
            up,
            fov_deg: 45.0,
            width: 512,
            height: 512,
        }
    }

    /// Load a scene by path (OBJ, glTF/GLB, PLY, MGF, TOML scene file) or by built-in name
    /// (`cornell`, `office`, `soup`, `trees`, `furnace`).
    pub fn load(spec: &str, opts: &SceneOptions) -> Result<Scene> {
        let t0 = std::time::Instant::now();
        let mut scene = load_any(spec, opts)?;
        scene.report.load_seconds = t0.elapsed().as_secs_f64();
        Ok(scene)
    }
}

/// Summary statistics of a scene (what `hirad info` prints).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SceneSummary {
    /// Scene name.
    pub name: String,
    /// File the scene came from.
    pub source: Option<PathBuf>,
    /// Triangles kept.
    pub triangles: usize,
    /// Vertices.
    pub vertices: usize,
    /// Objects.
    pub objects: usize,
    /// Materials.
    pub materials: usize,
    /// Materials with non-zero emission.
    pub emitter_materials: usize,
    /// Triangles with an emitting material.
    pub emitter_triangles: usize,
    /// Zero-area triangles dropped.
    pub degenerate_dropped: usize,
    /// Materials whose reflectance was clamped.
    pub clamped_materials: Vec<String>,
    /// Total surface area (scene units²).
    pub total_area: f64,
    /// Bounding box minimum corner.
    pub bbox_min: Vec3,
    /// Bounding box maximum corner.
    pub bbox_max: Vec3,
    /// Up axis.
    pub up: UpAxis,
    /// The file gives every surface a back face ([`Scene::two_sided`]).
    pub two_sided: bool,
    /// Materials whose surfaces have a back face ([`Scene::two_sided_materials`]).
    pub two_sided_materials: usize,
    /// Emitted power Φ = Σ π·L_e·A per channel (surfaces only).
    pub emitted_power: [f64; 3],
    /// Directional sun, if any.
    pub sun: Option<Sun>,
    /// Uniform sky radiance (RGB), if any.
    pub sky: Option<Vec3>,
    /// Camera names.
    pub cameras: Vec<String>,
    /// Wall time of loading, seconds.
    pub load_seconds: f64,
}

impl Scene {
    /// Counts, area, bounding box, emitters and load report of the scene.
    pub fn summary(&self) -> SceneSummary {
        let emitter_materials = self.materials.iter().filter(|m| m.is_emitter()).count();
        SceneSummary {
            name: self.name.clone(),
            source: self.source.clone(),
            triangles: self.num_triangles(),
            vertices: self.positions.len(),
            objects: self.objects.len(),
            materials: self.materials.len(),
            emitter_materials,
            emitter_triangles: self.emitters().len(),
            degenerate_dropped: self.report.degenerate_dropped,
            clamped_materials: self.report.clamped_materials.clone(),
            total_area: self.total_area(),
            bbox_min: self.bbox.min,
            bbox_max: self.bbox.max,
            up: self.up,
            two_sided: self.two_sided,
            two_sided_materials: self.two_sided_materials.iter().filter(|&&t| t).count(),
            emitted_power: self.emitted_power().to_array(),
            sun: self.sun,
            sky: self.sky,
            cameras: self.cameras.iter().map(|c| c.name.clone()).collect(),
            load_seconds: self.report.load_seconds,
        }
    }
}

fn load_any(spec: &str, opts: &SceneOptions) -> Result<Scene> {
    let path = Path::new(spec);
    // A directory is never a scene: a built-in name wins over a directory of that name.
    if !path.exists() || (path.is_dir() && builtin::is_name(spec)) {
        if let Some(raw) = builtin::generate(spec)? {
            let mut raw = raw;
            if let Some(up) = opts.up {
                raw.up = up;
            }
            return Scene::from_raw(raw, opts);
        }
        if !spec.contains(['/', '.']) {
            return Err(Error::Config(format!(
                "'{spec}' is neither a file nor a built-in scene (built-in scenes: {})",
                builtin::NAMES.join(", ")
            )));
        }
        return Err(Error::io(
            path,
            std::io::Error::new(std::io::ErrorKind::NotFound, "no such file"),
        ));
    }
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .unwrap_or("")
        .to_ascii_lowercase();
    let mut raw = match ext.as_str() {
        "obj" => obj::load(path)?,
        "gltf" | "glb" => gltf_io::load(path)?,
        "ply" => ply::load(path)?,
        "mgf" => mgf::load_with(path, opts.mgf_divisions)?.raw,
        "toml" => return desc::load(path, opts),
        _ => {
            return Err(Error::input(
                path,
                "unknown file type (expected .obj, .gltf, .glb, .ply, .mgf or .toml)",
            ))
        }
    };
    if let Some(up) = opts.up {
        raw.up = up;
    }
    Scene::from_raw(raw, opts)
}

pub mod builtin;
pub mod desc;
pub mod export;
pub mod gltf_io;
pub mod mgf;
pub mod obj;
pub mod ply;

#[cfg(test)]
mod tests {
    use super::*;

    fn quad_raw() -> RawScene {
        RawScene {
            name: "t".into(),
            positions: vec![
                Vec3::ZERO,
                Vec3::X,
                Vec3::new(1.0, 1.0, 0.0),
                Vec3::Y,
                Vec3::new(2.0, 0.0, 0.0),
            ],
            triangles: vec![[0, 1, 2], [0, 2, 3], [0, 1, 4]],
            tri_material: vec![0, 0, 0],
            tri_object: vec![0, 0, 0],
            materials: vec![Material::diffuse("m", Vec3::splat(0.5))],
            ..Default::default()
        }
    }

    #[test]
    fn builds_and_drops_degenerate() {
        let s = Scene::from_raw(quad_raw(), &SceneOptions::default()).unwrap();
        assert_eq!(s.num_triangles(), 2);
        assert_eq!(s.report.degenerate_dropped, 1);
        assert!((s.total_area() - 1.0).abs() < 1e-6);
        assert_eq!(s.normals[0], Vec3::Z);
    }

    #[test]
    fn rejects_bad_input() {
        let mut r = quad_raw();
        r.positions[1].x = f32::NAN;
        assert!(Scene::from_raw(r, &SceneOptions::default()).is_err());
        let mut r = quad_raw();
        r.triangles[0][2] = 99;
        let e = Scene::from_raw(r, &SceneOptions::default()).unwrap_err();
        assert!(e.to_string().contains("vertex 100"), "{e}");
        let mut r = quad_raw();
        r.materials[0].rho.y = 1.2;
        assert!(Scene::from_raw(r, &SceneOptions::default()).is_err());
        let mut r = quad_raw();
        r.triangles.clear();
        r.tri_material.clear();
        r.tri_object.clear();
        assert!(Scene::from_raw(r, &SceneOptions::default()).is_err());
    }

    #[test]
    fn clamps_rho_one() {
        let mut r = quad_raw();
        r.materials[0].rho = Vec3::new(1.0, 0.5, 0.2);
        let s = Scene::from_raw(r, &SceneOptions::default()).unwrap();
        assert_eq!(s.materials[0].rho.x, 0.95);
        assert_eq!(s.report.clamped_materials, vec!["m".to_string()]);
    }
}
