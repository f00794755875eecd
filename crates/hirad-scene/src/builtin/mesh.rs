//! Mesh building blocks shared by the built-in scene generators: a [`MeshBuilder`] that
//! accumulates vertices, triangles, materials and objects, and primitives (subdivided quads,
//! boxes, cylinders, spheres) with a fixed orientation convention:
//!
//! - a quad `(p0, p1, p2, p3)` given counter-clockwise faces `(p1 − p0) × (p3 − p0)`;
//! - closed solids (boxes, cylinders, spheres) face outwards unless the call says `inward`.
//!
//! Every generator works in a +Y-up frame; [`MeshBuilder::finish`] rotates to +Z up when asked
//! (a rotation, so the winding and hence the facing are kept).

use crate::{Camera, Material, RawScene, UpAxis};
use glam::{Affine3A, Vec3};
use std::collections::HashMap;

/// Accumulates the arrays of a [`RawScene`].
#[derive(Debug, Default)]
pub struct MeshBuilder {
    /// Vertex positions (metres, +Y up until [`finish`](Self::finish)).
    pub positions: Vec<Vec3>,
    /// Vertex indices per triangle.
    pub triangles: Vec<[u32; 3]>,
    /// Material id per triangle.
    pub tri_material: Vec<u32>,
    /// Object id per triangle.
    pub tri_object: Vec<u32>,
    /// Object names, indexed by object id.
    pub objects: Vec<String>,
    /// Materials, indexed by material id.
    pub materials: Vec<Material>,
    material_ids: HashMap<String, u32>,
    /// Current material id used by the primitives.
    pub mat: u32,
    /// Current object id used by the primitives.
    pub obj: u32,
}

impl MeshBuilder {
    /// Empty builder.
    pub fn new() -> Self {
        Self::default()
    }

    /// Id of the material `name`, adding it (with `rho`, `emission`) the first time.
    pub fn material(&mut self, name: &str, rho: Vec3, emission: Vec3) -> u32 {
        if let Some(&id) = self.material_ids.get(name) {
            return id;
        }
        let id = self.materials.len() as u32;
        self.materials.push(Material {
            name: name.to_string(),
            rho,
            emission,
        });
        self.material_ids.insert(name.to_string(), id);
        id
    }

    /// Make `name` (added if new) the current material.
    pub fn use_material(&mut self, name: &str, rho: Vec3, emission: Vec3) {
        self.mat = self.material(name, rho, emission);
    }

    /// Start a new object named `name` and make it current; returns its id.
    pub fn begin_object(&mut self, name: impl Into<String>) -> u32 {
        self.obj = self.objects.len() as u32;
        self.objects.push(name.into());
        self.obj
    }

    /// Add a vertex, returning its index.
    #[inline]
    pub fn vertex(&mut self, p: Vec3) -> u32 {
        self.positions.push(p);
        (self.positions.len() - 1) as u32
    }

    /// Add a triangle of existing vertices with the current material and object.
    #[inline]
    pub fn tri(&mut self, a: u32, b: u32, c: u32) {
        self.triangles.push([a, b, c]);
        self.tri_material.push(self.mat);
        self.tri_object.push(self.obj);
    }

    /// Number of triangles so far.
    pub fn num_triangles(&self) -> usize {
        self.triangles.len()
    }

    /// Quad `p0 p1 p2 p3` (counter-clockwise seen from the front) as two triangles.
    pub fn quad(&mut self, p: [Vec3; 4]) {
        let v = p.map(|q| self.vertex(q));
        self.tri(v[0], v[1], v[2]);
        self.tri(v[0], v[2], v[3]);
    }

    /// Parallelogram `origin + s·u + t·v`, s, t ∈ [0, 1], split into `nu × nv` cells of two
    /// triangles with shared vertices; faces `u × v`.
    pub fn grid(&mut self, origin: Vec3, u: Vec3, v: Vec3, nu: u32, nv: u32) {
        self.grid_masked(origin, u, v, nu, nv, |_, _| true);
    }

