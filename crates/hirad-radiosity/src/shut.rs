//! Parts of one-sided triangles that lie inside closed solids (a wall running into another
//! wall, a floor under a box without a bottom face). No light reaches such points and none
//! leaves them, but an element that straddles the solid's boundary would average zero
//! irradiance over its shut part into the radiosity of its open part, and emit that
//! radiosity from the shut part into the solid, where it is lost. Shut points are therefore
//! left out of the kernels like covered ones ([`super::overlap`]).
//!
//! A point is shut when rays along its normal and tilted 60° from it at six azimuths all hit
//! a back face first; a back face met at the same distance as another surface's front (a
//! solid pressed on a wall or a floor) counts, as long as one ray meets a back face alone
//! (from inside a room of zero-thickness boards every ray meets such pairs). Each triangle
//! gets a mask: a quadtree in the same 4-way midpoint
//! subdivision as its surface elements, split where its probe points disagree.
//! Two-sided solves have no masks: there the inside of a solid is a cavity that receives.

use glam::Vec3;
use hirad_accel::cluster::ClusterTree;
use hirad_accel::ray::RayCaster;
use hirad_scene::Scene;
use rayon::prelude::*;

/// Mask codes: an open cell, a shut cell, or `SPLIT + i` with children `i..i+4`.
const OPEN: u32 = 0;
const SHUT: u32 = 1;
const SPLIT: u32 = 2;

/// Cells are split without probing down to edges of this fraction of the scene's diagonal,
/// so that a solid standing inside a large triangle meets some probe.
const CELL_REL: f32 = 1.0 / 32.0;

/// Mixed cells split down to edges of this fraction of the scene's diagonal.
const FINE_REL: f32 = 1.0 / 512.0;

/// Deepest mask level in any case (cells of 1/256 of the triangle's edges).
const MAX_DEPTH: u32 = 8;

/// Probe points of a cell in its local coordinates (near the corners and the centroid).
const PROBES: [(f32, f32); 4] = [
    (1.0 / 3.0, 1.0 / 3.0),
    (0.05, 0.05),
    (0.9, 0.05),
    (0.05, 0.9),
];

/// Per-triangle shut masks.
#[derive(Clone, Debug, Default)]
pub struct ShutMasks {
    /// Per triangle: its range in `codes` (empty when wholly open).
    offsets: Vec<u32>,
    codes: Vec<u32>,
    /// Per triangle with a mask: `v0` and the dual edge vectors giving barycentric
    /// coordinates `b1 = d1·(p − v0)`, `b2 = d2·(p − v0)`.
    frames: Vec<[Vec3; 3]>,
    frame_of: Vec<u32>,
}

impl ShutMasks {
    /// No masks.
    pub const EMPTY: ShutMasks = ShutMasks {
        offsets: Vec::new(),
        codes: Vec::new(),
        frames: Vec::new(),
        frame_of: Vec::new(),
    };

    /// Bytes of the masks' arrays.
    pub fn memory_bytes(&self) -> usize {
        (self.offsets.capacity() + self.codes.capacity() + self.frame_of.capacity()) * 4
            + self.frames.capacity() * std::mem::size_of::<[Vec3; 3]>()
    }

    /// Masks of every triangle of a one-sided `scene` (none when `two_sided`).
    pub fn build(scene: &Scene, tree: &ClusterTree, two_sided: bool) -> ShutMasks {
        let n = scene.num_triangles();
        if two_sided || n == 0 {
            return ShutMasks::default();
        }
        let t0 = std::time::Instant::now();
        let caster = RayCaster::new(scene, tree);
        let diag = scene.bbox.extent().length().max(1e-12);
        let tmin = 1e-5 * diag;
        let per: Vec<Vec<u32>> = (0..n)
            .into_par_iter()
            .map(|t| {
                let mut codes = vec![OPEN];
                let v = scene.tri_vertices(t);
                let nrm = scene.normals[t];
                if scene.areas[t] > 0.0 && nrm.is_finite() {
                    let probe = |p: Vec3| shut_point(scene, &caster, p, nrm, tmin);
                    let edge = (0..3)
                        .map(|k| (v[k] - v[(k + 1) % 3]).length())
                        .fold(0.0, f32::max);
                    let depth = |rel: f32| {
                        (edge / (rel * diag))
                            .max(1.0)
                            .log2()
                            .ceil()
                            .min(MAX_DEPTH as f32) as u32
                    };
                    codes[0] = cell(&probe, v, (0, depth(CELL_REL), depth(FINE_REL)), &mut codes);
                }
                if codes == [OPEN] {
                    Vec::new()
                } else {
                    codes
                }
            })
            .collect();
        let mut m = ShutMasks {
            offsets: Vec::with_capacity(n + 1),
            frame_of: vec![u32::MAX; n],
            ..Default::default()
        };
        m.offsets.push(0);
        for (t, c) in per.into_iter().enumerate() {
            if !c.is_empty() {
                let v = scene.tri_vertices(t);
                let (e1, e2) = (v[1] - v[0], v[2] - v[0]);
                let (d11, d12, d22) = (e1.dot(e1), e1.dot(e2), e2.dot(e2));
                let den = d11 * d22 - d12 * d12;
                let d1 = (e1 * d22 - e2 * d12) / den;
                let d2 = (e2 * d11 - e1 * d12) / den;
                m.frame_of[t] = m.frames.len() as u32;
                m.frames.push([v[0], d1, d2]);
                m.codes.extend(c);
            }
            m.offsets.push(m.codes.len() as u32);
        }
        tracing::debug!(
            "shut masks: {} triangles, {} cells, {:.2} s",
            m.frames.len(),
            m.codes.len(),
            t0.elapsed().as_secs_f64()
        );
        m
    }

