//! Geometry primitives shared by every module: axis-aligned boxes and triangle helpers.

use glam::{Vec2, Vec3};
use serde::{Deserialize, Serialize};

/// Axis-aligned bounding box. The empty box has `min = +inf`, `max = -inf`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Aabb {
    /// Lowest corner.
    pub min: Vec3,
    /// Highest corner.
    pub max: Vec3,
}

impl Default for Aabb {
    fn default() -> Self {
        Self::EMPTY
    }
}

impl Aabb {
    /// The empty box (identity of [`Aabb::union`]).
    pub const EMPTY: Aabb = Aabb {
        min: Vec3::splat(f32::INFINITY),
        max: Vec3::splat(f32::NEG_INFINITY),
    };

    /// Box from its corners.
    #[inline]
    pub fn new(min: Vec3, max: Vec3) -> Self {
        Self { min, max }
    }

    /// Tight box of a set of points.
    pub fn from_points<'a>(pts: impl IntoIterator<Item = &'a Vec3>) -> Self {
        let mut b = Self::EMPTY;
        for p in pts {
            b.grow(*p);
        }
        b
    }

    /// True when the box contains nothing.
    #[inline]
    pub fn is_empty(&self) -> bool {
        self.min.x > self.max.x || self.min.y > self.max.y || self.min.z > self.max.z
    }

    /// Grow to contain a point.
    #[inline]
    pub fn grow(&mut self, p: Vec3) {
        self.min = self.min.min(p);
        self.max = self.max.max(p);
    }

    /// Grow to contain another box.
    #[inline]
    pub fn grow_box(&mut self, b: &Aabb) {
        self.min = self.min.min(b.min);
        self.max = self.max.max(b.max);
    }

    /// Smallest box containing both.
    #[inline]
    pub fn union(&self, b: &Aabb) -> Aabb {
        Aabb::new(self.min.min(b.min), self.max.max(b.max))
    }

    /// Intersection (possibly empty).
    #[inline]
    pub fn intersection(&self, b: &Aabb) -> Aabb {
        Aabb::new(self.min.max(b.min), self.max.min(b.max))
    }

    /// Edge lengths (zero for the empty box).
    #[inline]
    pub fn extent(&self) -> Vec3 {
        if self.is_empty() {
            Vec3::ZERO
        } else {
            self.max - self.min
        }
    }

    /// Centre point.
    #[inline]
    pub fn center(&self) -> Vec3 {
        (self.min + self.max) * 0.5
    }

    /// Longest edge length: `size()` of `clustering.md`.
    #[inline]
    pub fn size(&self) -> f32 {
        self.extent().max_element()
    }

    /// Index (0, 1, 2) of the longest axis; ties go to the lowest index.
    #[inline]
    pub fn longest_axis(&self) -> usize {
        let e = self.extent();
        if e.x >= e.y && e.x >= e.z {
            0
        } else if e.y >= e.z {
            1
        } else {
            2
        }
    }

    /// Volume (0 for empty or flat boxes).
    #[inline]
    pub fn volume(&self) -> f32 {
        let e = self.extent();
        e.x * e.y * e.z
    }

    /// Volume in f64 (for sums over many boxes).
    #[inline]
    pub fn volume_f64(&self) -> f64 {
        let e = self.extent();
        e.x as f64 * e.y as f64 * e.z as f64
    }

    /// Surface area (0 for the empty box).
    #[inline]
    pub fn surface_area(&self) -> f32 {
        let e = self.extent();
        2.0 * (e.x * e.y + e.y * e.z + e.z * e.x)
    }

    /// True when `p` lies inside (boundary included).
    #[inline]
    pub fn contains_point(&self, p: Vec3) -> bool {
        p.cmpge(self.min).all() && p.cmple(self.max).all()
    }

    /// True when `b` lies inside this box, allowing a relative slack `rel` of this box's size
    /// (plus a tiny absolute slack) for f32 rounding.
    pub fn contains_box(&self, b: &Aabb, rel: f32) -> bool {
        if b.is_empty() {
            return true;
        }
        let scale = self
            .min
            .abs()
            .max(self.max.abs())
            .max_element()
            .max(self.size());
        let slack = rel * scale + f32::MIN_POSITIVE;
        (b.min + Vec3::splat(slack)).cmpge(self.min).all()
            && (b.max - Vec3::splat(slack)).cmple(self.max).all()
    }

    /// Box grown to a cube of edge `size()` with the same centre.
    pub fn cube(&self) -> Aabb {
        let h = Vec3::splat(self.size() * 0.5);
        let c = self.center();
        Aabb::new(c - h, c + h)
    }
}

/// Area of the triangle (a, b, c).
#[inline]
pub fn triangle_area(a: Vec3, b: Vec3, c: Vec3) -> f32 {
    0.5 * (b - a).cross(c - a).length()
}

/// Length of the longest edge of triangle `v`.
#[inline]
pub fn longest_edge(v: &[Vec3; 3]) -> f32 {
    (v[1] - v[0])
        .length()
        .max((v[2] - v[1]).length())
        .max((v[0] - v[2]).length())
}