    /// As [`grid`](Self::grid), keeping only the cells `(i, j)` for which `keep` is true.
    pub fn grid_masked(
        &mut self,
        origin: Vec3,
        u: Vec3,
        v: Vec3,
        nu: u32,
        nv: u32,
        keep: impl Fn(u32, u32) -> bool,
    ) {
        let (nu, nv) = (nu.max(1), nv.max(1));
        let base = self.positions.len() as u32;
        for j in 0..=nv {
            for i in 0..=nu {
                let p = origin + u * (i as f32 / nu as f32) + v * (j as f32 / nv as f32);
                self.positions.push(p);
            }
        }
        let idx = |i: u32, j: u32| base + j * (nu + 1) + i;
        for j in 0..nv {
            for i in 0..nu {
                if !keep(i, j) {
                    continue;
                }
                let (a, b, c, d) = (idx(i, j), idx(i + 1, j), idx(i + 1, j + 1), idx(i, j + 1));
                // Alternate the diagonal so that the mesh has no preferred direction.
                if (i + j) % 2 == 0 {
                    self.tri(a, b, c);
                    self.tri(a, c, d);
                } else {
                    self.tri(a, b, d);
                    self.tri(b, c, d);
                }
            }
        }
    }

    /// Box `[min, max]` under transform `xf`, six faces of two triangles, facing outwards
    /// (`inward = false`) or inwards. `skip` lists faces to leave out, as bits:
    /// 1 = −X, 2 = +X, 4 = −Y, 8 = +Y, 16 = −Z, 32 = +Z.
    pub fn cuboid(&mut self, xf: &Affine3A, min: Vec3, max: Vec3, inward: bool, skip: u32) {
        self.cuboid_subdiv(xf, min, max, inward, skip, [1, 1, 1]);
    }

    /// [`cuboid`](Self::cuboid) with each face split into a grid; `n[k]` cells along axis k.
    pub fn cuboid_subdiv(
        &mut self,
        xf: &Affine3A,
        min: Vec3,
        max: Vec3,
        inward: bool,
        skip: u32,
        n: [u32; 3],
    ) {
        let e = max - min;
        let (ex, ey, ez) = (Vec3::X * e.x, Vec3::Y * e.y, Vec3::Z * e.z);
        // (bit, origin, u, v, nu, nv) with u × v pointing outwards.
        let faces = [
            (1, min, ez, ey, n[2], n[1]),
            (2, min + ex, ey, ez, n[1], n[2]),
            (4, min, ex, ez, n[0], n[2]),
            (8, min + ey, ez, ex, n[2], n[0]),
            (16, min, ey, ex, n[1], n[0]),
            (32, min + ez, ex, ey, n[0], n[1]),
        ];
        for (bit, o, u, v, nu, nv) in faces {
            if skip & bit != 0 {
                continue;
            }
            let (o, u, v) = (
                xf.transform_point3(o),
                xf.transform_vector3(u),
                xf.transform_vector3(v),
            );
            if inward {
                self.grid(o, v, u, nv, nu);
            } else {
                self.grid(o, u, v, nu, nv);
            }
        }
    }

    /// Closed cylinder (or open tube when `caps` is false) of radius `r` from `a` to `b`,
    /// `segments` around and `rings` along, facing outwards. A zero-length axis adds nothing.
    pub fn cylinder(&mut self, a: Vec3, b: Vec3, r: f32, segments: u32, rings: u32, caps: bool) {
        self.cone(a, b, r, r, segments, rings, caps);
    }

