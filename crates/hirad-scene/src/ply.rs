//! PLY loader (ASCII, binary little- and big-endian), a hand parser: it never panics, reports the
//! line of ASCII errors and the element/record of binary ones, and reads any property layout.
//!
//! Vertices need `x`, `y`, `z`; faces are a list property named `vertex_indices` or
//! `vertex_index` and are fan-triangulated. Optional vertex colours (`red`/`green`/`blue`, uchar
//! scaled to [0, 1] or float as stored, and the linear `radiosity_r/g/b` floats written by
//! [`super::export`]) are read into [`PlyMesh`] but do not make materials: a scene loaded from
//! PLY has one grey `default` material (ρ = 0.5) and one object. The up axis is read from a
//! `comment` such as `comment +Z up` (default +Y).

use super::{Material, RawScene, UpAxis};
use glam::Vec3;
use hirad_core::{Error, Result};
use std::path::Path;

/// Triangles and per-vertex data read from a PLY file.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PlyMesh {
    /// Vertex positions.
    pub positions: Vec<Vec3>,
    /// Vertex indices per triangle (polygons fan-triangulated).
    pub triangles: Vec<[u32; 3]>,
    /// `red`/`green`/`blue` per vertex: uchar/255 or float as stored (display colours).
    pub colors: Option<Vec<Vec3>>,
    /// `radiosity_r/g/b` per vertex (linear floats written by the exporter).
    pub linear_colors: Option<Vec<Vec3>>,
    /// Up axis stated in a `comment` line, if any.
    pub up: Option<UpAxis>,
}

/// Load a PLY file into raw scene data.
pub fn load(path: &Path) -> Result<RawScene> {
    let m = read(path)?;
    let n = m.triangles.len();
    Ok(RawScene {
        name: path
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| "scene".into()),
        source: Some(path.to_path_buf()),
        positions: m.positions,
        triangles: m.triangles,
        tri_material: vec![0; n],
        tri_object: vec![0; n],
        objects: vec!["default".into()],
        materials: vec![Material::diffuse("default", Vec3::splat(0.5))],
        up: m.up.unwrap_or_default(),
        ..Default::default()
    })
}

#[derive(Clone, Copy, Debug, PartialEq)]
enum Scalar {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

impl Scalar {
    fn parse(s: &str) -> Option<Scalar> {
        Some(match s {
            "char" | "int8" => Scalar::I8,
            "uchar" | "uint8" => Scalar::U8,
            "short" | "int16" => Scalar::I16,
            "ushort" | "uint16" => Scalar::U16,
            "int" | "int32" => Scalar::I32,
            "uint" | "uint32" => Scalar::U32,
            "float" | "float32" => Scalar::F32,
            "double" | "float64" => Scalar::F64,
            _ => return None,
        })
    }
    fn size(self) -> usize {
        match self {
            Scalar::I8 | Scalar::U8 => 1,
            Scalar::I16 | Scalar::U16 => 2,
            Scalar::I32 | Scalar::U32 | Scalar::F32 => 4,
            Scalar::F64 => 8,
        }
    }
}

#[derive(Clone, Debug)]
struct Property {
    name: String,
    /// `Some(count type)` for list properties.
    list: Option<Scalar>,
    ty: Scalar,
}

#[derive(Clone, Debug)]
struct Element {
    name: String,
    count: usize,
    props: Vec<Property>,
}

#[derive(Clone, Copy, PartialEq)]
enum Format {
    Ascii,
    Le,
    Be,
}

/// Reads scalars from the body, ASCII or binary.
struct Body<'a> {
    path: &'a Path,
    bytes: &'a [u8],
    pos: usize,
    format: Format,
    /// Current line (ASCII).
    line: usize,
    /// Tokens left on the current ASCII line.
    toks: Vec<&'a [u8]>,
    tok_i: usize,
}

impl<'a> Body<'a> {
    fn err(&self, what: &str) -> Error {
        match self.format {
            Format::Ascii => Error::input_at(self.path, self.line, what.to_string()),
            _ => Error::input(self.path, format!("{what} (at byte {})", self.pos)),
        }
    }

