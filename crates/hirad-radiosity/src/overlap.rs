//! Coplanar overlapping faces (a poster on a wall, two walls modelled through each other,
//! duplicated triangles; with two-sided surfaces also back-to-back ones). A ray meets one of
//! them where they overlap, but the solver would let both receive and emit there: that region
//! then sends and takes light twice, kernel sums pass 1 and closed cavities with such faces
//! amplify instead of absorbing. Each point of an overlap therefore belongs to one triangle: an
//! emitter's over a non-emitter's (a lamp panel flush with a ceiling shines), then that of the
//! smaller object (a detail lies on what carries it, however finely either is tessellated),
//! then the smaller triangle, then the lower id; the other's points there are *covered*: the
//! solver's kernels give them no light and take none from them. Parallel faces across a gap
//! too narrow to let light in (a board hung a millimetre off a wall) cover each other's sides
//! that face the gap: an element straddling the gap's edge is then lit as its open part is,
//! not at the mean over the dark part too. Points inside closed solids ([`ShutMasks`]) are
//! covered too.

use super::shut::ShutMasks;
use glam::{Vec2, Vec3};
use hirad_accel::cluster::ClusterTree;
use hirad_core::geom::{drop_axis, longest_edge, project, triangles_overlap, Aabb};
use hirad_scene::Scene;
use rayon::prelude::*;

/// For each triangle, the triangles that cover part of it, projected onto its plane.
#[derive(Clone, Debug, Default)]
pub struct Covers {
    offsets: Vec<u32>,
    ids: Vec<u32>,
    /// Per entry of `ids`: the covering triangle in the covered one's plane coordinates.
    shapes: Vec<[Vec2; 3]>,
    /// Per entry of `ids`: the normal of the covered side (the side facing a closed gap), or
    /// zero when both sides are covered (coplanar overlaps).
    sides: Vec<Vec3>,
    /// Per triangle: the coordinate its plane projection drops.
    axis: Vec<u8>,
    /// Per triangle: its grid in `grids` (`u32::MAX`: none, its entries are few).
    grid_of: Vec<u32>,
    grids: Vec<CoverGrid>,
    /// Entries (offsets into the triangle's range) per grid cell.
    items: Vec<u32>,
    /// The parts inside closed solids.
    shut: ShutMasks,
}

/// A triangle covered by many triangles (a wall under a row of pictures) finds the few a
/// point may lie under on a grid over its projection's box.
#[derive(Clone, Debug)]
struct CoverGrid {
    lo: Vec2,
    scale: Vec2,
    /// Range of cell `c` in `items`: `cells[c]..cells[c + 1]`.
    cells: [u32; GRID * GRID + 1],
}

/// Cells per side of a [`CoverGrid`].
const GRID: usize = 8;

/// Triangles with more entries than this get a [`CoverGrid`].
const GRID_MIN: usize = 8;

impl CoverGrid {
    /// Cell range (x0..=x1, y0..=y1) of the box `lo..hi`, clamped to the grid.
    fn span(&self, lo: Vec2, hi: Vec2) -> ((usize, usize), (usize, usize)) {
        let c = |q: Vec2| {
            let g = ((q - self.lo) * self.scale).floor();
            let f = |x: f32| (x.max(0.0) as usize).min(GRID - 1);
            (f(g.x), f(g.y))
        };
        let (a, b) = (c(lo), c(hi));
        ((a.0, b.0), (a.1, b.1))
    }
}

/// Normals closer than this (|cos| above `1 − PARALLEL`) make two triangles parallel.
const PARALLEL: f32 = 1e-5;

/// Widest closed gap between parallel faces, relative to the extent of the smaller of their
/// objects (its box's diagonal): a gap of width h and depth W lets in about (h/W)·ln(W/2h) of
/// the light on its opening area, under 1% at this ratio.
const GAP_REL: f32 = 1e-3;

/// Plane distance and overlap tolerance, relative to the larger triangle's longest edge.
const REL_TOL: f32 = 1e-4;

impl Covers {
    /// No overlaps.
    pub const EMPTY: Covers = Covers {
        offsets: Vec::new(),
        ids: Vec::new(),
        shapes: Vec::new(),
        sides: Vec::new(),
        axis: Vec::new(),
        grid_of: Vec::new(),
        grids: Vec::new(),
        items: Vec::new(),
        shut: ShutMasks::EMPTY,
    };