    /// Truncated cone from `a` (radius `ra`) to `b` (radius `rb`), facing outwards.
    #[allow(clippy::too_many_arguments)]
    pub fn cone(
        &mut self,
        a: Vec3,
        b: Vec3,
        ra: f32,
        rb: f32,
        segments: u32,
        rings: u32,
        caps: bool,
    ) {
        let axis = b - a;
        if axis.length_squared() <= 0.0 {
            return;
        }
        let w = axis.normalize();
        let u = w.any_orthonormal_vector();
        let v = w.cross(u);
        let segments = segments.max(3);
        let rings = rings.max(1);
        let dir = |k: u32| {
            let phi = std::f32::consts::TAU * k as f32 / segments as f32;
            u * phi.cos() + v * phi.sin()
        };
        let base = self.positions.len() as u32;
        for j in 0..=rings {
            let t = j as f32 / rings as f32;
            let c = a + axis * t;
            let r = ra + (rb - ra) * t;
            for k in 0..segments {
                self.positions.push(c + dir(k) * r);
            }
        }
        let idx = |k: u32, j: u32| base + j * segments + k % segments;
        // u × v = w, so increasing angle runs counter-clockwise around w: the quad
        // (k, j) → (k+1, j) → (k+1, j+1) → (k, j+1) faces outwards.
        for j in 0..rings {
            for k in 0..segments {
                let (p0, p1, p2, p3) = (idx(k, j), idx(k + 1, j), idx(k + 1, j + 1), idx(k, j + 1));
                // Skip the triangles that collapse at an apex (radius 0).
                if ra > 0.0 || j > 0 {
                    self.tri(p0, p1, p2);
                }
                if rb > 0.0 || j + 1 < rings {
                    self.tri(p0, p2, p3);
                }
            }
        }
        if caps {
            if ra > 0.0 {
                let ca = self.vertex(a);
                for k in 0..segments {
                    self.tri(ca, idx(k + 1, 0), idx(k, 0));
                }
            }
            if rb > 0.0 {
                let cb = self.vertex(b);
                for k in 0..segments {
                    self.tri(cb, idx(k, rings), idx(k + 1, rings));
                }
            }
        }
    }

    /// UV sphere of radius `r` at `c`, facing outwards (or inwards).
    pub fn sphere(&mut self, c: Vec3, r: f32, segments: u32, stacks: u32, inward: bool) {
        let segments = segments.max(3);
        let stacks = stacks.max(2);
        let top = self.vertex(c + Vec3::Y * r);
        let bottom = self.vertex(c - Vec3::Y * r);
        let base = self.positions.len() as u32;
        for j in 1..stacks {
            let theta = std::f32::consts::PI * j as f32 / stacks as f32;
            for k in 0..segments {
                let phi = std::f32::consts::TAU * k as f32 / segments as f32;
                let d = Vec3::new(
                    theta.sin() * phi.cos(),
                    theta.cos(),
                    -theta.sin() * phi.sin(),
                );
                self.positions.push(c + d * r);
            }
        }
        let idx = |k: u32, j: u32| base + (j - 1) * segments + k % segments;
        let emit = |s: &mut Self, a: u32, b: u32, c: u32| {
            if inward {
                s.tri(a, c, b)
            } else {
                s.tri(a, b, c)
            }
        };
        // Rings run counter-clockwise around +Y (phi increases towards −Z from +X).
        for k in 0..segments {
            emit(self, top, idx(k, 1), idx(k + 1, 1));
            emit(self, bottom, idx(k + 1, stacks - 1), idx(k, stacks - 1));
        }
        for j in 1..stacks - 1 {
            for k in 0..segments {
                let (p0, p1, p2, p3) = (idx(k, j), idx(k, j + 1), idx(k + 1, j + 1), idx(k + 1, j));
                emit(self, p0, p1, p2);
                emit(self, p0, p2, p3);
            }
        }
    }

    /// Merge vertices closer than `tol` (per coordinate, on a grid of that step) and drop the
    /// unused ones, so that surfaces built from separate primitives share edges by index.
    pub fn weld(&mut self, tol: f32) {
        let mut map: HashMap<[i64; 3], u32> = HashMap::new();
        let mut remap = Vec::with_capacity(self.positions.len());
        let mut out = Vec::new();
        for p in &self.positions {
            let k = (*p / tol).round().as_i64vec3().to_array();
            let id = *map.entry(k).or_insert_with(|| {
                out.push(*p);
                (out.len() - 1) as u32
            });
            remap.push(id);
        }
        for t in &mut self.triangles {
            *t = t.map(|v| remap[v as usize]);
        }
        self.positions = out;
    }