    /// Start the next ASCII record (one line).
    fn next_line(&mut self, what: &str) -> Result<()> {
        if self.format != Format::Ascii {
            return Ok(());
        }
        loop {
            if self.pos >= self.bytes.len() {
                self.line += 1;
                return Err(self.err(&format!("file ends before {what}")));
            }
            let end = self.bytes[self.pos..]
                .iter()
                .position(|&b| b == b'\n')
                .map(|p| self.pos + p)
                .unwrap_or(self.bytes.len());
            let line = &self.bytes[self.pos..end];
            self.pos = end + 1;
            self.line += 1;
            self.toks = line
                .split(|b| b.is_ascii_whitespace())
                .filter(|t| !t.is_empty())
                .collect();
            self.tok_i = 0;
            if !self.toks.is_empty() {
                return Ok(());
            }
        }
    }

    fn end_line(&self, what: &str) -> Result<()> {
        if self.format == Format::Ascii && self.tok_i != self.toks.len() {
            return Err(self.err(&format!(
                "{what}: {} values on the line, expected {}",
                self.toks.len(),
                self.tok_i
            )));
        }
        Ok(())
    }

    fn scalar(&mut self, ty: Scalar, what: &str) -> Result<f64> {
        match self.format {
            Format::Ascii => {
                let Some(tok) = self.toks.get(self.tok_i) else {
                    return Err(self.err(&format!("{what}: too few values on the line")));
                };
                self.tok_i += 1;
                let s = std::str::from_utf8(tok).unwrap_or("");
                let v = match ty {
                    Scalar::F32 | Scalar::F64 => s.parse::<f64>().ok(),
                    _ => s.parse::<i64>().ok().map(|v| v as f64),
                };
                v.ok_or_else(|| {
                    self.err(&format!(
                        "{what}: '{}' is not a {ty:?} number",
                        String::from_utf8_lossy(tok)
                    ))
                })
            }
            f => {
                let n = ty.size();
                let Some(b) = self.bytes.get(self.pos..self.pos + n) else {
                    return Err(self.err(&format!("file is truncated in {what}")));
                };
                self.pos += n;
                let mut a = [0u8; 8];
                a[..n].copy_from_slice(b);
                if f == Format::Be {
                    a[..n].reverse();
                }
                Ok(match ty {
                    Scalar::I8 => a[0] as i8 as f64,
                    Scalar::U8 => a[0] as f64,
                    Scalar::I16 => i16::from_le_bytes([a[0], a[1]]) as f64,
                    Scalar::U16 => u16::from_le_bytes([a[0], a[1]]) as f64,
                    Scalar::I32 => i32::from_le_bytes([a[0], a[1], a[2], a[3]]) as f64,
                    Scalar::U32 => u32::from_le_bytes([a[0], a[1], a[2], a[3]]) as f64,
                    Scalar::F32 => f32::from_le_bytes([a[0], a[1], a[2], a[3]]) as f64,
                    Scalar::F64 => f64::from_le_bytes(a),
                })
            }
        }
    }
}

/// What the header says: format, elements, offset of the body, header lines, up axis.
type Header = (Format, Vec<Element>, usize, usize, Option<UpAxis>);

