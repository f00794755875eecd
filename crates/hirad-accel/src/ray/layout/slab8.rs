//! The slab test of a [`Node8`]'s eight boxes ([`Slab8`]): one AVX pass where the CPU has it,
//! the same operations lane by lane otherwise (hence the same mask).

use super::super::watertight::{RayPre, BOX_SLACK};
use super::node8::Node8;

/// Per-ray data of the eight-wide box test: origin, reciprocal direction, and for each axis
/// the index of the near and far plane in [`Node8::b`] (chosen by the sign of the direction,
/// so that `0·∞ = NaN` can only come from an origin lying exactly in a box plane, which the
/// comparisons then ignore, as the scalar [`RayPre::slab`] does).
#[derive(Clone, Copy, Debug, Default)]
pub(in crate::ray) struct Slab8 {
    /// Origin, each coordinate in eight lanes.
    o: Splat8,
    /// Reciprocal direction, each component in eight lanes.
    inv: Splat8,
    near: [usize; 3],
    far: [usize; 3],
    /// Bit `a` set when the direction's component `a` is zero (the ray lies in a plane of
    /// constant coordinate `a`).
    in_plane: u32,
    /// Every `1/d` is finite: no plane distance is NaN ([`Slab8::test`]'s integer bounds).
    finite: bool,
}

/// Three values, each repeated in the eight lanes of a 32-byte row: the AVX test loads a row as
/// it is (broadcasting the ray's values again at every visit cost 2–6% of a query,
/// `docs/perf-log.md` (58)).
#[derive(Clone, Copy, Debug, Default)]
#[repr(C, align(32))]
struct Splat8([[f32; 8]; 3]);

impl Splat8 {
    #[inline(always)]
    fn new(v: [f32; 3]) -> Splat8 {
        Splat8(v.map(|x| [x; 8]))
    }

    #[inline(always)]
    fn get(&self, a: usize) -> f32 {
        self.0[a][0]
    }
}

/// The larger of `a` and `b` as the integers of their bits: the float maximum when either is
/// `≥ +0` (neither NaN); of two values with the sign bit set, the more negative.
#[inline(always)]
fn max_bits(a: f32, b: f32) -> f32 {
    if a.to_bits() as i32 > b.to_bits() as i32 {
        a
    } else {
        b
    }
}

/// The smaller of `a` and `b` as the integers of their bits: the float minimum when both are
/// `≥ +0` (neither NaN); otherwise a value with the sign bit set (`−0` before any other).
#[inline(always)]
fn min_bits(a: f32, b: f32) -> f32 {
    if (a.to_bits() as i32) < b.to_bits() as i32 {
        a
    } else {
        b
    }
}

impl Slab8 {
    #[inline(always)]
    pub(in crate::ray) fn new(r: &RayPre) -> Slab8 {
        Slab8 {
            o: Splat8::new(r.o),
            inv: Splat8::new(r.inv),
            // Plane indices are in 0..6 (RayPre's contract); keep that invariant for the
            // unchecked loads of `test`.
            near: r.near.map(|i| i.min(5)),
            far: r.far.map(|i| i.min(5)),
            in_plane: (r.d[0] == 0.0) as u32
                | ((r.d[1] == 0.0) as u32) << 1
                | ((r.d[2] == 0.0) as u32) << 2,
            finite: r.inv.iter().all(|x| x.is_finite()),
        }
    }

    /// Whether the running bounds of a test from `tmin` may be taken as the integers of their
    /// bits (a shorter chain of dependent operations, as in Embree): every `1/d` is finite, so
    /// no plane distance is NaN, and `tmin > 0`. The entry bound starts at `tmin`, so it is
    /// the float maximum; the exit bound is the float minimum when that is positive, and a
    /// value with the sign bit set (`≤ −0`, below the entry bound) otherwise, so the mask and
    /// the entry distances are the float test's. (From `tmin = 0` the exit bound `−0` of a
    /// box behind the origin with a far plane through it would pass as `+0`.)
    #[inline(always)]
    fn int_bounds(&self, tmin: f32) -> bool {
        self.finite && tmin > 0.0
    }

    /// Lanes of `n` that the ray only touches along a face: it lies in the plane of a face of
    /// the lane's box (direction component zero, origin on the face) and everything in the
    /// lane that touches that plane lies in it ([`Node8::faces`], from
    /// [`face_bits`](super::faces::face_bits); a box flat in the plane is one case). Triangles
    /// in the plane are coplanar with the ray: the watertight test computes all three sheared
    /// edge functions as exactly zero (the in-plane coordinate is one of the two sheared axes
    /// and its shear constant is zero) and reports no hit. The others lie strictly on one side
    /// of the plane, and the ray misses their boxes as it would in a leaf of their own.
    /// Skipping these lanes changes no result; it keeps a ray running along a floor from
    /// visiting every cell standing on the floor that it passes (the slab test itself must
    /// accept them: the ray touches them).
    #[inline(never)]
    fn flat_in_plane(&self, n: &Node8) -> u32 {
        let mut m = 0;
        for a in 0..3 {
            if self.in_plane & (1 << a) != 0 {
                let o = self.o.get(a);
                for lane in 0..8 {
                    let f = n.faces >> (8 * lane);
                    if (n.b[a][lane] == o && f & (1 << a) != 0)
                        || (n.b[a + 3][lane] == o && f & (1 << (a + 3)) != 0)
                    {
                        m |= 1 << lane;
                    }
                }
            }
        }
        m
    }

