//! glTF 2.0 loader (`.gltf` with external or embedded buffers, `.glb`).
//!
//! The whole scene graph of the default scene (or the first scene, or every root node when the
//! file has no scene) is walked with node transforms composed; a node with a negative-determinant
//! transform has its triangles' winding reversed so they keep facing the transformed normal.
//! Primitives in `TRIANGLES`, `TRIANGLE_STRIP` and `TRIANGLE_FAN` mode are read, indexed or not;
//! other modes (points, lines) are skipped. Materials: ρ = RGB of `baseColorFactor`,
//! L_e = `emissiveFactor` × `KHR_materials_emissive_strength` (1 when absent); primitives without
//! a material get the glTF default material (white, so ρ is clamped). One object per mesh
//! instance (node). glTF is +Y up. The `gltf` crate can panic on malformed files: every call is
//! guarded by `catch_unwind`, and the node walk is depth-limited against cycles.

use super::{Material, RawScene, UpAxis};
use glam::{Mat4, Vec3};
use hirad_core::{Error, Result};
use std::collections::HashMap;
use std::path::Path;

/// Deepest node nesting followed (guards against cyclic node graphs).
const MAX_DEPTH: usize = 128;

/// Load a glTF 2.0 file into raw scene data.
pub fn load(path: &Path) -> Result<RawScene> {
    let bytes = hirad_core::io::read_input(path)?;
    let base = path.parent().map(Path::to_path_buf);
    match std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        load_bytes(path, &bytes, base.as_deref())
    })) {
        Ok(r) => r,
        Err(_) => Err(Error::input(
            path,
            "malformed glTF (the glTF reader panicked)",
        )),
    }
}

fn gltf_err(path: &Path, e: gltf::Error) -> Error {
    let line = match &e {
        gltf::Error::Deserialize(d) => Some(d.line()),
        _ => None,
    };
    match line {
        Some(l) if l > 0 => Error::input_at(path, l, format!("malformed glTF: {e}")),
        _ => Error::input(path, format!("malformed glTF: {e}")),
    }
}

/// External buffers must be regular files: the `gltf` crate reads them whole, and a `uri` such as
/// `/dev/zero` would never end. URIs are resolved as `gltf::import_buffers` resolves them.
pub(crate) fn check_buffer_files(
    path: &Path,
    doc: &gltf::Document,
    base: Option<&Path>,
) -> Result<()> {
    let Some(base) = base else { return Ok(()) };
    for b in doc.buffers() {
        let gltf::buffer::Source::Uri(uri) = b.source() else {
            continue;
        };
        let file = if let Some(f) = uri.strip_prefix("file://").or(uri.strip_prefix("file:")) {
            std::path::PathBuf::from(f)
        } else if uri.contains(':') {
            continue; // data URI, or a scheme the reader refuses
        } else {
            base.join(percent_decode(uri))
        };
        if !file.is_file() {
            return Err(Error::input(
                path,
                format!(
                    "buffer {}: {} is not a regular file",
                    b.index(),
                    file.display()
                ),
            ));
        }
    }
    Ok(())
}

/// `%XX` escapes decoded (invalid UTF-8 replaced).
fn percent_decode(s: &str) -> String {
    let b = s.as_bytes();
    let mut out = Vec::with_capacity(b.len());
    let mut i = 0;
    while i < b.len() {
        let hex = b
            .get(i + 1..i + 3)
            .and_then(|h| std::str::from_utf8(h).ok());
        match (b[i], hex.and_then(|h| u8::from_str_radix(h, 16).ok())) {
            (b'%', Some(v)) => {
                out.push(v);
                i += 3;
            }
            (c, _) => {
                out.push(c);
                i += 1;
            }
        }
    }
    String::from_utf8_lossy(&out).into_owned()
}

fn load_bytes(path: &Path, bytes: &[u8], base: Option<&Path>) -> Result<RawScene> {
    let gltf::Gltf { document, blob } =
        gltf::Gltf::from_slice(bytes).map_err(|e| gltf_err(path, e))?;
    check_buffer_files(path, &document, base)?;
    let buffers = gltf::import_buffers(&document, base, blob).map_err(|e| gltf_err(path, e))?;
    let mut raw = RawScene {
        name: path
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| "scene".into()),
        source: Some(path.to_path_buf()),
        up: UpAxis::Y,
        ..Default::default()
    };
    for m in document.materials() {
        let pbr = m.pbr_metallic_roughness();
        let [r, g, b, _] = pbr.base_color_factor();
        let strength = m.emissive_strength().unwrap_or(1.0);
        raw.materials.push(Material {
            name: m
                .name()
                .map(str::to_string)
                .unwrap_or_else(|| format!("material{}", m.index().unwrap_or(0))),
            rho: Vec3::new(r, g, b),
            emission: Vec3::from(m.emissive_factor()) * strength,
        });
    }
    let mut walker = Walker {
        path,
        buffers: &buffers,
        raw,
        default_mat: None,
        cache: HashMap::new(),
    };
    let roots: Vec<gltf::Node> = match document.default_scene().or(document.scenes().next()) {
        Some(s) => s.nodes().collect(),
        None => {
            let mut is_child = vec![false; document.nodes().len()];
            for n in document.nodes() {
                for c in n.children() {
                    is_child[c.index()] = true;
                }
            }
            document.nodes().filter(|n| !is_child[n.index()]).collect()
        }
    };
    for n in roots {
        walker.node(&n, Mat4::IDENTITY, 0)?;
    }
    Ok(walker.raw)
}