fn parse_header(path: &Path, bytes: &[u8]) -> Result<Header> {
    let mut pos = 0usize;
    let mut line_no = 0usize;
    let mut format = None;
    let mut elements: Vec<Element> = Vec::new();
    let mut up = None;
    loop {
        if pos >= bytes.len() {
            return Err(Error::input_at(
                path,
                line_no.max(1),
                "PLY header has no end_header",
            ));
        }
        let end = bytes[pos..]
            .iter()
            .position(|&b| b == b'\n')
            .map(|p| pos + p)
            .unwrap_or(bytes.len());
        let line = String::from_utf8_lossy(&bytes[pos..end]).trim().to_string();
        pos = end + 1;
        line_no += 1;
        let toks: Vec<&str> = line.split_ascii_whitespace().collect();
        if line_no == 1 {
            if toks != ["ply"] {
                return Err(Error::input_at(
                    path,
                    1,
                    "not a PLY file (first line is not 'ply')",
                ));
            }
            continue;
        }
        let bad = |msg: String| Error::input_at(path, line_no, msg);
        match toks.first().copied() {
            None => {}
            Some("format") => {
                format = Some(match toks.get(1).copied() {
                    Some("ascii") => Format::Ascii,
                    Some("binary_little_endian") => Format::Le,
                    Some("binary_big_endian") => Format::Be,
                    other => return Err(bad(format!("unknown PLY format {other:?}"))),
                });
            }
            Some("comment") => {
                let l = line.to_ascii_lowercase();
                if l.contains("+z up") || l.contains("z-up") || l.contains("z up") {
                    up = Some(UpAxis::Z);
                } else if l.contains("+y up") || l.contains("y-up") || l.contains("y up") {
                    up = Some(UpAxis::Y);
                }
            }
            Some("obj_info") => {}
            Some("element") => {
                let (Some(name), Some(count)) = (toks.get(1), toks.get(2)) else {
                    return Err(bad("element needs a name and a count".into()));
                };
                let count: usize = count
                    .parse()
                    .map_err(|_| bad(format!("element count '{count}' is not a number")))?;
                elements.push(Element {
                    name: name.to_string(),
                    count,
                    props: Vec::new(),
                });
            }
            Some("property") => {
                let Some(el) = elements.last_mut() else {
                    return Err(bad("property before any element".into()));
                };
                let p = if toks.get(1) == Some(&"list") {
                    match (
                        toks.get(2).and_then(|s| Scalar::parse(s)),
                        toks.get(3).and_then(|s| Scalar::parse(s)),
                        toks.get(4),
                    ) {
                        (Some(c), Some(t), Some(n)) => Property {
                            name: n.to_string(),
                            list: Some(c),
                            ty: t,
                        },
                        _ => return Err(bad(format!("bad list property '{line}'"))),
                    }
                } else {
                    match (toks.get(1).and_then(|s| Scalar::parse(s)), toks.get(2)) {
                        (Some(t), Some(n)) => Property {
                            name: n.to_string(),
                            list: None,
                            ty: t,
                        },
                        _ => return Err(bad(format!("bad property '{line}'"))),
                    }
                };
                el.props.push(p);
            }
            Some("end_header") => break,
            Some(other) => return Err(bad(format!("unknown PLY header keyword '{other}'"))),
        }
    }
    let format =
        format.ok_or_else(|| Error::input_at(path, line_no, "PLY header has no format line"))?;
    Ok((format, elements, pos.min(bytes.len()), line_no, up))
}

/// Read a PLY file: positions, fan-triangulated faces, optional vertex colours.
pub fn read(path: &Path) -> Result<PlyMesh> {
    let bytes = hirad_core::io::read_input(path)?;
    read_bytes(path, &bytes)
}

