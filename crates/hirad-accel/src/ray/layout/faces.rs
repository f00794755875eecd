//! Face bits: per lane, which faces of its box hold only what lies in the face's plane, so
//! that a ray lying in that plane can skip the lane (`Slab8::flat_in_plane`).

use hirad_core::geom::Aabb;

/// Face bits of a triangle's box: bits `a` and `3 + a` when it is flat along axis `a` (it
/// lies in the plane of both faces).
pub(super) fn flat_bits(t: &Aabb) -> u8 {
    (0..3)
        .filter(|&a| t.min[a] == t.max[a])
        .fold(0, |m, a| m | 1 << a | 1 << (a + 3))
}

/// Face bits of box `b` holding `items` (boxes and their own face bits): bit `a` (`3 + a`)
/// stays set when every item that touches the plane of `b`'s min (max) face along axis `a`
/// has that bit, i.e. lies in that plane. A ray lying in such a face's plane meets only
/// triangles lying in the plane (coplanar with the ray: never hit, see
/// `Slab8::flat_in_plane`) and triangles whose boxes it misses (strictly on one side).
pub(super) fn face_bits(b: &Aabb, items: impl Iterator<Item = (Aabb, u8)>) -> u8 {
    let mut m = 0b11_1111u8;
    for (x, f) in items {
        for a in 0..3 {
            if x.min[a] == b.min[a] && f & (1 << a) == 0 {
                m &= !(1 << a);
            }
            if x.max[a] == b.max[a] && f & (1 << (a + 3)) == 0 {
                m &= !(1 << (a + 3));
            }
        }
    }
    m
}
