//! The 4-wide slab test of a [`Group`]'s boxes ([`Ray4`]), and the 8-wide test of two groups
//! under AVX.

use super::super::watertight::{RayPre, BOX_SLACK};
use super::encode::Group;

/// Per-ray data of the 4-wide box test: origin and reciprocal direction broadcast to four
/// lanes, and for each axis the index of the near and far plane in [`Group::b`] (chosen by
/// the sign of the direction, so that `0·∞ = NaN` can only come from an origin lying exactly
/// in a box plane, which the comparisons then ignore, as the scalar [`RayPre::slab`] does).
#[derive(Clone, Copy, Debug, Default)]
#[repr(C, align(16))]
pub(in crate::ray) struct Ray4 {
    o: [[f32; 4]; 3],
    inv: [[f32; 4]; 3],
    near: [usize; 3],
    far: [usize; 3],
    /// Bit `a` set when the direction's component `a` is zero (the ray lies in a plane of
    /// constant coordinate `a`).
    in_plane: u32,
}

impl Ray4 {
    pub(in crate::ray) fn new(r: &RayPre) -> Ray4 {
        let mut x = Ray4::default();
        x.set(r);
        x
    }

    /// Take the data of `r`.
    #[inline(always)]
    pub(in crate::ray) fn set(&mut self, r: &RayPre) {
        for a in 0..3 {
            self.o[a] = [r.o[a]; 4];
            self.inv[a] = [r.inv[a]; 4];
            // Plane indices are in 0..6 (RayPre's contract); keep that invariant for the
            // unchecked loads of `test`.
            self.near[a] = r.near[a].min(5);
            self.far[a] = r.far[a].min(5);
        }
        self.in_plane =
            (r.d[0] == 0.0) as u32 | ((r.d[1] == 0.0) as u32) << 1 | ((r.d[2] == 0.0) as u32) << 2;
    }

    /// Lanes of `g` that the ray only touches along a face: it lies in the plane of a face of
    /// the lane's box (direction component zero, origin on the face) and everything in the
    /// lane that touches that plane lies in it (`faces`, from [`face_bits`](super::faces::face_bits); a box flat in
    /// the plane is one case). Triangles in the plane are coplanar with the ray: the
    /// watertight test computes all three sheared edge functions as exactly zero (the in-plane
    /// coordinate is one of the two sheared axes and its shear constant is zero) and reports
    /// no hit. The others lie strictly on one side of the plane, and the ray misses their
    /// boxes as it would in a leaf of their own. Skipping these lanes changes no result; it
    /// keeps a ray running along a floor from visiting every cell standing on the floor that
    /// it passes (the slab test itself must accept them: the ray touches them).
    #[inline(always)]
    fn flat_in_plane(&self, g: &Group, faces: u32) -> u32 {
        let mut m = 0;
        for a in 0..3 {
            if self.in_plane & (1 << a) != 0 {
                let o = self.o[a][0];
                for lane in 0..4 {
                    let f = faces >> (8 * lane);
                    if (g.b[a][lane] == o && f & (1 << a) != 0)
                        || (g.b[a + 3][lane] == o && f & (1 << (a + 3)) != 0)
                    {
                        m |= 1 << lane;
                    }
                }
            }
        }
        m
    }

