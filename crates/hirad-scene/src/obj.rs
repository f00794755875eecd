//! Wavefront OBJ + MTL loader.
//!
//! The common subset (`v`, `f` with `v`, `v/t`, `v//n`, `v/t/n` corners and negative indices,
//! `o`, `g`, `usemtl`, `mtllib`, plus ignored `vn`, `vt`, `vp`, `s`, `mg`, `lod`, comments) is
//! read by a fast single-pass byte parser that knows the line of every statement, so every error
//! names the file and line. A file using anything else (line continuations, curves, ...) is
//! handed to `tobj` (triangulation on), guarded by `catch_unwind`; when `tobj` fails, a
//! line-by-line diagnostic scan finds the offending line.
//!
//! Mapping: polygons are fan-triangulated; every distinct `o`/`g` name is one object
//! (`tri_object`); MTL `Kd` is the reflectance ρ and `Ke` the emitted radiance L_e. Faces before
//! any `usemtl` get a grey `default` material (ρ = 0.5). The up axis is read from a leading
//! comment such as `# Units: metres, +Z up.` (default +Y).

use super::{Material, RawScene, UpAxis};
use glam::Vec3;
use hirad_core::{Error, Result};
use std::collections::HashMap;
use std::path::{Path, PathBuf};

/// Reflectance of the material used by faces that have no `usemtl`.
const DEFAULT_RHO: f32 = 0.5;

/// Load an OBJ file (and its MTL libraries) into raw scene data.
pub fn load(path: &Path) -> Result<RawScene> {
    let bytes = hirad_core::io::read_input(path)?;
    match parse(path, &bytes, true)? {
        Some(raw) => Ok(raw),
        None => {
            tracing::debug!(
                "{}: statements outside the fast subset, loading with tobj",
                path.display()
            );
            load_with_tobj(path)
        }
    }
}

/// Load an OBJ file through the `tobj` crate only (the fallback of [`load`], also used to
/// cross-check the fast parser). Panics inside `tobj` become [`Error::Input`].
pub fn load_with_tobj(path: &Path) -> Result<RawScene> {
    let bytes = hirad_core::io::read_input(path)?;
    let dir = path.parent().map(Path::to_path_buf).unwrap_or_default();
    let opts = tobj::LoadOptions {
        triangulate: true,
        single_index: false,
        ignore_points: true,
        ignore_lines: true,
    };
    let result = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        tobj::load_obj_buf(&mut &bytes[..], &opts, |p| {
            // tobj opens the library itself: only regular files (not /dev/zero, FIFOs).
            let f = dir.join(p);
            if !f.is_file() {
                return Err(tobj::LoadError::OpenFileFailed);
            }
            tobj::load_mtl(f)
        })
    }));
    let (models, materials) = match result {
        Ok(Ok(r)) => r,
        Ok(Err(e)) => return Err(diagnose(path, &bytes, &format!("tobj: {e}"))),
        Err(_) => return Err(diagnose(path, &bytes, "tobj panicked on this file")),
    };
    let uses_materials = models.iter().any(|m| m.mesh.material_id.is_some());
    let tmats = match materials {
        Ok(m) => m,
        Err(e) => {
            if uses_materials || bytes_contain_mtllib(&bytes) {
                return Err(diagnose(path, &bytes, &format!("material library: {e}")));
            }
            Vec::new()
        }
    };
    let mut raw = new_raw(path, &bytes);
    for m in &tmats {
        let rho = m
            .diffuse
            .map(Vec3::from)
            .unwrap_or(Vec3::splat(DEFAULT_RHO));
        // tobj 4 reads `Ke` into `emissive`; older versions left it in `unknown_param`.
        let emission = match (m.emissive, m.unknown_param.get("Ke")) {
            (Some(e), _) => Vec3::from(e),
            (None, Some(s)) => parse_rgb_str(s).ok_or_else(|| {
                Error::input(path, format!("material '{}': bad Ke '{s}'", m.name))
            })?,
            (None, None) => Vec3::ZERO,
        };
        raw.materials.push(Material {
            name: m.name.clone(),
            rho,
            emission,
        });
    }
    let mut default_mat: Option<u32> = None;
    let mut object_ids: HashMap<String, u32> = HashMap::new();
    for model in &models {
        let mesh = &model.mesh;
        let obj = *object_ids.entry(model.name.clone()).or_insert_with(|| {
            raw.objects.push(model.name.clone());
            raw.objects.len() as u32 - 1
        });
        let mat = match mesh.material_id {
            Some(id) if id < raw.materials.len() => id as u32,
            _ => *default_mat.get_or_insert_with(|| push_default_material(&mut raw.materials)),
        };
        let base = raw.positions.len() as u32;
        raw.positions.extend(
            mesh.positions
                .chunks_exact(3)
                .map(|c| Vec3::new(c[0], c[1], c[2])),
        );
        for t in mesh.indices.chunks_exact(3) {
            raw.triangles.push([base + t[0], base + t[1], base + t[2]]);
            raw.tri_material.push(mat);
            raw.tri_object.push(obj);
        }
    }
    Ok(raw)
}

