//! MGF geometry entities to triangles: `f` and `fh` polygons of world-space vertices, and the
//! primitives `sph cyl cone ring torus prism`, built in local coordinates with faces oriented
//! outwards and then transformed. Curved primitives are tessellated as mgflib does, with
//! `divisions` quarter-circle divisions (4 × divisions segments around the axis).

use super::parse::At;
use super::triangulate::triangulate;
use super::Loader;
use glam::DVec3;
use hirad_core::Result;

/// A triangle mesh in local coordinates.
struct Mesh {
    points: Vec<DVec3>,
    tris: Vec<[u32; 3]>,
}

/// Two unit vectors completing `w` to a right-handed frame (u × v = w).
fn axes(w: DVec3) -> (DVec3, DVec3) {
    let a = w.abs();
    let e = if a.x <= a.y && a.x <= a.z {
        DVec3::X
    } else if a.y <= a.z {
        DVec3::Y
    } else {
        DVec3::Z
    };
    let u = w.cross(e).normalize();
    (u, w.cross(u))
}

/// A surface of revolution about the axis (`c`, `w`): rings of `(radius, height)` from the
/// profile, 4 × `div` segments around; each triangle faces `outward(centroid)`.
fn revolve(
    c: DVec3,
    w: DVec3,
    profile: &[(f64, f64)],
    div: usize,
    outward: impl Fn(DVec3) -> DVec3,
) -> Mesh {
    let segs = 4 * div;
    let (u, v) = axes(w);
    let mut points = Vec::new();
    let mut rings: Vec<Vec<u32>> = Vec::new();
    for &(r, h) in profile {
        let base = c + w * h;
        if r == 0.0 {
            points.push(base);
            rings.push(vec![points.len() as u32 - 1; segs]);
        } else {
            let ring = (0..segs)
                .map(|s| {
                    let t = std::f64::consts::TAU * s as f64 / segs as f64;
                    points.push(base + (u * t.cos() + v * t.sin()) * r);
                    points.len() as u32 - 1
                })
                .collect();
            rings.push(ring);
        }
    }
    let mut tris = Vec::new();
    for k in 0..rings.len().saturating_sub(1) {
        let (r0, r1) = (&rings[k], &rings[k + 1]);
        for s in 0..segs {
            let s1 = (s + 1) % segs;
            for t in [[r0[s], r0[s1], r1[s1]], [r0[s], r1[s1], r1[s]]] {
                if t[0] == t[1] || t[1] == t[2] || t[0] == t[2] {
                    continue;
                }
                let [a, b, cc] = t.map(|i| points[i as usize]);
                let n = (b - a).cross(cc - a);
                tris.push(if n.dot(outward((a + b + cc) / 3.0)) < 0.0 {
                    [t[0], t[2], t[1]]
                } else {
                    t
                });
            }
        }
    }
    Mesh { points, tris }
}

/// Sphere of radius `r` (negative: facing inwards) about `c`.
fn sphere(c: DVec3, r: f64, div: usize) -> Mesh {
    let n = 2 * div;
    let profile: Vec<(f64, f64)> = (0..=n)
        .map(|i| {
            let th = std::f64::consts::FRAC_PI_2 * i as f64 / div as f64;
            let s = if i == 0 || i == n { 0.0 } else { th.sin() };
            (r.abs() * s, r.abs() * th.cos())
        })
        .collect();
    let sign = r.signum();
    revolve(c, DVec3::Z, &profile, div, |p| (p - c) * sign)
}

/// Cone (or cylinder) from `a` (radius `r1`) to `b` (radius `r2`); negative radii face
/// inwards. `None` when `a` = `b`.
fn cone(a: DVec3, r1: f64, b: DVec3, r2: f64, div: usize) -> Option<Mesh> {
    let d = b - a;
    let h = d.length();
    let w = d.try_normalize()?;
    let sign = if r1 < 0.0 || r2 < 0.0 { -1.0 } else { 1.0 };
    Some(revolve(a, w, &[(r1.abs(), 0.0), (r2.abs(), h)], div, |p| {
        let q = p - a;
        (q - w * q.dot(w)) * sign
    }))
}

/// Flat annulus between radii `r0` and `r1` about `c`, facing `n`.
fn ring(c: DVec3, n: DVec3, r0: f64, r1: f64, div: usize) -> Mesh {
    revolve(c, n, &[(r0, 0.0), (r1, 0.0)], div, |_| n)
}