    /// Build the raw scene; for `up = Z` every point and camera is rotated by +90° about X
    /// (y → z, z → −y), which keeps the winding.
    pub fn finish(self, name: &str, up: UpAxis, mut cameras: Vec<Camera>) -> RawScene {
        let mut positions = self.positions;
        if up == UpAxis::Z {
            for p in &mut positions {
                *p = y_up_to_z_up(*p);
            }
            for c in &mut cameras {
                c.eye = y_up_to_z_up(c.eye);
                c.target = y_up_to_z_up(c.target);
                c.up = y_up_to_z_up(c.up);
            }
        }
        RawScene {
            name: name.to_string(),
            source: None,
            positions,
            triangles: self.triangles,
            tri_material: self.tri_material,
            tri_object: self.tri_object,
            objects: self.objects,
            materials: self.materials,
            sun: None,
            sky: None,
            cameras,
            up,
            two_sided: false,
            two_sided_materials: Vec::new(),
        }
    }
}

/// Rotation by +90° about X: the +Y-up frame of the generators to a +Z-up frame.
#[inline]
pub fn y_up_to_z_up(p: Vec3) -> Vec3 {
    Vec3::new(p.x, -p.z, p.y)
}

/// Camera named `name` with a 4:3 or square image as given.
pub fn camera(
    name: &str,
    eye: Vec3,
    target: Vec3,
    fov_deg: f32,
    width: u32,
    height: u32,
) -> Camera {
    Camera {
        name: name.to_string(),
        eye,
        target,
        up: Vec3::Y,
        fov_deg,
        width,
        height,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tri_normal(b: &MeshBuilder, t: usize) -> Vec3 {
        let [a, bb, c] = b.triangles[t].map(|v| b.positions[v as usize]);
        (bb - a).cross(c - a)
    }

    fn centroid(b: &MeshBuilder, t: usize) -> Vec3 {
        let [a, bb, c] = b.triangles[t].map(|v| b.positions[v as usize]);
        (a + bb + c) / 3.0
    }

    #[test]
    fn primitives_face_outwards() {
        let c = Vec3::new(0.3, -0.2, 0.7);
        let mut b = MeshBuilder::new();
        b.cuboid_subdiv(
            &Affine3A::from_rotation_y(0.4),
            Vec3::new(-1.0, -0.5, -0.3),
            Vec3::new(1.0, 0.5, 0.3),
            false,
            0,
            [3, 2, 1],
        );
        let nbox = b.num_triangles();
        assert_eq!(nbox, 2 * 2 * (3 * 2 + 2 + 3));
        for t in 0..nbox {
            assert!(tri_normal(&b, t).dot(centroid(&b, t)) > 0.0, "box tri {t}");
        }
        let mut b = MeshBuilder::new();
        b.cylinder(c, c + Vec3::new(0.2, 1.0, -0.1), 0.3, 12, 3, true);
        assert_eq!(b.num_triangles(), 12 * 3 * 2 + 2 * 12);
        let axis_mid = c + Vec3::new(0.1, 0.5, -0.05);
        for t in 0..b.num_triangles() {
            assert!(
                tri_normal(&b, t).dot(centroid(&b, t) - axis_mid) > 0.0,
                "cyl tri {t}"
            );
        }
        let mut b = MeshBuilder::new();
        b.sphere(c, 0.5, 10, 6, false);
        assert_eq!(b.num_triangles(), 2 * 10 + 2 * 10 * 4);
        for t in 0..b.num_triangles() {
            assert!(
                tri_normal(&b, t).dot(centroid(&b, t) - c) > 0.0,
                "sphere tri {t}"
            );
        }
        let mut b = MeshBuilder::new();
        b.cone(c, c + Vec3::Y, 0.3, 0.0, 8, 2, true);
        for t in 0..b.num_triangles() {
            let n = tri_normal(&b, t);
            assert!(n.length() > 0.0, "cone degenerate tri {t}");
            assert!(
                n.dot(centroid(&b, t) - (c + Vec3::Y * 0.3)) > 0.0,
                "cone tri {t}"
            );
        }
    }

    #[test]
    fn z_up_rotation_keeps_winding() {
        let p = [Vec3::ZERO, Vec3::X, Vec3::new(1.0, 0.0, -1.0)];
        let n = (p[1] - p[0]).cross(p[2] - p[0]);
        let q = p.map(y_up_to_z_up);
        let m = (q[1] - q[0]).cross(q[2] - q[0]);
        assert_eq!(n, Vec3::Y);
        assert_eq!(m, Vec3::Z);
    }
}