/// Read PLY data from memory (`path` names it in errors).
pub fn read_bytes(path: &Path, bytes: &[u8]) -> Result<PlyMesh> {
    let (format, elements, start, header_lines, up) = parse_header(path, bytes)?;
    let mut body = Body {
        path,
        bytes,
        pos: start,
        format,
        line: header_lines,
        toks: Vec::new(),
        tok_i: 0,
    };
    let mut out = PlyMesh {
        up,
        ..Default::default()
    };
    let mut have_vertices = false;
    let mut nv_total = 0usize;
    for el in &elements {
        // Each record needs at least one byte (binary) or one line (ASCII): reject counts the
        // file cannot hold before reserving memory for them.
        let min_rec = match format {
            Format::Ascii => 2,
            _ => el
                .props
                .iter()
                .map(|p| p.list.map_or(p.ty.size(), |c| c.size()))
                .sum::<usize>()
                .max(1),
        };
        if el.count > 0
            && el.count.saturating_mul(min_rec) > bytes.len() - body.pos.min(bytes.len()) + 1
        {
            return Err(body.err(&format!(
                "element '{}' declares {} records but the file is too short for them",
                el.name, el.count
            )));
        }
        match el.name.as_str() {
            "vertex" => {
                have_vertices = true;
                nv_total = el.count;
                let find = |n: &str| {
                    el.props
                        .iter()
                        .position(|p| p.name == n && p.list.is_none())
                };
                let (Some(ix), Some(iy), Some(iz)) = (find("x"), find("y"), find("z")) else {
                    return Err(Error::input(path, "vertex element lacks x, y or z"));
                };
                let rgb = (find("red"), find("green"), find("blue"));
                let lin = (
                    find("radiosity_r"),
                    find("radiosity_g"),
                    find("radiosity_b"),
                );
                let has_rgb = rgb.0.is_some() && rgb.1.is_some() && rgb.2.is_some();
                let has_lin = lin.0.is_some() && lin.1.is_some() && lin.2.is_some();
                out.positions.reserve(el.count);
                let mut cols = Vec::new();
                let mut lins = Vec::new();
                let mut vals = vec![0f64; el.props.len()];
                for i in 0..el.count {
                    body.next_line("vertex data")?;
                    for (k, p) in el.props.iter().enumerate() {
                        vals[k] = read_prop(&mut body, p, "vertex")?;
                    }
                    body.end_line("vertex")?;
                    let v = Vec3::new(vals[ix] as f32, vals[iy] as f32, vals[iz] as f32);
                    if !v.is_finite() {
                        return Err(body.err(&format!("vertex {i} has a non-finite coordinate")));
                    }
                    out.positions.push(v);
                    if has_rgb {
                        let scale = |k: usize| {
                            let p = &el.props[k];
                            if matches!(p.ty, Scalar::F32 | Scalar::F64) {
                                vals[k] as f32
                            } else if p.ty == Scalar::U16 {
                                vals[k] as f32 / 65535.0
                            } else {
                                vals[k] as f32 / 255.0
                            }
                        };
                        cols.push(Vec3::new(
                            scale(rgb.0.unwrap_or(0)),
                            scale(rgb.1.unwrap_or(0)),
                            scale(rgb.2.unwrap_or(0)),
                        ));
                    }
                    if has_lin {
                        lins.push(Vec3::new(
                            vals[lin.0.unwrap_or(0)] as f32,
                            vals[lin.1.unwrap_or(0)] as f32,
                            vals[lin.2.unwrap_or(0)] as f32,
                        ));
                    }
                }
                if has_rgb {
                    out.colors = Some(cols);
                }
                if has_lin {
                    out.linear_colors = Some(lins);
                }
            }
            "face" => {
                let fi = el.props.iter().position(|p| {
                    p.list.is_some() && (p.name == "vertex_indices" || p.name == "vertex_index")
                });
                let Some(fi) = fi else {
                    return Err(Error::input(
                        path,
                        "face element lacks a vertex_indices list property",
                    ));
                };
                out.triangles.reserve(el.count);
                let mut corners: Vec<u32> = Vec::new();
                for i in 0..el.count {
                    body.next_line("face data")?;
                    for (k, p) in el.props.iter().enumerate() {
                        if k != fi {
                            skip_prop(&mut body, p)?;
                            continue;
                        }
                        let cty = p.list.unwrap_or(Scalar::U8);
                        let n = body.scalar(cty, "face vertex count")?;
                        if !(0.0..=1e6).contains(&n) {
                            return Err(body.err(&format!("face {i} has {n} vertices")));
                        }
                        corners.clear();
                        for _ in 0..n as usize {
                            let v = body.scalar(p.ty, "face index")?;
                            if v < 0.0 || v >= nv_total as f64 || !have_vertices {
                                return Err(body.err(&format!(
                                    "face {i} uses vertex {v} but there are {nv_total} vertices"
                                )));
                            }
                            corners.push(v as u32);
                        }
                    }
                    body.end_line("face")?;
                    if corners.len() < 3 {
                        return Err(body.err(&format!(
                            "face {i} has {} vertices, expected at least 3",
                            corners.len()
                        )));
                    }
                    for k in 1..corners.len() - 1 {
                        out.triangles.push([corners[0], corners[k], corners[k + 1]]);
                    }
                }
            }
            _ => {
                for _ in 0..el.count {
                    body.next_line(&format!("{} data", el.name))?;
                    for p in &el.props {
                        skip_prop(&mut body, p)?;
                    }
                    body.end_line(&el.name)?;
                }
            }
        }
    }
    Ok(out)
}