/// Torus about `c` and axis `n` between radii `r0` and `r1` (negative: facing inwards).
fn torus(c: DVec3, n: DVec3, r0: f64, r1: f64, div: usize) -> Mesh {
    let sign = r1.signum();
    let (r0, r1) = (r0.abs(), r1.abs());
    let minor = 0.5 * (r1 - r0);
    let major = 0.5 * (r1 + r0);
    let steps = 4 * div;
    let profile: Vec<(f64, f64)> = (0..=steps)
        .map(|i| {
            let th = std::f64::consts::TAU * (i % steps) as f64 / steps as f64;
            (major + minor * th.cos(), minor * th.sin())
        })
        .collect();
    revolve(c, n, &profile, div, |p| {
        let q = p - c;
        let radial = (q - n * q.dot(n)).normalize_or_zero();
        (q - radial * major) * sign
    })
}

/// `prism`, as the MGF specification has it: the polygon keeps its orientation and is
/// extruded opposite its (right-hand rule) normal, so with a positive length every face points
/// outwards; with a negative length the prism lies above the polygon and faces inwards.
fn prism(base: &[DVec3], len: f64) -> Option<Mesh> {
    let n = base.len();
    let tris = triangulate(&[base.to_vec()]);
    let mut normal = DVec3::ZERO;
    for k in 0..n {
        normal += base[k].cross(base[(k + 1) % n]);
    }
    let normal = normal.try_normalize()?;
    let d = -normal * len;
    let mut points = base.to_vec();
    points.extend(base.iter().map(|&p| p + d));
    let n32 = n as u32;
    let mut out = Vec::new();
    for t in &tris {
        let t = t.map(|k| k as u32);
        // The base as given, the opposite end its mirror image.
        out.push(t);
        out.push([t[0] + n32, t[2] + n32, t[1] + n32]);
    }
    for k in 0..n32 {
        let k1 = (k + 1) % n32;
        out.push([k, k + n32, k1 + n32]);
        out.push([k, k1 + n32, k1]);
    }
    Some(Mesh { points, tris: out })
}

impl Loader {
    /// Run a geometry entity (`f fh sph cyl cone ring torus prism`).
    pub(super) fn geometry(&mut self, at: At, w: &[String]) -> Result<()> {
        let e = w[0].as_str();
        let n = w.len() - 1;
        match e {
            "f" => {
                at.argc(w, n >= 3, "f v1 v2 v3 ...")?;
                let idx = w[1..]
                    .iter()
                    .map(|s| self.world_vertex(at, s))
                    .collect::<Result<Vec<_>>>()?;
                self.polygon(vec![idx]);
            }
            "fh" => {
                at.argc(w, n >= 3, "fh v1 v2 v3 ... [- v1 v2 v3 ...]")?;
                let mut contours = vec![Vec::new()];
                for s in &w[1..] {
                    if s == "-" {
                        contours.push(Vec::new());
                    } else {
                        let v = self.world_vertex(at, s)?;
                        contours.last_mut().expect("contour").push(v);
                    }
                }
                if contours.iter().any(|c| c.len() < 3) {
                    return Err(at.err("fh: every contour needs at least 3 vertices"));
                }
                self.polygon(contours);
            }
            "sph" => {
                at.argc(w, n == 2, "sph center radius")?;
                let c = self.local_vertex(at, &w[1])?.p;
                let r = at.num(&w[2])?;
                let mesh = sphere(c, r, self.divisions);
                self.emit_mesh(mesh);
            }
            "cyl" | "cone" => {
                let (r1, r2, v2) = if e == "cyl" {
                    at.argc(w, n == 3, "cyl v1 radius v2")?;
                    let r = at.num(&w[2])?;
                    (r, r, &w[3])
                } else {
                    at.argc(w, n == 4, "cone v1 radius1 v2 radius2")?;
                    (at.num(&w[2])?, at.num(&w[4])?, &w[3])
                };
                let a = self.local_vertex(at, &w[1])?.p;
                let b = self.local_vertex(at, v2)?.p;
                if r1 * r2 < 0.0 || (r1 == 0.0 && r2 == 0.0) {
                    return Err(at.err(format!("illegal radii {r1}, {r2}")));
                }
                if let Some(mesh) = cone(a, r1, b, r2, self.divisions) {
                    self.emit_mesh(mesh);
                }
            }
            "ring" | "torus" => {
                at.argc(w, n == 3, &format!("{e} center rmin rmax"))?;
                let v = self.local_vertex(at, &w[1])?;
                let (r0, r1) = (at.num(&w[2])?, at.num(&w[3])?);
                let illegal = if e == "ring" {
                    r0 < 0.0 || r1 <= r0
                } else {
                    r0 * r1 < 0.0 || r1.abs() <= r0.abs()
                };
                if illegal {
                    return Err(at.err(format!("illegal {e} radii {r0}, {r1}")));
                }
                let nrm =
                    v.n.try_normalize()
                        .ok_or_else(|| at.err(format!("{e}: vertex '{}' has no normal", w[1])))?;
                let mesh = if e == "ring" {
                    ring(v.p, nrm, r0, r1, self.divisions)
                } else {
                    torus(v.p, nrm, r0, r1, self.divisions)
                };
                self.emit_mesh(mesh);
            }
            "prism" => {
                at.argc(w, n >= 4, "prism v1 v2 v3 ... length")?;
                let len = at.num(&w[n])?;
                let pts = w[1..n]
                    .iter()
                    .map(|s| Ok(self.local_vertex(at, s)?.p))
                    .collect::<Result<Vec<_>>>()?;
                if let Some(mesh) = prism(&pts, len) {
                    self.emit_mesh(mesh);
                }
            }
            _ => unreachable!("'{e}' is not a geometry entity"),
        }
        Ok(())
    }