    /// Triangles with a shut part.
    pub fn shut_triangles(&self) -> usize {
        self.frames.len()
    }

    /// Triangle `tri` has a shut part.
    #[inline]
    pub fn has_mask(&self, tri: u32) -> bool {
        self.frame_of
            .get(tri as usize)
            .is_some_and(|&f| f != u32::MAX)
    }

    /// True when point `p` of triangle `tri` lies in a shut cell of its mask.
    #[inline]
    pub fn shut(&self, tri: u32, p: Vec3) -> bool {
        if !self.has_mask(tri) {
            return false;
        }
        let f = self.frame_of[tri as usize];
        let [o, d1, d2] = self.frames[f as usize];
        let q = p - o;
        let (mut c1, mut c2) = (d1.dot(q).clamp(0.0, 1.0), d2.dot(q).clamp(0.0, 1.0));
        let codes = &self.codes[self.offsets[tri as usize] as usize..];
        let mut code = codes[0];
        while code >= SPLIT {
            let first = (code - SPLIT) as usize;
            let c0 = 1.0 - c1 - c2;
            let (k, n1, n2) = if c0 >= 0.5 {
                (0, 2.0 * c1, 2.0 * c2)
            } else if c1 >= 0.5 {
                (1, 2.0 * c1 - 1.0, 2.0 * c2)
            } else if c2 >= 0.5 {
                (2, 2.0 * c1, 2.0 * c2 - 1.0)
            } else {
                (3, 2.0 * (c1 + c2) - 1.0, 1.0 - 2.0 * c1)
            };
            (c1, c2) = (n1, n2);
            code = codes[first + k];
        }
        code == SHUT
    }
}

/// The code of the cell `v` (world corners, in the frame order of [`Elements::subdivide`])
/// at `depth`, appending its children's codes to `codes` when it splits; cells above
/// `min_depth` split without probes, mixed cells down to `max_depth`.
///
/// [`Elements::subdivide`]: super::element::Elements::subdivide
fn cell(
    probe: &impl Fn(Vec3) -> bool,
    v: [Vec3; 3],
    (depth, min_depth, max_depth): (u32, u32, u32),
    codes: &mut Vec<u32>,
) -> u32 {
    if depth >= min_depth {
        let at = |(c1, c2): (f32, f32)| v[0] + (v[1] - v[0]) * c1 + (v[2] - v[0]) * c2;
        let shut = PROBES.map(|c| probe(at(c)));
        let all = shut.iter().all(|&s| s);
        if all || !shut.iter().any(|&s| s) {
            return if all { SHUT } else { OPEN };
        }
        if depth >= max_depth {
            // The centroid decides a mixed cell at the finest level.
            return if shut[0] { SHUT } else { OPEN };
        }
    }
    let [a, b, c] = v;
    let (ab, bc, ca) = ((a + b) * 0.5, (b + c) * 0.5, (c + a) * 0.5);
    let first = codes.len();
    codes.extend([OPEN; 4]);
    for (k, t) in [[a, ab, ca], [ab, b, bc], [ca, bc, c], [ab, bc, ca]]
        .into_iter()
        .enumerate()
    {
        codes[first + k] = cell(probe, t, (depth + 1, min_depth, max_depth), codes);
    }
    // Four equal leaf cells make one.
    let kids = &codes[first..first + 4];
    if kids[0] < SPLIT && kids.iter().all(|&k| k == kids[0]) {
        let code = kids[0];
        codes.truncate(first);
        return code;
    }
    SPLIT + first as u32
}