fn bytes_contain_mtllib(bytes: &[u8]) -> bool {
    bytes.windows(7).any(|w| w == b"mtllib ")
}

/// Find the offending line of a file `tobj` rejected: run the strict fast parser over it and
/// report its first error; otherwise report `fallback` for the whole file.
fn diagnose(path: &Path, bytes: &[u8], fallback: &str) -> Error {
    match parse(path, bytes, false) {
        Err(e) => e,
        Ok(_) => Error::input(path, fallback.to_string()),
    }
}

fn new_raw(path: &Path, bytes: &[u8]) -> RawScene {
    RawScene {
        name: path
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| "scene".into()),
        source: Some(path.to_path_buf()),
        up: header_up_axis(bytes).unwrap_or_default(),
        ..Default::default()
    }
}

fn push_default_material(materials: &mut Vec<Material>) -> u32 {
    materials.push(Material::diffuse("default", Vec3::splat(DEFAULT_RHO)));
    materials.len() as u32 - 1
}

/// Up axis stated in the leading comment block (`+Z up`, `Z-up`, `z up`), if any.
pub fn header_up_axis(bytes: &[u8]) -> Option<UpAxis> {
    for line in bytes.split(|&b| b == b'\n').take(200) {
        let line = trim(line);
        if line.is_empty() {
            continue;
        }
        if line[0] != b'#' {
            break;
        }
        let s = String::from_utf8_lossy(line).to_ascii_lowercase();
        for (axis, up) in [('z', UpAxis::Z), ('y', UpAxis::Y)] {
            for pat in [
                format!("+{axis} up"),
                format!("{axis}-up"),
                format!("{axis} up"),
            ] {
                if s.contains(&pat) {
                    return Some(up);
                }
            }
        }
    }
    None
}

#[inline]
fn is_space(b: u8) -> bool {
    b == b' ' || b == b'\t' || b == b'\r' || b == b'\x0c' || b == b'\x0b'
}

#[inline]
/// The non-empty lines of an OBJ or MTL file with their 1-based numbers, comments (`#` to the
/// end of the line) removed and surrounding white space trimmed.
fn content_lines(bytes: &[u8]) -> impl Iterator<Item = (usize, &[u8])> {
    bytes
        .split(|&b| b == b'\n')
        .enumerate()
        .filter_map(|(li, line)| {
            let line = match line.iter().position(|&b| b == b'#') {
                Some(h) => &line[..h],
                None => line,
            };
            let line = trim(line);
            (!line.is_empty()).then_some((li + 1, line))
        })
}

fn trim(mut s: &[u8]) -> &[u8] {
    while let [first, rest @ ..] = s {
        if is_space(*first) {
            s = rest;
        } else {
            break;
        }
    }
    while let [rest @ .., last] = s {
        if is_space(*last) {
            s = rest;
        } else {
            break;
        }
    }
    s
}

/// Whitespace-separated tokens of a line.
#[inline]
fn tokens(s: &[u8]) -> impl Iterator<Item = &[u8]> {
    s.split(|&b| is_space(b)).filter(|t| !t.is_empty())
}

#[inline]
fn parse_f32(tok: &[u8]) -> Option<f32> {
    std::str::from_utf8(tok).ok()?.parse::<f32>().ok()
}

#[inline]
fn parse_i64(tok: &[u8]) -> Option<i64> {
    let (neg, digits) = match tok.first()? {
        b'-' => (true, &tok[1..]),
        b'+' => (false, &tok[1..]),
        _ => (false, tok),
    };
    if digits.is_empty() || digits.len() > 18 {
        return None;
    }
    let mut v: i64 = 0;
    for &d in digits {
        if !d.is_ascii_digit() {
            return None;
        }
        v = v * 10 + (d - b'0') as i64;
    }
    Some(if neg { -v } else { v })
}