    /// Bytes of the overlaps, their grids and the shut masks.
    pub fn memory_bytes(&self) -> usize {
        (self.offsets.capacity()
            + self.ids.capacity()
            + self.grid_of.capacity()
            + self.items.capacity())
            * 4
            + self.shapes.capacity() * std::mem::size_of::<[Vec2; 3]>()
            + self.sides.capacity() * std::mem::size_of::<Vec3>()
            + self.axis.capacity()
            + self.grids.capacity() * std::mem::size_of::<CoverGrid>()
            + self.shut.memory_bytes()
    }

    /// Find the coplanar overlaps of `scene`, querying the bounding boxes of `tree`. One-sided
    /// triangles overlap only when they face the same way (back-to-back faces of a thin board
    /// each receive from their own side); two with a back face ([`Scene::has_back`] with
    /// `two_sided`) always do.
    pub fn build(scene: &Scene, tree: &ClusterTree, two_sided: bool) -> Covers {
        let n = scene.num_triangles();
        let object_area = scene.object_areas();
        let rank = |t: u32| {
            let t = t as usize;
            (
                !scene.material_of(t).is_emitter(),
                object_area[scene.tri_object[t] as usize],
                scene.areas[t],
            )
        };
        // Each object's extent (its box's diagonal) sets how narrow a gap is closed.
        let mut boxes = vec![Aabb::EMPTY; object_area.len()];
        for t in 0..n {
            boxes[scene.tri_object[t] as usize].grow_box(&scene.tri_bbox(t));
        }
        let extent: Vec<f32> = boxes.iter().map(|b| b.extent().length()).collect();
        let gap = |t: u32| GAP_REL * extent[scene.tri_object[t as usize] as usize];
        let back = |t: u32| scene.has_back(t as usize, two_sided);
        let per: Vec<Vec<(u32, Vec3)>> = (0..n)
            .into_par_iter()
            .map(|i| covering(scene, tree, i as u32, &back, &rank, &gap))
            .collect();
        let mut offsets = Vec::with_capacity(n + 1);
        let (mut ids, mut shapes, mut sides) = (Vec::new(), Vec::new(), Vec::new());
        let axis: Vec<u8> = scene.normals.iter().map(|&n| drop_axis(n) as u8).collect();
        let (mut grid_of, mut grids, mut items) = (vec![u32::MAX; n], Vec::new(), Vec::new());
        offsets.push(0);
        for (i, v) in per.into_iter().enumerate() {
            let first = ids.len();
            let a = axis[i] as usize;
            for (j, side) in v {
                shapes.push(scene.tri_vertices(j as usize).map(|p| project(p, a)));
                ids.push(j);
                sides.push(side);
            }
            offsets.push(ids.len() as u32);
            if ids.len() - first > GRID_MIN {
                let own = scene.tri_vertices(i).map(|p| project(p, a));
                grid_of[i] = grids.len() as u32;
                grids.push(cover_grid(&own, &shapes[first..], &mut items));
            }
        }
        tracing::debug!(
            "covers: {} triangles covered, {} entries, at most {} on one triangle",
            offsets.windows(2).filter(|w| w[1] > w[0]).count(),
            ids.len(),
            offsets.windows(2).map(|w| w[1] - w[0]).max().unwrap_or(0)
        );
        Covers {
            offsets,
            ids,
            shapes,
            sides,
            axis,
            grid_of,
            grids,
            items,
            shut: ShutMasks::build(scene, tree, scene.any_back(two_sided)),
        }
    }

    /// No triangle covers another.
    pub fn is_empty(&self) -> bool {
        self.ids.is_empty()
    }

    /// Triangles with a part under a coplanar one.
    pub fn covered_triangles(&self) -> usize {
        self.offsets.windows(2).filter(|w| w[1] > w[0]).count()
    }

    /// Triangles with a part inside a closed solid.
    pub fn shut_triangles(&self) -> usize {
        self.shut.shut_triangles()
    }