/// Rays from `p` along normal `n` and tilted 60° from it at six azimuths all meet a back face
/// first (one ray that does not is enough to open the point: a cloud of loose one-sided
/// faces is not a solid). A front face with a back face at the same distance is a solid
/// pressed against another surface (a box's side on a wall) and counts as a back face, but at
/// least one ray must meet a back face alone: zero-thickness boards (two faces back to back)
/// show the same pair from outside.
fn shut_point(scene: &Scene, caster: &RayCaster, p: Vec3, n: Vec3, tmin: f32) -> bool {
    let (t, b) = n.any_orthonormal_pair();
    // None: open; Some(true): a back face alone; Some(false): a pressed pair.
    let back = |d: Vec3| -> Option<bool> {
        let h = caster.closest(p, d, tmin, f32::INFINITY)?;
        let is_back = |tri: u32| scene.normals[tri as usize].dot(d) > 0.0;
        // A face of the other kind at the same distance (either may come first).
        let twin = |want_back: bool| {
            caster.occluded_except(p, d, ((h.t - tmin).max(tmin), h.t + tmin), &|tri| {
                is_back(tri) != want_back
            })
        };
        if is_back(h.tri) {
            Some(!twin(false))
        } else {
            twin(true).then_some(false)
        }
    };
    let mut alone = false;
    for k in 0..7 {
        let d = if k == 0 {
            n
        } else {
            let phi = (k - 1) as f32 * std::f32::consts::FRAC_PI_3;
            (n * 0.5 + (t * phi.cos() + b * phi.sin()) * 0.866_025_4).normalize()
        };
        match back(d) {
            None => return false,
            Some(a) => alone |= a,
        }
    }
    alone
}

#[cfg(test)]
mod tests {
    use super::*;
    use hirad_accel::cluster::{ClusterConfig, Strategy};
    use hirad_scene::{Material, RawScene, SceneOptions};

    /// A floor quad with a box (outward faces) on its middle third, open-bottomed or with a
    /// bottom face lying on the floor.
    fn floor_under_box(bottom: bool) -> Scene {
        let mut raw = RawScene {
            name: "box".into(),
            materials: vec![Material::diffuse("white", Vec3::splat(0.5))],
            objects: vec!["all".into()],
            ..Default::default()
        };
        raw.positions = vec![
            Vec3::new(0.0, 0.0, 0.0),
            Vec3::new(3.0, 0.0, 0.0),
            Vec3::new(3.0, 0.0, 3.0),
            Vec3::new(0.0, 0.0, 3.0),
        ];
        // Box x, z ∈ [1, 2], y ∈ [0, 1]: vertices 4..12.
        for y in [0.0, 1.0] {
            for (x, z) in [(1.0, 1.0), (2.0, 1.0), (2.0, 2.0), (1.0, 2.0)] {
                raw.positions.push(Vec3::new(x, y, z));
            }
        }
        // Floor and box top face +y; the sides face out.
        raw.triangles = vec![[0, 2, 1], [0, 3, 2], [8, 10, 9], [8, 11, 10]];
        for k in 0..4u32 {
            let (a, b) = (4 + k, 4 + (k + 1) % 4);
            raw.triangles.push([a, b + 4, b]);
            raw.triangles.push([a, a + 4, b + 4]);
        }
        if bottom {
            raw.triangles.push([4, 5, 6]);
            raw.triangles.push([4, 6, 7]);
        }
        raw.tri_material = vec![0; raw.triangles.len()];
        raw.tri_object = vec![0; raw.triangles.len()];
        Scene::from_raw(raw, &SceneOptions::default()).expect("scene")
    }

    #[test]
    fn floor_under_a_box_is_shut_and_beside_it_open() {
        for bottom in [false, true] {
            floor_under_box_case(bottom);
        }
    }

    fn floor_under_box_case(bottom: bool) {
        let scene = floor_under_box(bottom);
        let centre = Vec3::new(1.5, 0.5, 1.5);
        for t in 2..scene.num_triangles() {
            let out = scene.tri_centroid(t) - centre;
            assert!(scene.normals[t].dot(out) > 0.0, "box face {t} faces out");
        }
        let tree = ClusterTree::build(&scene, Strategy::Kdt, &ClusterConfig::default());
        let m = ShutMasks::build(&scene, &tree, false);
        assert!(m.shut(0, Vec3::new(1.6, 0.0, 1.4)), "bottom {bottom}");
        assert_eq!(m.shut_triangles(), 2, "the two floor triangles");
        // Sample the floor on a grid: shut exactly under the box, up to the mask's cells.
        let (mut wrong, mut total) = (0, 0);
        for i in 0..60 {
            for j in 0..60 {
                let p = Vec3::new((i as f32 + 0.5) / 20.0, 0.0, (j as f32 + 0.5) / 20.0);
                let tri = if p.x > p.z { 0 } else { 1 };
                let inside = (1.0..2.0).contains(&p.x) && (1.0..2.0).contains(&p.z);
                let near_edge = [p.x - 1.0, p.x - 2.0, p.z - 1.0, p.z - 2.0]
                    .iter()
                    .any(|d| d.abs() < 3.0 / 64.0 * 1.5);
                total += 1;
                if m.shut(tri, p) != inside && !near_edge {
                    wrong += 1;
                }
            }
        }
        assert_eq!(wrong, 0, "of {total} floor points");
        assert!(ShutMasks::build(&scene, &tree, true).shut_triangles() == 0);
    }