    /// Slab test of the eight boxes of `n` clipped to `[tmin, tmax]`: bit `i` of the mask is
    /// set when lane `i` is (conservatively, like [`RayPre::slab`]) hit and not ruled out by
    /// [`Slab8::flat_in_plane`]; `tn` its entry distance. `AVX`: in one AVX pass (only in the
    /// AVX2 copies of the traversals).
    #[inline(always)]
    pub(in crate::ray) fn test<const AVX: bool>(
        &self,
        n: &Node8,
        tmin: f32,
        tmax: f32,
    ) -> (u32, [f32; 8]) {
        #[cfg(target_arch = "x86_64")]
        if AVX {
            // SAFETY: `AVX` is set only in the AVX2 copies of the traversals.
            return unsafe { self.test_avx(n, tmin, tmax) };
        }
        let mut mask = 0;
        let mut out = [0f32; 8];
        let int = self.int_bounds(tmin);
        for (lane, out) in out.iter_mut().enumerate() {
            let mut tn = tmin;
            let mut tf = tmax;
            for a in 0..3 {
                // `near`/`far` are below 6 (`new`), the length of `n.b`.
                let (o, inv) = (self.o.get(a), self.inv.get(a));
                let t0 = (n.b[self.near[a]][lane] - o) * inv;
                let t1 = (n.b[self.far[a]][lane] - o) * inv;
                if int {
                    tn = max_bits(t0, tn);
                    tf = min_bits(t1, tf);
                } else {
                    // NaN compares false: it leaves the running bound unchanged.
                    tn = if t0 > tn { t0 } else { tn };
                    tf = if t1 < tf { t1 } else { tf };
                }
            }
            if tn <= tf * BOX_SLACK {
                mask |= 1 << lane;
            }
            *out = tn;
        }
        if self.in_plane != 0 {
            mask &= !self.flat_in_plane(n);
        }
        (mask, out)
    }

    /// [`Slab8::test`] in one AVX pass: the same operations per lane (float max/min return
    /// the second operand when either is NaN, as the scalar form keeps its running bound;
    /// the integer bounds are AVX2's `max_epi32`/`min_epi32`).
    ///
    /// Not itself compiled for AVX2 (a function with target features is not inlined into the
    /// traversal loops, which are written once for both copies): it is inlined into the AVX2
    /// copies of the traversals, where its intrinsics are then compiled for AVX2 too.
    ///
    /// # Safety
    /// The CPU must support AVX2.
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    pub(in crate::ray) unsafe fn test_avx(
        &self,
        n: &Node8,
        tmin: f32,
        tmax: f32,
    ) -> (u32, [f32; 8]) {
        use core::arch::x86_64::*;
        let mut tn = _mm256_set1_ps(tmin);
        let mut tf = _mm256_set1_ps(tmax);
        let int = self.int_bounds(tmin);
        for a in 0..3 {
            let o = _mm256_load_ps(self.o.0[a].as_ptr());
            let inv = _mm256_load_ps(self.inv.0[a].as_ptr());
            // Rows of 32 bytes in a 64-byte aligned node; `near`/`far` below 6 (`new`).
            let near = _mm256_load_ps(n.b.get_unchecked(self.near[a]).as_ptr());
            let far = _mm256_load_ps(n.b.get_unchecked(self.far[a]).as_ptr());
            let t0 = _mm256_mul_ps(_mm256_sub_ps(near, o), inv);
            let t1 = _mm256_mul_ps(_mm256_sub_ps(far, o), inv);
            if int {
                let (t0, t1) = (_mm256_castps_si256(t0), _mm256_castps_si256(t1));
                tn = _mm256_castsi256_ps(_mm256_max_epi32(t0, _mm256_castps_si256(tn)));
                tf = _mm256_castsi256_ps(_mm256_min_epi32(t1, _mm256_castps_si256(tf)));
            } else {
                tn = _mm256_max_ps(t0, tn);
                tf = _mm256_min_ps(t1, tf);
            }
        }
        let hit = _mm256_cmp_ps::<_CMP_LE_OQ>(tn, _mm256_mul_ps(tf, _mm256_set1_ps(BOX_SLACK)));
        let mut mask = _mm256_movemask_ps(hit) as u32;
        if self.in_plane != 0 {
            mask &= !self.flat_in_plane(n);
        }
        let mut out = [0f32; 8];
        _mm256_storeu_ps(out.as_mut_ptr(), tn);
        (mask, out)
    }
}