    /// Entries of triangle `tri` in `ids` and `shapes`.
    #[inline]
    fn range(&self, tri: u32) -> std::ops::Range<usize> {
        match self.offsets.get(tri as usize..tri as usize + 2) {
            Some(&[a, b]) => a as usize..b as usize,
            _ => 0..0,
        }
    }

    /// True when no part of triangle `tri` is covered or shut.
    pub fn all_open(&self, tri: u32) -> bool {
        self.range(tri).is_empty() && !self.shut.has_mask(tri)
    }

    /// The triangles covering parts of triangle `tri`.
    pub fn of(&self, tri: u32) -> &[u32] {
        &self.ids[self.range(tri)]
    }

    /// Share of the triangle `v` (a part of input triangle `tri`, its side facing `n`) that
    /// is not covered, from 64 stratified points (1 when no part of `tri` is).
    pub fn open_fraction(&self, tri: u32, n: Vec3, v: &[Vec3; 3]) -> f64 {
        if self.range(tri).is_empty() && !self.shut.has_mask(tri) {
            return 1.0;
        }
        let open = stratified(v).filter(|&p| !self.covered(tri, n, p)).count();
        open as f64 / 64.0
    }

    /// True when the triangle `v` (a part of input triangle `tri`) lies within one coplanar
    /// triangle that owns the place (up to 10⁻⁴ of its longest edge): a duplicated face
    /// under its original. Points a ray can reach between several owners do not count.
    pub fn within_coplanar_owner(&self, tri: u32, v: &[Vec3; 3]) -> bool {
        let axis = self.axis[tri as usize] as usize;
        let q = v.map(|p| project(p, axis));
        let tol = REL_TOL * longest_edge(v);
        self.range(tri).any(|k| {
            self.sides[k] == Vec3::ZERO && q.iter().all(|&p| inside_or_on(p, &self.shapes[k], tol))
        })
    }

    /// True when point `p` of triangle `tri`, on its side facing `n`, lies under a triangle
    /// that covers it or inside a closed solid.
    #[inline]
    pub fn covered(&self, tri: u32, n: Vec3, p: Vec3) -> bool {
        self.shut.shut(tri, p) || self.under(tri, n, p)
    }

    /// True when point `p` of triangle `tri` lies under a triangle that covers it: coplanar,
    /// or across a closed gap on its side facing `n`.
    #[inline]
    fn under(&self, tri: u32, n: Vec3, p: Vec3) -> bool {
        let r = self.range(tri);
        if r.is_empty() {
            return false;
        }
        let q = project(p, self.axis[tri as usize] as usize);
        let test = |k: usize| {
            let s = self.sides[k];
            (s == Vec3::ZERO || s.dot(n) > 0.0) && inside(q, &self.shapes[k])
        };
        match self.grid_of.get(tri as usize) {
            Some(&g) if g != u32::MAX => {
                let grid = &self.grids[g as usize];
                let ((x, _), (y, _)) = grid.span(q, q);
                let c = y * GRID + x;
                self.items[grid.cells[c] as usize..grid.cells[c + 1] as usize]
                    .iter()
                    .any(|&k| test(r.start + k as usize))
            }
            _ => r.into_iter().any(test),
        }
    }
}