    /// Triangulate a polygon (outer contour, then holes) of output vertex indices.
    fn polygon(&mut self, mut contours: Vec<Vec<u32>>) {
        if self.top_xf().flip {
            for c in &mut contours {
                c.reverse();
            }
        }
        let pts: Vec<Vec<DVec3>> = contours
            .iter()
            .map(|c| {
                c.iter()
                    .map(|&i| self.raw.positions[i as usize].as_dvec3())
                    .collect()
            })
            .collect();
        let tris = triangulate(&pts);
        if tris.is_empty() {
            return;
        }
        let flat: Vec<u32> = contours.concat();
        self.add_triangles(tris.into_iter().map(|t| t.map(|k| flat[k])));
    }

    /// Transform a mesh built in local coordinates and add it.
    fn emit_mesh(&mut self, mesh: Mesh) {
        if mesh.tris.is_empty() {
            return;
        }
        let xf = self.top_xf();
        let base = self.raw.positions.len() as u32;
        self.raw.positions.extend(
            mesh.points
                .iter()
                .map(|&p| xf.m.transform_point3(p).as_vec3()),
        );
        self.add_triangles(mesh.tris.into_iter().map(|t| {
            let t = t.map(|k| base + k);
            if xf.flip {
                [t[0], t[2], t[1]]
            } else {
                t
            }
        }));
    }

    /// Add triangles of output vertex indices with the current material and object.
    fn add_triangles(&mut self, tris: impl Iterator<Item = [u32; 3]>) {
        let mat = self.material();
        let obj = self.object();
        for t in tris {
            self.raw.triangles.push(t);
            self.raw.tri_material.push(mat);
            self.raw.tri_object.push(obj);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn primitive_triangle_counts() {
        let c = DVec3::ZERO;
        assert_eq!(sphere(c, 1.0, 4).tris.len(), 224);
        assert_eq!(cone(c, 1.0, DVec3::Z, 1.0, 4).unwrap().tris.len(), 32);
        assert_eq!(cone(c, 1.0, DVec3::Z, 0.0, 4).unwrap().tris.len(), 16);
        assert_eq!(ring(c, DVec3::Z, 0.5, 1.0, 4).tris.len(), 32);
        assert_eq!(ring(c, DVec3::Z, 0.0, 1.0, 4).tris.len(), 16);
        assert_eq!(torus(c, DVec3::Z, 1.0, 2.0, 4).tris.len(), 512);
        let sq = [DVec3::ZERO, DVec3::X, DVec3::new(1.0, 1.0, 0.0), DVec3::Y];
        assert_eq!(prism(&sq, 1.0).unwrap().tris.len(), 12);
    }
}