struct Walker<'a> {
    path: &'a Path,
    buffers: &'a [gltf::buffer::Data],
    raw: RawScene,
    default_mat: Option<u32>,
    /// First vertex of (position accessor, node) already appended.
    cache: HashMap<(usize, usize), (u32, u32)>,
}

impl Walker<'_> {
    fn node(&mut self, node: &gltf::Node, parent: Mat4, depth: usize) -> Result<()> {
        if depth > MAX_DEPTH {
            return Err(Error::input(
                self.path,
                format!("node graph deeper than {MAX_DEPTH} levels (a cycle?)"),
            ));
        }
        let local = Mat4::from_cols_array_2d(&node.transform().matrix());
        let world = parent * local;
        if let Some(mesh) = node.mesh() {
            let name = node
                .name()
                .or(mesh.name())
                .map(str::to_string)
                .unwrap_or_else(|| format!("node{}", node.index()));
            self.raw.objects.push(name);
            let obj = self.raw.objects.len() as u32 - 1;
            for prim in mesh.primitives() {
                self.primitive(&prim, node.index(), world, obj)?;
            }
        }
        for c in node.children() {
            self.node(&c, world, depth + 1)?;
        }
        Ok(())
    }

    fn primitive(
        &mut self,
        prim: &gltf::Primitive,
        node: usize,
        world: Mat4,
        obj: u32,
    ) -> Result<()> {
        use gltf::mesh::Mode;
        let mode = prim.mode();
        if !matches!(
            mode,
            Mode::Triangles | Mode::TriangleStrip | Mode::TriangleFan
        ) {
            return Ok(());
        }
        let buffers = self.buffers;
        let reader = prim.reader(|b| buffers.get(b.index()).map(|d| &d.0[..]));
        let Some(pos_acc) = prim.get(&gltf::Semantic::Positions) else {
            return Err(Error::input(
                self.path,
                format!("mesh primitive of node {node} has no POSITION attribute"),
            ));
        };
        let (base, count) = match self.cache.get(&(pos_acc.index(), node)) {
            Some(&v) => v,
            None => {
                let positions = reader.read_positions().ok_or_else(|| {
                    Error::input(self.path, format!("node {node}: unreadable POSITION data"))
                })?;
                let base = self.raw.positions.len() as u32;
                self.raw
                    .positions
                    .extend(positions.map(|p| world.transform_point3(Vec3::from(p))));
                let count = self.raw.positions.len() as u32 - base;
                self.cache.insert((pos_acc.index(), node), (base, count));
                (base, count)
            }
        };
        let idx: Vec<u32> = match reader.read_indices() {
            Some(i) => i.into_u32().collect(),
            None => (0..count).collect(),
        };
        if let Some(&bad) = idx.iter().find(|&&i| i >= count) {
            return Err(Error::input(
                self.path,
                format!("node {node}: index {bad} out of range ({count} vertices)"),
            ));
        }
        let mut tris: Vec<[u32; 3]> = Vec::new();
        match mode {
            Mode::Triangles => {
                tris.extend(idx.chunks_exact(3).map(|t| [t[0], t[1], t[2]]));
            }
            Mode::TriangleStrip => {
                for k in 2..idx.len() {
                    tris.push(if k % 2 == 0 {
                        [idx[k - 2], idx[k - 1], idx[k]]
                    } else {
                        [idx[k - 1], idx[k - 2], idx[k]]
                    });
                }
            }
            _ => {
                for k in 2..idx.len() {
                    tris.push([idx[0], idx[k - 1], idx[k]]);
                }
            }
        }
        let flip = world.determinant() < 0.0;
        let mat = match prim.material().index() {
            Some(m) if m < self.raw.materials.len() => m as u32,
            _ => *self.default_mat.get_or_insert_with(|| {
                self.raw
                    .materials
                    .push(Material::diffuse("default", Vec3::ONE));
                self.raw.materials.len() as u32 - 1
            }),
        };
        for t in tris {
            let t = if flip { [t[0], t[2], t[1]] } else { t };
            self.raw.triangles.push(t.map(|i| base + i));
            self.raw.tri_material.push(mat);
            self.raw.tri_object.push(obj);
        }
        Ok(())
    }
}