/// The triangles covering part of triangle `i`, each with the normal of the side of `i` it
/// covers (zero: both sides). Coplanar triangles (facing the same way unless one of them has a
/// back face, `back`) cover `i` on both sides where they overlap it with positive area, when
/// they own the overlap: lower `rank` (emitter first, then object area, then triangle area), or
/// equal rank and a lower id. A parallel triangle across a closed gap (no farther than the
/// smaller of `gap(i)` and `gap(j)`, in front of `i`, or behind it when `i` has a back face)
/// covers the side of `i` that faces it.
fn covering(
    scene: &Scene,
    tree: &ClusterTree,
    i: u32,
    back: &(impl Fn(u32) -> bool + Sync),
    rank: &(impl Fn(u32) -> (bool, f64, f32) + Sync),
    gap: &(impl Fn(u32) -> f32 + Sync),
) -> Vec<(u32, Vec3)> {
    let vi = scene.tri_vertices(i as usize);
    let ni = scene.normals[i as usize];
    if scene.areas[i as usize] <= 0.0 {
        return Vec::new();
    }
    let ri = rank(i);
    let edge = longest_edge;
    let bb = scene.tri_bbox(i as usize);
    let grow = (REL_TOL * edge(&vi)).max(gap(i));
    let (lo, hi) = (bb.min - Vec3::splat(grow), bb.max + Vec3::splat(grow));
    let mut out = Vec::new();
    tree.any_surface_near(lo, hi, |j| {
        if j == i || scene.areas[j as usize] <= 0.0 {
            return false;
        }
        let nj = scene.normals[j as usize];
        let c = ni.dot(nj);
        if c.abs() < 1.0 - PARALLEL {
            return false;
        }
        let vj = scene.tri_vertices(j as usize);
        let tol = REL_TOL * edge(&vi).max(edge(&vj));
        let d = vj.map(|p| ni.dot(p - vi[0]));
        let side = if d.iter().all(|x| x.abs() <= tol) {
            let owns = match rank(j).partial_cmp(&ri) {
                Some(std::cmp::Ordering::Less) => true,
                Some(std::cmp::Ordering::Equal) => j < i,
                _ => false,
            };
            if !owns || (c < 0.0 && !back(i) && !back(j)) {
                return false;
            }
            Vec3::ZERO
        } else {
            let g = gap(i).min(gap(j));
            if d.iter().all(|&x| x > 0.0 && x <= g) {
                ni
            } else if back(i) && d.iter().all(|&x| x < 0.0 && x >= -g) {
                -ni
            } else {
                return false;
            }
        };
        let axis = drop_axis(ni);
        if triangles_overlap(
            &vi.map(|p| project(p, axis)),
            &vj.map(|p| project(p, axis)),
            tol,
        ) {
            out.push((j, side));
        }
        false
    });
    out.sort_unstable_by_key(|e| e.0);
    out
}

/// The coordinate dropped when projecting onto a plane of normal `n` (its largest component).
/// The grid over the box of `own` (a triangle in its plane coordinates) listing in `items`
/// the entries of `shapes` whose boxes meet each cell.
fn cover_grid(own: &[Vec2; 3], shapes: &[[Vec2; 3]], items: &mut Vec<u32>) -> CoverGrid {
    let lo = own[0].min(own[1]).min(own[2]);
    let hi = own[0].max(own[1]).max(own[2]);
    let mut grid = CoverGrid {
        lo,
        scale: Vec2::splat(GRID as f32) / (hi - lo).max(Vec2::splat(f32::MIN_POSITIVE)),
        cells: [0; GRID * GRID + 1],
    };
    let mut per: Vec<Vec<u32>> = vec![Vec::new(); GRID * GRID];
    for (k, v) in shapes.iter().enumerate() {
        let ((x0, x1), (y0, y1)) = grid.span(v[0].min(v[1]).min(v[2]), v[0].max(v[1]).max(v[2]));
        for y in y0..=y1 {
            for x in x0..=x1 {
                per[y * GRID + x].push(k as u32);
            }
        }
    }
    for (c, list) in per.into_iter().enumerate() {
        grid.cells[c] = items.len() as u32;
        items.extend(list);
    }
    grid.cells[GRID * GRID] = items.len() as u32;
    grid
}

/// 64 stratified points on the triangle `v` (8 × 8 strata of the square mapped by the square
/// root warp).
fn stratified(v: &[Vec3; 3]) -> impl Iterator<Item = Vec3> + '_ {
    (0..64).map(move |k| {
        let (u1, u2) = (((k / 8) as f32 + 0.5) / 8.0, ((k % 8) as f32 + 0.5) / 8.0);
        let s = u1.sqrt();
        v[0] * (1.0 - s) + v[1] * (s * (1.0 - u2)) + v[2] * (s * u2)
    })
}

/// `q` inside the triangle `v` or within `tol` of it (either orientation).
fn inside_or_on(q: Vec2, v: &[Vec2; 3], tol: f32) -> bool {
    let d = |a: Vec2, b: Vec2| (b - a).perp_dot(q - a) / (b - a).length().max(f32::MIN_POSITIVE);
    let e = [d(v[0], v[1]), d(v[1], v[2]), d(v[2], v[0])];
    e.iter().all(|&x| x >= -tol) || e.iter().all(|&x| x <= tol)
}