    /// A scene of quads `(corner, u, v)`, each facing `u × v`.
    fn quads(q: &[(Vec3, Vec3, Vec3)]) -> Scene {
        let mut raw = RawScene {
            name: "quads".into(),
            materials: vec![Material::diffuse("white", Vec3::splat(0.5))],
            objects: vec!["all".into()],
            ..Default::default()
        };
        for &(c, u, v) in q {
            let i = raw.positions.len() as u32;
            raw.positions.extend([c, c + u, c + u + v, c + v]);
            raw.triangles.extend([[i, i + 1, i + 2], [i, i + 2, i + 3]]);
        }
        raw.tri_material = vec![0; raw.triangles.len()];
        raw.tri_object = vec![0; raw.triangles.len()];
        Scene::from_raw(raw, &SceneOptions::default()).expect("scene")
    }

    /// The six faces of the box `[lo, hi]`, facing out.
    fn box_out(lo: Vec3, hi: Vec3) -> Vec<(Vec3, Vec3, Vec3)> {
        let d = hi - lo;
        let (x, y, z) = (Vec3::X * d.x, Vec3::Y * d.y, Vec3::Z * d.z);
        vec![
            (lo, x, z),
            (lo + y, z, x),
            (lo, z, y),
            (lo + x, y, z),
            (lo, y, x),
            (lo + z, x, y),
        ]
    }

    /// A closed box pressed into a corner: its bottom on the floor, one side on a wall. The
    /// rays from under it that leave through the pressed side meet the wall's front and the
    /// box's back at the same distance; those points are inside the box all the same.
    #[test]
    fn a_box_pressed_on_floor_and_wall_shuts_both_under_it() {
        let mut q = vec![
            (Vec3::ZERO, Vec3::Z * 3.0, Vec3::X * 3.0),
            (Vec3::X, Vec3::Y * 3.0, Vec3::Z * 3.0),
        ];
        q.extend(box_out(Vec3::new(1.0, 0.0, 1.0), Vec3::new(2.0, 1.0, 2.0)));
        let scene = quads(&q);
        assert!(scene.normals[0].y > 0.9 && scene.normals[2].x > 0.9);
        let tree = ClusterTree::build(&scene, Strategy::Kdt, &ClusterConfig::default());
        let m = ShutMasks::build(&scene, &tree, false);
        let (mut wrong, mut total) = (0, 0);
        for i in 0..20 {
            for j in 0..20 {
                let (a, b) = (0.05 + 0.9 * i as f32 / 19.0, 0.05 + 0.9 * j as f32 / 19.0);
                // Floor under the box, and the wall behind it.
                let floor = Vec3::new(1.0 + a, 0.0, 1.0 + b);
                let wall = Vec3::new(1.0, a, 1.0 + b);
                let ft = (0..2).find(|&t| in_tri(&scene, t, floor)).unwrap();
                let wt = (2..4).find(|&t| in_tri(&scene, t, wall)).unwrap();
                total += 2;
                wrong += !m.shut(ft, floor) as u32 + !m.shut(wt, wall) as u32;
            }
        }
        assert_eq!(wrong, 0, "of {total} points under the box");
        // Beside the box the floor and the wall stay open.
        assert!(!m.shut(0, Vec3::new(2.5, 0.0, 0.5)) && !m.shut(1, Vec3::new(2.5, 0.0, 2.7)));
    }

    /// A closed room whose walls are zero-thickness boards (an inward and an outward face
    /// back to back): every ray from inside meets such a pair, and nothing is shut.
    #[test]
    fn a_room_of_thin_boards_shuts_nothing() {
        let mut q = box_out(Vec3::ZERO, Vec3::splat(3.0));
        let inward: Vec<_> = q.iter().map(|&(c, u, v)| (c, v, u)).collect();
        q.extend(inward);
        q.extend(box_out(Vec3::splat(1.0), Vec3::splat(1.5)));
        let scene = quads(&q);
        let tree = ClusterTree::build(&scene, Strategy::Kdt, &ClusterConfig::default());
        let m = ShutMasks::build(&scene, &tree, false);
        assert_eq!(m.shut_triangles(), 0);
    }

    fn in_tri(scene: &Scene, t: u32, p: Vec3) -> bool {
        let [a, b, c] = scene.tri_vertices(t as usize);
        let n = (b - a).cross(c - a);
        [(a, b), (b, c), (c, a)]
            .iter()
            .all(|&(u, v)| (v - u).cross(p - u).dot(n) >= -1e-6)
    }
}