    /// Slab test of the four boxes of `g` clipped to `[tmin, tmax]`: bit `i` of the mask is
    /// set when lane `i` is (conservatively, like [`RayPre::slab`]) hit and not ruled out by
    /// [`Ray4::flat_in_plane`]; `tn` its entry distance.
    #[inline(always)]
    pub(in crate::ray) fn test(
        &self,
        g: &Group,
        faces: &u32,
        tmin: f32,
        tmax: f32,
    ) -> (u32, [f32; 4]) {
        #[cfg(target_arch = "x86_64")]
        {
            use core::arch::x86_64::*;
            // SAFETY: SSE and SSE2 are part of the x86_64 baseline; `o`/`inv` are 16-byte
            // aligned (repr align 16, arrays of four f32 at offsets multiple of 16), the other
            // loads are unaligned; plane indices are below 6 by construction (`set`).
            #[allow(unused_unsafe)]
            unsafe {
                let mut tn = _mm_set1_ps(tmin);
                let mut tf = _mm_set1_ps(tmax);
                for a in 0..3 {
                    let o = _mm_load_ps(self.o[a].as_ptr());
                    let inv = _mm_load_ps(self.inv[a].as_ptr());
                    // `near`/`far` are below 6 (`set`), the length of `g.b`.
                    let n = _mm_loadu_ps(g.b.get_unchecked(self.near[a]).as_ptr());
                    let f = _mm_loadu_ps(g.b.get_unchecked(self.far[a]).as_ptr());
                    let t0 = _mm_mul_ps(_mm_sub_ps(n, o), inv);
                    let t1 = _mm_mul_ps(_mm_sub_ps(f, o), inv);
                    // max/min return the second operand when either is NaN: a NaN plane
                    // distance leaves the running bound unchanged.
                    tn = _mm_max_ps(t0, tn);
                    tf = _mm_min_ps(t1, tf);
                }
                let hit = _mm_cmple_ps(tn, _mm_mul_ps(tf, _mm_set1_ps(BOX_SLACK)));
                let mut mask = _mm_movemask_ps(hit) as u32;
                if self.in_plane != 0 {
                    mask &= !self.flat_in_plane(g, *faces);
                }
                let mut out = [0f32; 4];
                _mm_storeu_ps(out.as_mut_ptr(), tn);
                (mask, out)
            }
        }
        #[cfg(not(target_arch = "x86_64"))]
        {
            let mut mask = 0;
            let mut out = [0f32; 4];
            for lane in 0..4 {
                let mut tn = tmin;
                let mut tf = tmax;
                for a in 0..3 {
                    let t0 = (g.b[self.near[a]][lane] - self.o[a][0]) * self.inv[a][0];
                    let t1 = (g.b[self.far[a]][lane] - self.o[a][0]) * self.inv[a][0];
                    tn = if t0 > tn { t0 } else { tn };
                    tf = if t1 < tf { t1 } else { tf };
                }
                if tn <= tf * BOX_SLACK {
                    mask |= 1 << lane;
                }
                out[lane] = tn;
            }
            if self.in_plane != 0 {
                mask &= !self.flat_in_plane(g, *faces);
            }
            (mask, out)
        }
    }

    /// [`Ray4::test`] of the two groups `g0`, `g1` (face words `f0`, `f1`) in one 8-wide AVX
    /// pass: bit `i` (`4 + i`) of the mask is lane `i` of `g0` (`g1`). The same f32 operations
    /// per lane as [`Ray4::test`], hence the same mask.
    ///
    /// Not itself compiled for AVX (a function with target features is not inlined into the
    /// traversal loops, which are written once for both copies): it is inlined into the AVX2
    /// copies of the traversals, where its intrinsics are then compiled for AVX too.
    ///
    /// # Safety
    /// The CPU must support AVX.
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    pub(in crate::ray) unsafe fn test8(
        &self,
        (g0, g1): (&Group, &Group),
        (f0, f1): (u32, u32),
        tmin: f32,
        tmax: f32,
    ) -> (u32, [f32; 8]) {
        use core::arch::x86_64::*;
        let mut tn = _mm256_set1_ps(tmin);
        let mut tf = _mm256_set1_ps(tmax);
        for a in 0..3 {
            let o = _mm256_broadcast_ps(&*(self.o[a].as_ptr() as *const __m128));
            let inv = _mm256_broadcast_ps(&*(self.inv[a].as_ptr() as *const __m128));
            let (i, j) = (self.near[a], self.far[a]);
            let n = _mm256_loadu2_m128(
                g1.b.get_unchecked(i).as_ptr(),
                g0.b.get_unchecked(i).as_ptr(),
            );
            let f = _mm256_loadu2_m128(
                g1.b.get_unchecked(j).as_ptr(),
                g0.b.get_unchecked(j).as_ptr(),
            );
            let t0 = _mm256_mul_ps(_mm256_sub_ps(n, o), inv);
            let t1 = _mm256_mul_ps(_mm256_sub_ps(f, o), inv);
            tn = _mm256_max_ps(t0, tn);
            tf = _mm256_min_ps(t1, tf);
        }
        let hit = _mm256_cmp_ps::<_CMP_LE_OQ>(tn, _mm256_mul_ps(tf, _mm256_set1_ps(BOX_SLACK)));
        let mut mask = _mm256_movemask_ps(hit) as u32;
        if self.in_plane != 0 {
            mask &= !(self.flat_in_plane(g0, f0) | self.flat_in_plane(g1, f1) << 4);
        }
        let mut out = [0f32; 8];
        _mm256_storeu_ps(out.as_mut_ptr(), tn);
        (mask, out)
    }
}