/// Area of the triangle (a, b, c) computed in f64.
#[inline]
pub fn triangle_area_f64(a: Vec3, b: Vec3, c: Vec3) -> f64 {
    let a = a.as_dvec3();
    let b = b.as_dvec3();
    let c = c.as_dvec3();
    0.5 * (b - a).cross(c - a).length()
}

/// The coordinate a plane of normal `n` is projected along: that of `n`'s largest component,
/// so that the projection keeps the most area.
#[inline]
pub fn drop_axis(n: Vec3) -> usize {
    let a = n.abs();
    if a.x >= a.y && a.x >= a.z {
        0
    } else if a.y >= a.z {
        1
    } else {
        2
    }
}

/// `p` projected along coordinate `axis` ([`drop_axis`]).
#[inline]
pub fn project(p: Vec3, axis: usize) -> Vec2 {
    match axis {
        0 => Vec2::new(p.y, p.z),
        1 => Vec2::new(p.z, p.x),
        _ => Vec2::new(p.x, p.y),
    }
}

/// Two triangles of one plane, projected ([`project`]), overlap by more than `tol` along every
/// separating axis (their edge normals): touching along an edge or a corner, or a degenerate
/// edge, is not an overlap.
pub fn triangles_overlap(a: &[Vec2; 3], b: &[Vec2; 3], tol: f32) -> bool {
    for tri in [a, b] {
        for e in 0..3 {
            let d = tri[(e + 1) % 3] - tri[e];
            let axis = Vec2::new(-d.y, d.x);
            let len = axis.length();
            if len <= 0.0 {
                return false;
            }
            let axis = axis / len;
            let span = |t: &[Vec2; 3]| {
                let p = t.map(|v| v.dot(axis));
                (p[0].min(p[1]).min(p[2]), p[0].max(p[1]).max(p[2]))
            };
            let (a0, a1) = span(a);
            let (b0, b1) = span(b);
            if a1.min(b1) - a0.max(b0) <= tol {
                return false;
            }
        }
    }
    true
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn triangles_overlap_in_their_plane_not_along_a_shared_edge() {
        let v = |x: f32, y: f32| Vec2::new(x, y);
        let a = [v(0.0, 0.0), v(1.0, 0.0), v(1.0, 1.0)];
        for (b, overlap, what) in [
            (
                [v(0.0, 0.0), v(1.0, 1.0), v(0.0, 1.0)],
                false,
                "the square's other half",
            ),
            ([a[1], a[2], a[0]], true, "itself in another vertex order"),
            (
                [v(0.0, 0.0), v(1.0, 0.0), v(0.0, 1.0)],
                true,
                "the other diagonal's half",
            ),
            (
                [v(0.6, 0.2), v(0.8, 0.2), v(0.8, 0.4)],
                true,
                "a small one inside",
            ),
            (
                [v(1.1, 0.0), v(2.0, 0.0), v(2.0, 1.0)],
                false,
                "one beyond a vertex",
            ),
            ([v(2.0, 2.0), v(3.0, 2.0), v(2.0, 3.0)], false, "disjoint"),
            (
                [v(0.999, 0.5), v(2.0, 0.5), v(2.0, 0.6)],
                true,
                "across an edge by 0.001",
            ),
            (
                [v(0.99995, 0.5), v(2.0, 0.5), v(2.0, 0.6)],
                false,
                "within the tolerance",
            ),
        ] {
            assert_eq!(triangles_overlap(&a, &b, 1e-4), overlap, "{what}");
            assert_eq!(triangles_overlap(&b, &a, 1e-4), overlap, "{what}, swapped");
        }
        // Projected along the normal's largest component, a tilted plane keeps its overlaps.
        let n = Vec3::new(0.2, -0.3, 0.9).normalize();
        assert_eq!(drop_axis(n), 2);
        assert_eq!(drop_axis(Vec3::new(0.0, -1.0, 0.5)), 1);
        assert_eq!(project(Vec3::new(1.0, 2.0, 3.0), 1), v(3.0, 1.0));
    }

    #[test]
    fn box_basics() {
        let b = Aabb::new(Vec3::ZERO, Vec3::new(2.0, 1.0, 4.0));
        assert_eq!(b.size(), 4.0);
        assert_eq!(b.longest_axis(), 2);
        assert_eq!(b.volume(), 8.0);
        assert_eq!(b.surface_area(), 2.0 * (2.0 + 4.0 + 8.0));
        assert!(Aabb::EMPTY.is_empty());
        assert_eq!(Aabb::EMPTY.volume(), 0.0);
        let c = b.cube();
        assert_eq!(c.extent(), Vec3::splat(4.0));
        assert!(c.contains_box(&b, 0.0));
        assert!(!b.contains_box(&c, 1e-6));
        assert_eq!(triangle_area(Vec3::ZERO, Vec3::X, Vec3::Y), 0.5);
    }
}