fn parse_rgb_str(s: &str) -> Option<Vec3> {
    let v: Vec<f32> = s
        .split_ascii_whitespace()
        .map(|t| t.parse::<f32>().ok())
        .collect::<Option<Vec<_>>>()?;
    match v.as_slice() {
        [g] => Some(Vec3::splat(*g)),
        [r, g, b, ..] => Some(Vec3::new(*r, *g, *b)),
        _ => None,
    }
}

fn lossy(s: &[u8]) -> String {
    String::from_utf8_lossy(s).into_owned()
}

/// The fast parser. Returns `Ok(None)` when `allow_fallback` is set and the file uses a statement
/// outside the supported subset; with `allow_fallback` off such statements are skipped (the
/// diagnostic mode used after `tobj` failed).
fn parse(path: &Path, bytes: &[u8], allow_fallback: bool) -> Result<Option<RawScene>> {
    // A UTF-8 byte order mark is not part of the first statement.
    let bytes = bytes.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(bytes);
    let mut raw = new_raw(path, bytes);
    let dir = path.parent().map(Path::to_path_buf).unwrap_or_default();
    // Rough pre-sizing: a typical line is ~30 bytes.
    let guess = bytes.len() / 40;
    raw.positions.reserve(guess / 2);
    raw.triangles.reserve(guess);
    raw.tri_material.reserve(guess);
    raw.tri_object.reserve(guess);

    let mut mat_ids: HashMap<String, u32> = HashMap::new();
    let mut libraries: Vec<PathBuf> = Vec::new();
    let mut obj_ids: HashMap<Vec<u8>, u32> = HashMap::new();
    let mut cur_mat: Option<u32> = None;
    let mut cur_obj: Option<u32> = None;
    let mut default_mat: Option<u32> = None;
    // Largest positive index that referred to a vertex not yet defined, with its line.
    let mut forward: Option<(u64, usize)> = None;
    let mut corners: Vec<u32> = Vec::with_capacity(8);

    for (line_no, line) in content_lines(bytes) {
        if line.last() == Some(&b'\\') {
            if allow_fallback {
                return Ok(None);
            }
            continue;
        }
        let split = line.iter().position(|&b| is_space(b)).unwrap_or(line.len());
        let (kw, rest) = (&line[..split], trim(&line[split..]));
        match kw {
            b"v" => {
                let mut it = tokens(rest);
                let mut c = [0f32; 3];
                for (k, slot) in c.iter_mut().enumerate() {
                    let tok = it.next().ok_or_else(|| {
                        Error::input_at(
                            path,
                            line_no,
                            format!("vertex has {k} coordinates, expected 3"),
                        )
                    })?;
                    *slot = parse_f32(tok).ok_or_else(|| {
                        Error::input_at(
                            path,
                            line_no,
                            format!("vertex coordinate '{}' is not a number", lossy(tok)),
                        )
                    })?;
                    if !slot.is_finite() {
                        return Err(Error::input_at(
                            path,
                            line_no,
                            format!("vertex coordinate '{}' is not finite", lossy(tok)),
                        ));
                    }
                }
                raw.positions.push(Vec3::from_array(c));
            }
            b"f" => {
                corners.clear();
                let nv = raw.positions.len() as i64;
                for tok in tokens(rest) {
                    let vtok = match tok.iter().position(|&b| b == b'/') {
                        Some(p) => &tok[..p],
                        None => tok,
                    };
                    let idx = parse_i64(vtok).ok_or_else(|| {
                        Error::input_at(
                            path,
                            line_no,
                            format!("face vertex '{}' is not an index", lossy(tok)),
                        )
                    })?;
                    let v = if idx > 0 {
                        if idx > u32::MAX as i64 {
                            return Err(Error::input_at(
                                path,
                                line_no,
                                format!("face uses vertex {idx}, which is out of range"),
                            ));
                        }
                        if idx > nv && forward.is_none_or(|(m, _)| idx as u64 > m) {
                            forward = Some((idx as u64, line_no));
                        }
                        idx - 1
                    } else if idx < 0 {
                        let v = nv + idx;
                        if v < 0 {
                            return Err(Error::input_at(
                                path,
                                line_no,
                                format!(
                                    "face uses relative vertex {idx} but only {nv} vertices \
                                     are defined so far"
                                ),
                            ));
                        }
                        v
                    } else {
                        return Err(Error::input_at(
                            path,
                            line_no,
                            "face uses vertex index 0 (OBJ indices start at 1)",
                        ));
                    };
                    corners.push(v as u32);
                }
                if corners.len() < 3 {
                    return Err(Error::input_at(
                        path,
                        line_no,
                        format!("face has {} vertices, expected at least 3", corners.len()),
                    ));
                }
                let mat = match cur_mat {
                    Some(m) => m,
                    None => *default_mat
                        .get_or_insert_with(|| push_default_material(&mut raw.materials)),
                };
                let obj = match cur_obj {
                    Some(o) => o,
                    None => {
                        let o = intern_object(&mut raw.objects, &mut obj_ids, b"default");
                        cur_obj = Some(o);
                        o
                    }
                };
                for k in 1..corners.len() - 1 {
                    raw.triangles.push([corners[0], corners[k], corners[k + 1]]);
                    raw.tri_material.push(mat);
                    raw.tri_object.push(obj);
                }
            }
            b"o" | b"g" => {
                let name: &[u8] = if rest.is_empty() { b"default" } else { rest };
                cur_obj = Some(intern_object(&mut raw.objects, &mut obj_ids, name));
            }
            b"usemtl" => {
                let name = lossy(rest);
                match mat_ids.get(&name) {
                    Some(&m) => cur_mat = Some(m),
                    None => {
                        return Err(Error::input_at(
                            path,
                            line_no,
                            if libraries.is_empty() {
                                format!("material '{name}' used but no mtllib was given before")
                            } else {
                                format!(
                                    "material '{name}' is not defined in {}",
                                    libraries
                                        .iter()
                                        .map(|p| p.display().to_string())
                                        .collect::<Vec<_>>()
                                        .join(", ")
                                )
                            },
                        ))
                    }
                }
            }
            b"mtllib" => {
                let rest_s = lossy(rest);
                // A single name may contain spaces; otherwise the line lists several files.
                let whole = dir.join(&rest_s);
                let files: Vec<PathBuf> = if whole.is_file() {
                    vec![whole]
                } else {
                    rest_s
                        .split_ascii_whitespace()
                        .map(|f| dir.join(f))
                        .collect()
                };
                if files.is_empty() {
                    return Err(Error::input_at(path, line_no, "mtllib without a file name"));
                }
                for f in files {
                    if !f.is_file() {
                        return Err(Error::input_at(
                            path,
                            line_no,
                            format!("material library {} not found", f.display()),
                        ));
                    }
                    for m in parse_mtl(&f)? {
                        if mat_ids.contains_key(&m.name) {
                            tracing::warn!(
                                "{}: material '{}' defined again, keeping the first",
                                f.display(),
                                m.name
                            );
                            continue;
                        }
                        mat_ids.insert(m.name.clone(), raw.materials.len() as u32);
                        raw.materials.push(m);
                    }
                    libraries.push(f);
                }
            }
            b"vn" | b"vt" | b"vp" | b"s" | b"mg" | b"lod" | b"shadow_obj" | b"trace_obj"
            | b"usemap" | b"maplib" | b"l" | b"p" => {}
            _ => {
                if allow_fallback {
                    return Ok(None);
                }
            }
        }
    }
    if let Some((idx, line)) = forward {
        let nv = raw.positions.len() as u64;
        if idx > nv {
            return Err(Error::input_at(
                path,
                line,
                format!("face uses vertex {idx} but the file defines {nv} vertices"),
            ));
        }
    }
    Ok(Some(raw))
}