fn read_prop(body: &mut Body, p: &Property, what: &str) -> Result<f64> {
    match p.list {
        None => body.scalar(p.ty, what),
        Some(_) => {
            skip_prop(body, p)?;
            Ok(0.0)
        }
    }
}

fn skip_prop(body: &mut Body, p: &Property) -> Result<()> {
    match p.list {
        None => body.scalar(p.ty, &p.name).map(|_| ()),
        Some(c) => {
            let n = body.scalar(c, &p.name)?;
            if !(0.0..=1e6).contains(&n) {
                return Err(body.err(&format!("list '{}' has length {n}", p.name)));
            }
            for _ in 0..n as usize {
                body.scalar(p.ty, &p.name)?;
            }
            Ok(())
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ascii_with_quad_and_colours() {
        let text = "ply\nformat ascii 1.0\ncomment +Z up\nelement vertex 4\nproperty float x\n\
                    property float y\nproperty float z\nproperty uchar red\nproperty uchar green\n\
                    property uchar blue\nelement face 1\nproperty list uchar int vertex_indices\n\
                    end_header\n0 0 0 255 0 0\n1 0 0 0 255 0\n1 1 0 0 0 255\n0 1 0 51 51 51\n\
                    4 0 1 2 3\n";
        let m = read_bytes(Path::new("q.ply"), text.as_bytes()).unwrap();
        assert_eq!(m.triangles, vec![[0, 1, 2], [0, 2, 3]]);
        assert_eq!(m.up, Some(UpAxis::Z));
        let c = m.colors.unwrap();
        assert_eq!(c[0], Vec3::X);
        assert!((c[3].x - 0.2).abs() < 1e-6);
        // An index past the end names the line.
        let bad = text.replace("4 0 1 2 3", "3 0 1 7");
        let e = read_bytes(Path::new("q.ply"), bad.as_bytes()).unwrap_err();
        assert!(e.to_string().contains("q.ply:18:"), "{e}");
    }

    #[test]
    fn binary_big_and_little_endian() {
        for (fmt, be) in [("binary_little_endian", false), ("binary_big_endian", true)] {
            let mut b = format!(
                "ply\nformat {fmt} 1.0\nelement vertex 3\nproperty double x\nproperty double y\n\
                 property double z\nelement face 1\nproperty list uchar uint vertex_indices\n\
                 end_header\n"
            )
            .into_bytes();
            for v in [[0.0f64, 0.0, 0.0], [2.0, 0.0, 0.0], [0.0, 3.0, 0.0]] {
                for x in v {
                    b.extend(if be { x.to_be_bytes() } else { x.to_le_bytes() });
                }
            }
            b.push(3);
            for i in [0u32, 1, 2] {
                b.extend(if be { i.to_be_bytes() } else { i.to_le_bytes() });
            }
            let m = read_bytes(Path::new("b.ply"), &b).unwrap();
            assert_eq!(m.positions[2], Vec3::new(0.0, 3.0, 0.0));
            assert_eq!(m.triangles, vec![[0, 1, 2]]);
            // Truncation is an error, never a panic.
            for cut in 0..b.len() {
                let _ = read_bytes(Path::new("b.ply"), &b[..cut]);
            }
            assert!(read_bytes(Path::new("b.ply"), &b[..b.len() - 1]).is_err());
        }
    }
}