/// Point `q` strictly inside triangle `v` (either winding).
fn inside(q: Vec2, v: &[Vec2; 3]) -> bool {
    let s = |a: Vec2, b: Vec2| (b - a).perp_dot(q - a);
    let (d0, d1, d2) = (s(v[0], v[1]), s(v[1], v[2]), s(v[2], v[0]));
    (d0 > 0.0 && d1 > 0.0 && d2 > 0.0) || (d0 < 0.0 && d1 < 0.0 && d2 < 0.0)
}

#[cfg(test)]
mod tests {
    use super::*;
    use hirad_accel::cluster::{ClusterConfig, Strategy};
    use hirad_core::rng::SplitMix64;
    use hirad_scene::{Material, RawScene, SceneOptions};

    /// A 4 × 4 floor (one triangle) under 16 coplanar tiles of 0.4 × 0.4 (two triangles each,
    /// another object, so they own the overlap): the floor has 32 covering entries and a grid;
    /// a point is covered exactly when it lies inside a tile.
    #[test]
    fn many_covers_are_found_on_the_grid() {
        let mut raw = RawScene {
            name: "tiles".into(),
            positions: vec![
                Vec3::new(0.0, 0.0, 0.0),
                Vec3::new(8.0, 0.0, 0.0),
                Vec3::new(0.0, 8.0, 0.0),
            ],
            triangles: vec![[0, 1, 2]],
            tri_material: vec![0],
            tri_object: vec![0],
            objects: vec!["floor".into(), "tiles".into()],
            materials: vec![Material::diffuse("grey", Vec3::splat(0.5))],
            ..Default::default()
        };
        let mut tiles = Vec::new();
        for i in 0..4 {
            for j in 0..4 {
                let (x, y) = (0.3 + i as f32, 0.2 + j as f32);
                tiles.push((x, y));
                let b = raw.positions.len() as u32;
                raw.positions.extend([
                    Vec3::new(x, y, 0.0),
                    Vec3::new(x + 0.4, y, 0.0),
                    Vec3::new(x + 0.4, y + 0.4, 0.0),
                    Vec3::new(x, y + 0.4, 0.0),
                ]);
                raw.triangles.extend([[b, b + 1, b + 2], [b, b + 2, b + 3]]);
                raw.tri_material.extend([0, 0]);
                raw.tri_object.extend([1, 1]);
            }
        }
        let scene = Scene::from_raw(raw, &SceneOptions::default()).unwrap();
        let tree = ClusterTree::build(&scene, Strategy::Kdt, &ClusterConfig::default());
        let covers = Covers::build(&scene, &tree, false);
        assert_eq!(covers.of(0).len(), 32);
        assert!(covers.grid_of[0] != u32::MAX, "the floor has a grid");
        let mut rng = SplitMix64::new(7);
        let (mut inside_tiles, mut outside) = (0, 0);
        for _ in 0..20_000 {
            let p = Vec3::new(rng.next_f32() * 4.2, rng.next_f32() * 4.2, 0.0);
            let d = |x: f32, lo: f32| (x - lo).min(lo + 0.4 - x);
            let under = tiles
                .iter()
                .map(|&(x, y)| d(p.x, x).min(d(p.y, y)))
                .fold(f32::MIN, f32::max);
            if under.abs() < 1e-4 {
                continue;
            }
            assert_eq!(covers.covered(0, Vec3::Z, p), under > 0.0, "{p}");
            if under > 0.0 {
                inside_tiles += 1;
            } else {
                outside += 1;
            }
        }
        assert!(inside_tiles > 1000 && outside > 1000);
    }

    #[test]
    fn points_inside_a_triangle() {
        let t = |p: [[f32; 2]; 3]| p.map(|q| Vec2::new(q[0], q[1]));
        let c = t([[0.1, 0.1], [0.3, 0.1], [0.1, 0.3]]);
        assert!(inside(Vec2::new(0.15, 0.15), &c));
        assert!(!inside(Vec2::new(0.5, 0.4), &c));
        // On an edge: not strictly inside, but within any tolerance.
        let on = Vec2::new(0.2, 0.1);
        assert!(!inside(on, &c) && inside_or_on(on, &c, 1e-6));
        assert!(!inside_or_on(Vec2::new(0.2, 0.09), &c, 1e-3));
    }
}