fn intern_object(objects: &mut Vec<String>, ids: &mut HashMap<Vec<u8>, u32>, name: &[u8]) -> u32 {
    if let Some(&o) = ids.get(name) {
        return o;
    }
    let o = objects.len() as u32;
    objects.push(lossy(name));
    ids.insert(name.to_vec(), o);
    o
}

/// Parse an MTL file: `newmtl`, `Kd` (ρ) and `Ke` (L_e); other statements are ignored. Errors
/// name the MTL file and line: unparsable colours, ρ outside [0, 1], negative or non-finite Ke.
pub fn parse_mtl(path: &Path) -> Result<Vec<Material>> {
    let bytes = hirad_core::io::read_input(path)?;
    let mut out: Vec<Material> = Vec::new();
    for (line_no, line) in content_lines(&bytes) {
        let split = line.iter().position(|&b| is_space(b)).unwrap_or(line.len());
        let (kw, rest) = (&line[..split], trim(&line[split..]));
        match kw {
            b"newmtl" => {
                if rest.is_empty() {
                    return Err(Error::input_at(path, line_no, "newmtl without a name"));
                }
                out.push(Material {
                    name: lossy(rest),
                    rho: Vec3::splat(DEFAULT_RHO),
                    emission: Vec3::ZERO,
                });
            }
            b"Kd" | b"Ke" => {
                let key = lossy(kw);
                let Some(m) = out.last_mut() else {
                    return Err(Error::input_at(
                        path,
                        line_no,
                        format!("{key} before any newmtl"),
                    ));
                };
                let c = parse_rgb_str(&lossy(rest)).ok_or_else(|| {
                    Error::input_at(
                        path,
                        line_no,
                        format!(
                            "material '{}': {key} '{}' is not an RGB colour",
                            m.name,
                            lossy(rest)
                        ),
                    )
                })?;
                if kw == b"Kd" {
                    if !c.is_finite() || c.min_element() < 0.0 || c.max_element() > 1.0 {
                        return Err(Error::input_at(
                            path,
                            line_no,
                            format!("material '{}': reflectance Kd {c} outside [0, 1]", m.name),
                        ));
                    }
                    m.rho = c;
                } else {
                    if !c.is_finite() || c.min_element() < 0.0 {
                        return Err(Error::input_at(
                            path,
                            line_no,
                            format!(
                                "material '{}': emission Ke {c} must be finite and >= 0",
                                m.name
                            ),
                        ));
                    }
                    m.emission = c;
                }
            }
            _ => {}
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
        let p = dir.join(name);
        std::fs::write(&p, text).unwrap();
        p
    }

    #[test]
    fn parses_subset_with_fans_groups_and_materials() {
        let d = tempfile::tempdir().unwrap();
        write(
            d.path(),
            "m.mtl",
            "newmtl red\nKd 0.8 0.1 0.1\nnewmtl lamp\nKd 0 0 0\nKe 2 3 4\n",
        );
        let p = write(
            d.path(),
            "s.obj",
            "# test, +Z up\nmtllib m.mtl\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n\
             o quad\nusemtl red\nf 1/1/1 2/2/2 3/3/3 4/4/4\ng lamp\nusemtl lamp\nf -4//1 -3//1 -2//1\n",
        );
        let raw = load(&p).unwrap();
        assert_eq!(raw.up, UpAxis::Z);
        assert_eq!(raw.positions.len(), 4);
        assert_eq!(raw.triangles, vec![[0, 1, 2], [0, 2, 3], [0, 1, 2]]);
        assert_eq!(raw.tri_material, vec![0, 0, 1]);
        assert_eq!(raw.tri_object, vec![0, 0, 1]);
        assert_eq!(raw.objects, vec!["quad".to_string(), "lamp".to_string()]);
        assert_eq!(raw.materials[1].emission, Vec3::new(2.0, 3.0, 4.0));
        assert_eq!(raw.materials[0].rho, Vec3::new(0.8, 0.1, 0.1));
        // tobj agrees on triangles, materials and emission.
        let t = load_with_tobj(&p).unwrap();
        assert_eq!(t.triangles.len(), 3);
        assert_eq!(t.materials, raw.materials);
        assert_eq!(t.tri_material, raw.tri_material);
    }

    #[test]
    fn errors_name_line() {
        let d = tempfile::tempdir().unwrap();
        let p = write(d.path(), "a.obj", "v 0 0 0\nv 1 0 0\nv 1 nan 0\nf 1 2 3\n");
        let e = load(&p).unwrap_err().to_string();
        assert!(e.contains("a.obj:3:"), "{e}");
        let p = write(
            d.path(),
            "b.obj",
            "v 0 0 0\nv 1 0 0\nv 1 1 0\nf 1 2 3\nf 1 2 9\n",
        );
        let e = load(&p).unwrap_err().to_string();
        assert!(e.contains("b.obj:5:") && e.contains("vertex 9"), "{e}");
    }

    #[test]
    fn byte_order_mark_and_crlf() {
        let d = tempfile::tempdir().unwrap();
        let p = write(
            d.path(),
            "bom.obj",
            "\u{feff}v 0 0 0\r\nv 1 0 0\r\nv 0 1 0\r\nf 1 2 3\r\n",
        );
        let raw = parse(&p, &std::fs::read(&p).unwrap(), true)
            .unwrap()
            .unwrap();
        assert_eq!(raw.positions[1], Vec3::X);
        assert_eq!(raw.triangles, vec![[0, 1, 2]]);
    }

    #[test]
    fn unusual_statement_falls_back_to_tobj() {
        let d = tempfile::tempdir().unwrap();
        let p = write(
            d.path(),
            "c.obj",
            "v 0 0 0\nv 1 0 0\nv 1 1 0\ncstype bezier\nf 1 2 3\n",
        );
        let raw = load(&p).unwrap();
        assert_eq!(raw.triangles.len(), 1);
        assert_eq!(raw.materials[0].name, "default");
    }
}
