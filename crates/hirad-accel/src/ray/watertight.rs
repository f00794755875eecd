//! Watertight ray–triangle intersection (Woop, Benthin & Wald, *Watertight Ray/Triangle
//! Intersection*, JCGT 2013) and the per-ray precomputation it shares with the slab test.
//!
//! The ray is transformed (translation to the origin, permutation of the axes so that the
//! dominant direction axis becomes z, shear so that the direction becomes +z) and the triangle
//! edge functions are evaluated in 2D. Vertices shared by neighbouring triangles are transformed
//! identically, so the edge function of a shared edge is computed bit-identically (with opposite
//! sign) by both triangles: a ray can never slip between them. Edge functions that evaluate to
//! exactly zero are recomputed in f64 to get their sign right. Both faces are hit (no culling).

use glam::{Vec3, Vec4};

/// Triangle vertices as stored by the traversal layout: `[x0, y0, z0, x1, y1, z1, x2, y2, z2]`.
pub type TriVerts = [f32; 9];

/// Corners of scene triangle `i` as the triangle test takes them.
#[inline]
pub fn tri_verts(scene: &hirad_scene::Scene, i: usize) -> TriVerts {
    let [a, b, c] = scene.tri_vertices(i);
    [a.x, a.y, a.z, b.x, b.y, b.z, c.x, c.y, c.z]
}

/// Per-ray data shared by the box and triangle tests.
#[derive(Clone, Copy, Debug)]
pub struct RayPre {
    /// Origin.
    pub o: [f32; 3],
    /// Direction.
    pub d: [f32; 3],
    /// Reciprocal direction (±∞ for zero components, sign of the zero kept).
    pub inv: [f32; 3],
    /// Index of the near box plane per axis in `[minx, miny, minz, maxx, maxy, maxz]`.
    pub near: [usize; 3],
    /// Index of the far box plane per axis.
    pub far: [usize; 3],
    /// Axis permutation of the watertight test: `kz` is the dominant axis of the direction.
    pub kx: usize,
    /// Second axis of the permutation.
    pub ky: usize,
    /// Dominant axis of the direction.
    pub kz: usize,
    /// Shear constant along `kx` (`d[kx] / d[kz]`).
    pub sx: f32,
    /// Shear constant along `ky` (`d[ky] / d[kz]`).
    pub sy: f32,
}

impl RayPre {
    /// Precompute the ray data. Returns `None` for a direction that is zero or not finite, or a
    /// non-finite origin (such a ray hits nothing).
    #[inline]
    pub fn new(origin: Vec3, dir: Vec3) -> Option<RayPre> {
        if !origin.is_finite() || !dir.is_finite() || dir == Vec3::ZERO {
            return None;
        }
        let d = dir.to_array();
        let ad = dir.abs();
        let kz = if ad.x >= ad.y && ad.x >= ad.z {
            0
        } else if ad.y >= ad.z {
            1
        } else {
            2
        };
        let mut kx = (kz + 1) % 3;
        let mut ky = (kx + 1) % 3;
        // Keep the winding of the 2D projection consistent.
        if d[kz] < 0.0 {
            std::mem::swap(&mut kx, &mut ky);
        }
        // One 4-wide division for the shear constants and one for the reciprocals: the same
        // correctly rounded quotients as scalar divisions (±∞ with the sign of a zero).
        let q = Vec4::new(d[kx], d[ky], 1.0, 1.0) / Vec4::splat(d[kz]);
        let (sx, sy) = (q.x, q.y);
        let r = Vec4::ONE / Vec4::new(d[0], d[1], d[2], 1.0);
        let inv = [r.x, r.y, r.z];
        let mut near = [0usize; 3];
        let mut far = [0usize; 3];
        for a in 0..3 {
            // The sign bit decides, so that -0.0 gives -∞ consistently.
            if inv[a].is_sign_negative() {
                near[a] = a + 3;
                far[a] = a;
            } else {
                near[a] = a;
                far[a] = a + 3;
            }
        }
        Some(RayPre {
            o: origin.to_array(),
            d,
            inv,
            near,
            far,
            kx,
            ky,
            kz,
            sx,
            sy,
        })
    }

    /// Slab test against `b = [minx, miny, minz, maxx, maxy, maxz]` clipped to `[tmin, tmax]`.
    /// Returns the entry parameter when the box is (conservatively) hit.
    ///
    /// Conservative: the far distance is enlarged by a relative [`BOX_SLACK`] so that f32
    /// rounding never culls a box whose contents the triangle test would hit. A component of
    /// the direction equal to zero with the origin exactly on a box plane gives `0·∞ = NaN`;
    /// the comparisons below ignore NaN, which treats the ray (lying in that plane) as inside
    /// the slab, as it is.
    #[inline(always)]
    pub fn slab(&self, b: &[f32; 6], tmin: f32, tmax: f32) -> Option<f32> {
        let mut tn = tmin;
        let mut tf = tmax;
        for a in 0..3 {
            let t0 = (b[self.near[a]] - self.o[a]) * self.inv[a];
            let t1 = (b[self.far[a]] - self.o[a]) * self.inv[a];
            // NaN compares false: it leaves the running bound unchanged.
            tn = if t0 > tn { t0 } else { tn };
            tf = if t1 < tf { t1 } else { tf };
        }
        (tn <= tf * BOX_SLACK).then_some(tn)
    }
}

/// Relative slack of the slab test's far distance (about 16 ulp of f32).
pub const BOX_SLACK: f32 = 1.0 + 1e-6;

/// Watertight intersection of a precomputed ray with a triangle, for `t ∈ [tmin, tmax]`.
/// Returns `(t, u, v)`: `u` is the barycentric weight of vertex 1, `v` of vertex 2.
#[inline(always)]
pub fn intersect(r: &RayPre, tri: &TriVerts, tmin: f32, tmax: f32) -> Option<(f32, f32, f32)> {
    let (kx, ky, kz) = (r.kx, r.ky, r.kz);
    let a = [tri[0] - r.o[0], tri[1] - r.o[1], tri[2] - r.o[2]];
    let b = [tri[3] - r.o[0], tri[4] - r.o[1], tri[5] - r.o[2]];
    let c = [tri[6] - r.o[0], tri[7] - r.o[1], tri[8] - r.o[2]];
    let ax = a[kx] - r.sx * a[kz];
    let ay = a[ky] - r.sy * a[kz];
    let bx = b[kx] - r.sx * b[kz];
    let by = b[ky] - r.sy * b[kz];
    let cx = c[kx] - r.sx * c[kz];
    let cy = c[ky] - r.sy * c[kz];
    let mut u = cx * by - cy * bx;
    let mut v = ax * cy - ay * cx;
    let mut w = bx * ay - by * ax;
    if u == 0.0 || v == 0.0 || w == 0.0 {
        // Exact sign of the edge functions in double precision (products of f32 are exact).
        let (axd, ayd, bxd, byd, cxd, cyd) = (
            ax as f64, ay as f64, bx as f64, by as f64, cx as f64, cy as f64,
        );
        u = (cxd * byd - cyd * bxd) as f32;
        v = (axd * cyd - ayd * cxd) as f32;
        w = (bxd * ayd - byd * axd) as f32;
    }
    if (u < 0.0 || v < 0.0 || w < 0.0) && (u > 0.0 || v > 0.0 || w > 0.0) {
        return None;
    }
    let det = u + v + w;
    if det == 0.0 {
        return None;
    }
    // The edge functions decide whether the ray crosses the triangle (watertight). The hit
    // distance is then taken from the plane equation in f64, exact up to one final rounding:
    // the sheared f32 form `T/det` loses most of its digits for slivers and for rays nearly
    // in the triangle's plane, which would make hits appear outside the segment (and disagree
    // with the conservative box test of the traversal).
    let e1 = [
        tri[3] as f64 - tri[0] as f64,
        tri[4] as f64 - tri[1] as f64,
        tri[5] as f64 - tri[2] as f64,
    ];
    let e2 = [
        tri[6] as f64 - tri[0] as f64,
        tri[7] as f64 - tri[1] as f64,
        tri[8] as f64 - tri[2] as f64,
    ];
    let n = [
        e1[1] * e2[2] - e1[2] * e2[1],
        e1[2] * e2[0] - e1[0] * e2[2],
        e1[0] * e2[1] - e1[1] * e2[0],
    ];
    let num = n[0] * (tri[0] as f64 - r.o[0] as f64)
        + n[1] * (tri[1] as f64 - r.o[1] as f64)
        + n[2] * (tri[2] as f64 - r.o[2] as f64);
    let den = n[0] * r.d[0] as f64 + n[1] * r.d[1] as f64 + n[2] * r.d[2] as f64;
    let t = (num / den) as f32;
    // NaN (0/0, a ray in the plane through the origin) compares false: no hit.
    if !(t >= tmin && t <= tmax) {
        return None;
    }
    let rcp = 1.0 / det;
    Some((t, v * rcp, w * rcp))
}

/// Four triangles in structure-of-arrays form: `v[3k + a][lane]` is coordinate `a` of vertex
/// `k` of the triangle in `lane`.
pub type Tri4 = [[f32; 4]; 9];

/// Sixteen triangles in structure-of-arrays form, as [`Tri4`].
pub type Tri16 = [[f32; 16]; 9];

/// The triangle of `lane` of a structure-of-arrays block ([`Tri4`], [`Tri16`]).
#[inline(always)]
pub fn tri_of<const N: usize>(p: &[[f32; N]; 9], lane: usize) -> TriVerts {
    std::array::from_fn(|i| p[i][lane])
}

/// The edge-function stage of [`intersect`] for four triangles at once: returns the mask of
/// lanes that [`intersect`] may report as hit (the signs of the sheared edge functions agree,
/// or one of them is exactly zero and needs the f64 recomputation). A lane outside the mask is
/// certainly missed by [`intersect`]: the f32 operations are the same, in the same order, so
/// the edge functions are bit-identical to the scalar test's.
#[inline(always)]
pub fn candidates4(r: &RayPre, p: &Tri4) -> u32 {
    candidates4_at(r, p, 0)
}

/// [`candidates4`] for lanes `off..off + 4` of a wider block.
#[inline(always)]
pub fn candidates4_at<const N: usize>(r: &RayPre, p: &[[f32; N]; 9], off: usize) -> u32 {
    assert!(off + 4 <= N);
    #[cfg(target_arch = "x86_64")]
    {
        // SAFETY: SSE is part of the x86_64 baseline; lanes `off..off + 4` lie inside every
        // row (asserted above).
        #[allow(unused_unsafe)]
        unsafe {
            let (_, mixed, zero) = edges4(r, p, off);
            (!mixed | zero) & 0xF
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        let mut m = 0;
        for lane in 0..4 {
            let t = tri_of(p, off + lane);
            let e = |k: usize| {
                let q = [
                    t[3 * k] - r.o[0],
                    t[3 * k + 1] - r.o[1],
                    t[3 * k + 2] - r.o[2],
                ];
                (q[r.kx] - r.sx * q[r.kz], q[r.ky] - r.sy * q[r.kz])
            };
            let ((ax, ay), (bx, by), (cx, cy)) = (e(0), e(1), e(2));
            let u = cx * by - cy * bx;
            let v = ax * cy - ay * cx;
            let w = bx * ay - by * ax;
            let zero = u == 0.0 || v == 0.0 || w == 0.0;
            let mixed = (u < 0.0 || v < 0.0 || w < 0.0) && (u > 0.0 || v > 0.0 || w > 0.0);
            if zero || !mixed {
                m |= 1 << lane;
            }
        }
        m
    }
}

/// The sheared edge functions `[u, v, w]` of [`intersect`] for lanes `off..off + 4` of a
/// structure-of-arrays block (the same f32 operations in the same order), with the masks of
/// the lanes whose signs are mixed and of those with an edge function of exactly zero.
///
/// # Safety
/// `off + 4 <= N` (SSE is part of the x86_64 baseline).
#[cfg(target_arch = "x86_64")]
#[inline(always)]
unsafe fn edges4<const N: usize>(
    r: &RayPre,
    p: &[[f32; N]; 9],
    off: usize,
) -> ([core::arch::x86_64::__m128; 3], u32, u32) {
    use core::arch::x86_64::*;
    let ld = |row: usize| _mm_loadu_ps(p[row].as_ptr().add(off));
    let ox = _mm_set1_ps(r.o[r.kx]);
    let oy = _mm_set1_ps(r.o[r.ky]);
    let oz = _mm_set1_ps(r.o[r.kz]);
    let sx = _mm_set1_ps(r.sx);
    let sy = _mm_set1_ps(r.sy);
    let mut x = [_mm_setzero_ps(); 3];
    let mut y = [_mm_setzero_ps(); 3];
    for k in 0..3 {
        let px = _mm_sub_ps(ld(3 * k + r.kx), ox);
        let py = _mm_sub_ps(ld(3 * k + r.ky), oy);
        let pz = _mm_sub_ps(ld(3 * k + r.kz), oz);
        x[k] = _mm_sub_ps(px, _mm_mul_ps(sx, pz));
        y[k] = _mm_sub_ps(py, _mm_mul_ps(sy, pz));
    }
    let u = _mm_sub_ps(_mm_mul_ps(x[2], y[1]), _mm_mul_ps(y[2], x[1]));
    let v = _mm_sub_ps(_mm_mul_ps(x[0], y[2]), _mm_mul_ps(y[0], x[2]));
    let w = _mm_sub_ps(_mm_mul_ps(x[1], y[0]), _mm_mul_ps(y[1], x[0]));
    let z = _mm_setzero_ps();
    let zero = _mm_or_ps(
        _mm_or_ps(_mm_cmpeq_ps(u, z), _mm_cmpeq_ps(v, z)),
        _mm_cmpeq_ps(w, z),
    );
    let neg = _mm_or_ps(
        _mm_or_ps(_mm_cmplt_ps(u, z), _mm_cmplt_ps(v, z)),
        _mm_cmplt_ps(w, z),
    );
    let pos = _mm_or_ps(
        _mm_or_ps(_mm_cmpgt_ps(u, z), _mm_cmpgt_ps(v, z)),
        _mm_cmpgt_ps(w, z),
    );
    (
        [u, v, w],
        _mm_movemask_ps(_mm_and_ps(neg, pos)) as u32,
        _mm_movemask_ps(zero) as u32,
    )
}

/// What a packet test ([`hits4_avx`], [`hits16_avx512`]) finds for the `N` lanes it decides.
#[cfg(target_arch = "x86_64")]
#[derive(Clone, Copy)]
pub struct Hits<const N: usize> {
    /// Lanes [`intersect`] reports as hit in `[tmin, tmax]`.
    pub hit: u32,
    /// Lanes with an edge function of exactly zero, which [`intersect`] must decide.
    pub unsure: u32,
    /// Per lane, [`intersect`]'s `(t, u, v)` (meaningful in `hit` lanes; `u` and `v` only from
    /// a test made with `UV`, else zero).
    pub t: [f32; N],
    /// Barycentric coordinate of vertex 1.
    pub u: [f32; N],
    /// Barycentric coordinate of vertex 2.
    pub v: [f32; N],
}

/// [`intersect`] for the four triangles of a [`Tri4`] at once: edge functions in f32 and the hit
/// distances of all four lanes in 4-wide f64, the same operations in the same order as
/// [`intersect`] (no fused multiply-adds), hence the same answers. Lanes with an edge function
/// of exactly zero (recomputed in f64 by [`intersect`]) are left to [`intersect`]
/// ([`Hits::unsure`]). `UV`: also the barycentric coordinates (not needed by occlusion).
///
/// Not itself compiled for AVX: it is inlined into the AVX2 copies of the traversals (as
/// `Slab8::test_avx`).
///
/// # Safety
/// The CPU must support AVX.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
pub unsafe fn hits4_avx<const UV: bool>(r: &RayPre, p: &Tri4, tmin: f32, tmax: f32) -> Hits<4> {
    hits4_avx_at::<4, UV>(r, p, 0, tmin, tmax)
}

/// [`hits4_avx`] for lanes `off..off + 4` of a wider block.
///
/// # Safety
/// The CPU must support AVX, and `off + 4 <= N`.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
pub unsafe fn hits4_avx_at<const N: usize, const UV: bool>(
    r: &RayPre,
    p: &[[f32; N]; 9],
    off: usize,
    tmin: f32,
    tmax: f32,
) -> Hits<4> {
    use core::arch::x86_64::*;
    let ld = |row: usize| _mm_loadu_ps(p[row].as_ptr().add(off));
    let ([u, v, w], mixed, zero_m) = edges4(r, p, off);
    let inside = !mixed & !zero_m & 0xF;
    let mut out = Hits {
        hit: 0,
        unsure: zero_m,
        t: [0.0; 4],
        u: [0.0; 4],
        v: [0.0; 4],
    };
    if inside == 0 {
        return out;
    }
    let det = _mm_add_ps(_mm_add_ps(u, v), w);
    let det_ok = !(_mm_movemask_ps(_mm_cmpeq_ps(det, _mm_setzero_ps())) as u32);
    // The hit distance from the plane equation in f64, as `intersect` computes it.
    let f = |row: usize| _mm256_cvtps_pd(ld(row));
    let (v0, v1, v2) = ([f(0), f(1), f(2)], [f(3), f(4), f(5)], [f(6), f(7), f(8)]);
    let e1 = [
        _mm256_sub_pd(v1[0], v0[0]),
        _mm256_sub_pd(v1[1], v0[1]),
        _mm256_sub_pd(v1[2], v0[2]),
    ];
    let e2 = [
        _mm256_sub_pd(v2[0], v0[0]),
        _mm256_sub_pd(v2[1], v0[1]),
        _mm256_sub_pd(v2[2], v0[2]),
    ];
    let n = [
        _mm256_sub_pd(_mm256_mul_pd(e1[1], e2[2]), _mm256_mul_pd(e1[2], e2[1])),
        _mm256_sub_pd(_mm256_mul_pd(e1[2], e2[0]), _mm256_mul_pd(e1[0], e2[2])),
        _mm256_sub_pd(_mm256_mul_pd(e1[0], e2[1]), _mm256_mul_pd(e1[1], e2[0])),
    ];
    let o = |a: usize| _mm256_set1_pd(r.o[a] as f64);
    let d = |a: usize| _mm256_set1_pd(r.d[a] as f64);
    let num = _mm256_add_pd(
        _mm256_add_pd(
            _mm256_mul_pd(n[0], _mm256_sub_pd(v0[0], o(0))),
            _mm256_mul_pd(n[1], _mm256_sub_pd(v0[1], o(1))),
        ),
        _mm256_mul_pd(n[2], _mm256_sub_pd(v0[2], o(2))),
    );
    let den = _mm256_add_pd(
        _mm256_add_pd(_mm256_mul_pd(n[0], d(0)), _mm256_mul_pd(n[1], d(1))),
        _mm256_mul_pd(n[2], d(2)),
    );
    let t = _mm256_cvtpd_ps(_mm256_div_pd(num, den));
    // Ordered comparisons: a NaN distance is no hit.
    let in_range = _mm_and_ps(
        _mm_cmpge_ps(t, _mm_set1_ps(tmin)),
        _mm_cmple_ps(t, _mm_set1_ps(tmax)),
    );
    out.hit = inside & det_ok & _mm_movemask_ps(in_range) as u32;
    _mm_storeu_ps(out.t.as_mut_ptr(), t);
    if UV {
        let rcp = _mm_div_ps(_mm_set1_ps(1.0), det);
        _mm_storeu_ps(out.u.as_mut_ptr(), _mm_mul_ps(v, rcp));
        _mm_storeu_ps(out.v.as_mut_ptr(), _mm_mul_ps(w, rcp));
    }
    out
}

/// [`candidates4`] for the sixteen triangles of a [`Tri16`] in one pass of AVX-512 (the same
/// f32 operations in the same order, without fused multiply-adds: bit-identical edge
/// functions, the same mask as four calls of [`candidates4_at`]).
///
/// # Safety
/// The CPU must support AVX-512F (`is_x86_feature_detected!("avx512f")`).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
#[inline]
pub unsafe fn candidates16_avx512(r: &RayPre, p: &Tri16) -> u32 {
    let (_, mixed, zero) = edges16(r, p);
    (!mixed | zero) & 0xFFFF
}

/// The sheared edge functions `[u, v, w]` of [`intersect`] for the sixteen lanes of a
/// [`Tri16`] (as [`edges4`]), with the masks of the lanes whose signs are mixed and of those
/// with an edge function of exactly zero.
///
/// # Safety
/// The CPU must support AVX-512F.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
#[inline]
unsafe fn edges16(r: &RayPre, p: &Tri16) -> ([core::arch::x86_64::__m512; 3], u32, u32) {
    use core::arch::x86_64::*;
    // SAFETY (loads): every row of a Tri16 holds sixteen f32; unaligned loads.
    let ld = |row: usize| unsafe { _mm512_loadu_ps(p[row].as_ptr()) };
    let ox = _mm512_set1_ps(r.o[r.kx]);
    let oy = _mm512_set1_ps(r.o[r.ky]);
    let oz = _mm512_set1_ps(r.o[r.kz]);
    let sx = _mm512_set1_ps(r.sx);
    let sy = _mm512_set1_ps(r.sy);
    let mut x = [_mm512_setzero_ps(); 3];
    let mut y = [_mm512_setzero_ps(); 3];
    for k in 0..3 {
        let px = _mm512_sub_ps(ld(3 * k + r.kx), ox);
        let py = _mm512_sub_ps(ld(3 * k + r.ky), oy);
        let pz = _mm512_sub_ps(ld(3 * k + r.kz), oz);
        x[k] = _mm512_sub_ps(px, _mm512_mul_ps(sx, pz));
        y[k] = _mm512_sub_ps(py, _mm512_mul_ps(sy, pz));
    }
    let u = _mm512_sub_ps(_mm512_mul_ps(x[2], y[1]), _mm512_mul_ps(y[2], x[1]));
    let v = _mm512_sub_ps(_mm512_mul_ps(x[0], y[2]), _mm512_mul_ps(y[0], x[2]));
    let w = _mm512_sub_ps(_mm512_mul_ps(x[1], y[0]), _mm512_mul_ps(y[1], x[0]));
    let z = _mm512_setzero_ps();
    let zero = _mm512_cmp_ps_mask::<_CMP_EQ_OQ>(u, z)
        | _mm512_cmp_ps_mask::<_CMP_EQ_OQ>(v, z)
        | _mm512_cmp_ps_mask::<_CMP_EQ_OQ>(w, z);
    let neg = _mm512_cmp_ps_mask::<_CMP_LT_OQ>(u, z)
        | _mm512_cmp_ps_mask::<_CMP_LT_OQ>(v, z)
        | _mm512_cmp_ps_mask::<_CMP_LT_OQ>(w, z);
    let pos = _mm512_cmp_ps_mask::<_CMP_GT_OQ>(u, z)
        | _mm512_cmp_ps_mask::<_CMP_GT_OQ>(v, z)
        | _mm512_cmp_ps_mask::<_CMP_GT_OQ>(w, z);
    ([u, v, w], (neg & pos) as u32, zero as u32)
}

/// [`hits4_avx`] for the sixteen triangles of a [`Tri16`] in AVX-512: the edge functions of
/// `edges16`, the hit distances of the lanes inside in 8-wide f64, eight lanes at a time
/// (the operations of [`intersect`] in its order, hence its answers).
///
/// # Safety
/// The CPU must support AVX-512F (`is_x86_feature_detected!("avx512f")`).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
#[inline]
pub unsafe fn hits16_avx512<const UV: bool>(
    r: &RayPre,
    p: &Tri16,
    tmin: f32,
    tmax: f32,
) -> Hits<16> {
    use core::arch::x86_64::*;
    let ([u, v, w], mixed, zero_m) = edges16(r, p);
    let inside = !mixed & !zero_m & 0xFFFF;
    let mut out = Hits {
        hit: 0,
        unsure: zero_m,
        t: [0.0; 16],
        u: [0.0; 16],
        v: [0.0; 16],
    };
    if inside == 0 {
        return out;
    }
    let det = _mm512_add_ps(_mm512_add_ps(u, v), w);
    let det_ok = !(_mm512_cmp_ps_mask::<_CMP_EQ_OQ>(det, _mm512_setzero_ps()) as u32);
    let o = |a: usize| _mm512_set1_pd(r.o[a] as f64);
    let d = |a: usize| _mm512_set1_pd(r.d[a] as f64);
    for h in 0..2 {
        if inside >> (8 * h) & 0xFF == 0 {
            continue;
        }
        // SAFETY (loads): lanes `8h..8h + 8` of a row of sixteen.
        let f =
            |row: usize| unsafe { _mm512_cvtps_pd(_mm256_loadu_ps(p[row].as_ptr().add(8 * h))) };
        let (v0, v1, v2) = ([f(0), f(1), f(2)], [f(3), f(4), f(5)], [f(6), f(7), f(8)]);
        let e1 = [
            _mm512_sub_pd(v1[0], v0[0]),
            _mm512_sub_pd(v1[1], v0[1]),
            _mm512_sub_pd(v1[2], v0[2]),
        ];
        let e2 = [
            _mm512_sub_pd(v2[0], v0[0]),
            _mm512_sub_pd(v2[1], v0[1]),
            _mm512_sub_pd(v2[2], v0[2]),
        ];
        let n = [
            _mm512_sub_pd(_mm512_mul_pd(e1[1], e2[2]), _mm512_mul_pd(e1[2], e2[1])),
            _mm512_sub_pd(_mm512_mul_pd(e1[2], e2[0]), _mm512_mul_pd(e1[0], e2[2])),
            _mm512_sub_pd(_mm512_mul_pd(e1[0], e2[1]), _mm512_mul_pd(e1[1], e2[0])),
        ];
        let num = _mm512_add_pd(
            _mm512_add_pd(
                _mm512_mul_pd(n[0], _mm512_sub_pd(v0[0], o(0))),
                _mm512_mul_pd(n[1], _mm512_sub_pd(v0[1], o(1))),
            ),
            _mm512_mul_pd(n[2], _mm512_sub_pd(v0[2], o(2))),
        );
        let den = _mm512_add_pd(
            _mm512_add_pd(_mm512_mul_pd(n[0], d(0)), _mm512_mul_pd(n[1], d(1))),
            _mm512_mul_pd(n[2], d(2)),
        );
        let t = _mm512_cvtpd_ps(_mm512_div_pd(num, den));
        _mm256_storeu_ps(out.t.as_mut_ptr().add(8 * h), t);
    }
    let t = _mm512_loadu_ps(out.t.as_ptr());
    // Ordered comparisons: a NaN distance is no hit.
    let in_range = _mm512_cmp_ps_mask::<_CMP_GE_OQ>(t, _mm512_set1_ps(tmin))
        & _mm512_cmp_ps_mask::<_CMP_LE_OQ>(t, _mm512_set1_ps(tmax));
    out.hit = inside & det_ok & in_range as u32;
    if UV {
        let rcp = _mm512_div_ps(_mm512_set1_ps(1.0), det);
        _mm512_storeu_ps(out.u.as_mut_ptr(), _mm512_mul_ps(v, rcp));
        _mm512_storeu_ps(out.v.as_mut_ptr(), _mm512_mul_ps(w, rcp));
    }
    out
}

/// Convenience: intersect a ray with a triangle given by its corners.
pub fn intersect_triangle(
    [p0, p1, p2]: [Vec3; 3],
    origin: Vec3,
    dir: Vec3,
    tmin: f32,
    tmax: f32,
) -> Option<(f32, f32, f32)> {
    let r = RayPre::new(origin, dir)?;
    let tri = [p0.x, p0.y, p0.z, p1.x, p1.y, p1.z, p2.x, p2.y, p2.z];
    intersect(&r, &tri, tmin, tmax)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hits_inside_misses_outside() {
        let tri = [Vec3::ZERO, Vec3::X, Vec3::Y];
        let (t, u, v) =
            intersect_triangle(tri, Vec3::new(0.25, 0.25, 1.0), -Vec3::Z, 0.0, 10.0).unwrap();
        assert!((t - 1.0).abs() < 1e-6);
        assert!((u - 0.25).abs() < 1e-6 && (v - 0.25).abs() < 1e-6);
        // Back face is hit as well.
        let (t, _, _) =
            intersect_triangle(tri, Vec3::new(0.25, 0.25, -2.0), Vec3::Z, 0.0, 10.0).unwrap();
        assert!((t - 2.0).abs() < 1e-6);
        assert!(intersect_triangle(tri, Vec3::new(0.6, 0.6, 1.0), -Vec3::Z, 0.0, 10.0).is_none());
        // Outside the t range.
        assert!(intersect_triangle(tri, Vec3::new(0.2, 0.2, 1.0), -Vec3::Z, 0.0, 0.5).is_none());
        assert!(intersect_triangle(tri, Vec3::new(0.2, 0.2, 1.0), -Vec3::Z, 1.5, 3.0).is_none());
        // Degenerate rays hit nothing.
        assert!(intersect_triangle(tri, Vec3::new(0.2, 0.2, 1.0), Vec3::ZERO, 0.0, 3.0).is_none());
        assert!(RayPre::new(Vec3::NAN, Vec3::X).is_none());
    }

    #[test]
    fn edges_and_vertices_are_hit() {
        let tri = [Vec3::ZERO, Vec3::X, Vec3::Y];
        // Exactly on the hypotenuse, on an axis edge and on a vertex.
        for p in [
            Vec3::new(0.5, 0.5, 1.0),
            Vec3::new(0.5, 0.0, 1.0),
            Vec3::new(0.0, 0.0, 1.0),
            Vec3::new(1.0, 0.0, 1.0),
        ] {
            assert!(
                intersect_triangle(tri, p, -Vec3::Z, 0.0, 10.0).is_some(),
                "{p}"
            );
        }
    }

    #[test]
    fn sixteen_lane_candidates_equal_four_lane_ones() {
        // The AVX-512 edge test gives bit for bit the mask of four SSE passes (same f32
        // operations), on random rays and triangles with coordinates on a coarse grid so that
        // edge functions of exactly zero (the f64 re-check) occur.
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx512f") {
            let mut g = hirad_core::rng::SplitMix64::new(9);
            let c = |g: &mut hirad_core::rng::SplitMix64| (g.next_u64() % 7) as f32 * 0.5 - 1.5;
            let (mut zero_lanes, mut set) = (0, 0u32);
            for _ in 0..5000 {
                let o = Vec3::new(c(&mut g), c(&mut g), c(&mut g));
                let d = Vec3::new(c(&mut g), c(&mut g), c(&mut g));
                let Some(r) = RayPre::new(o, d) else { continue };
                let mut p: Tri16 = [[0.0; 16]; 9];
                for row in p.iter_mut() {
                    for x in row.iter_mut() {
                        *x = c(&mut g);
                    }
                }
                // SAFETY: AVX-512F was detected above.
                let m16 = unsafe { candidates16_avx512(&r, &p) };
                let m4 = (0..4).fold(0, |m, q| m | candidates4_at(&r, &p, 4 * q) << (4 * q));
                assert_eq!(m16, m4);
                set += m16.count_ones();
                for lane in 0..16 {
                    let t = tri_of(&p, lane);
                    zero_lanes +=
                        intersect(&r, &t, -1e30, 1e30).is_none() as u32 * (m16 >> lane & 1);
                }
            }
            // Both kinds of lanes occur: candidates the scalar test rejects, and hits.
            assert!(set > 10_000 && zero_lanes > 500, "{set} {zero_lanes}");
        }
    }

    /// Check a packet test against `intersect` (hit, distance, barycentric coordinates) in
    /// every lane without an edge function of exactly zero, on random rays and triangles with
    /// coordinates on a coarse grid (so that zero edge functions, hit distances exactly at the
    /// range's ends and rays in a triangle's plane occur). `test(r, p, tmin, tmax, uv)`.
    #[cfg(target_arch = "x86_64")]
    fn check_packet_test<const N: usize>(
        seed: u64,
        rays: usize,
        test: impl Fn(&RayPre, &[[f32; N]; 9], f32, f32, bool) -> Hits<N>,
    ) {
        let mut g = hirad_core::rng::SplitMix64::new(seed);
        let c = |g: &mut hirad_core::rng::SplitMix64| (g.next_u64() % 7) as f32 * 0.5 - 1.5;
        let (mut hits, mut misses, mut unsure, mut at_ends) = (0, 0, 0, 0);
        for i in 0..rays {
            let o = Vec3::new(c(&mut g), c(&mut g), c(&mut g));
            let d = Vec3::new(c(&mut g), c(&mut g), c(&mut g));
            let Some(r) = RayPre::new(o, d) else { continue };
            let mut p = [[0.0; N]; 9];
            for row in p.iter_mut() {
                for x in row.iter_mut() {
                    *x = c(&mut g);
                }
            }
            let (tmin, tmax) = if i % 2 == 0 { (0.5, 1.0) } else { (0.0, 2.0) };
            let (h, h_no_uv) = (
                test(&r, &p, tmin, tmax, true),
                test(&r, &p, tmin, tmax, false),
            );
            // The same lanes, and the same distances where hit.
            let bits = |h: &Hits<N>| {
                let t: [u32; N] = std::array::from_fn(|i| (h.hit >> i & 1) * h.t[i].to_bits());
                (h.hit, h.unsure, t)
            };
            assert_eq!(bits(&h), bits(&h_no_uv));
            for lane in 0..N {
                let t = tri_of(&p, lane);
                let want = intersect(&r, &t, tmin, tmax);
                if h.unsure >> lane & 1 == 1 {
                    assert_eq!(h.hit >> lane & 1, 0);
                    unsure += 1;
                    continue;
                }
                assert_eq!(h.hit >> lane & 1 == 1, want.is_some(), "{o} {d} {t:?}");
                if let Some((th, u, v)) = want {
                    assert_eq!((h.t[lane], h.u[lane], h.v[lane]), (th, u, v));
                    at_ends += (th == tmin || th == tmax) as u32;
                    hits += 1;
                } else {
                    misses += 1;
                }
            }
        }
        let k = N as u32 / 4;
        assert!(
            hits > 1000 * k && misses > 20000 * k && unsure > 500 * k,
            "{hits} {misses} {unsure}"
        );
        assert!(at_ends > 50 * k, "{at_ends}");
    }

    #[test]
    fn four_lane_packet_test_equals_scalar_test() {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx") {
            // SAFETY: AVX was detected above.
            check_packet_test::<4>(17, 20000, |r, p, tmin, tmax, uv| unsafe {
                if uv {
                    hits4_avx::<true>(r, p, tmin, tmax)
                } else {
                    hits4_avx::<false>(r, p, tmin, tmax)
                }
            });
        }
    }

    #[test]
    fn sixteen_lane_packet_test_equals_scalar_test() {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx512f") {
            // SAFETY: AVX-512F was detected above.
            check_packet_test::<16>(23, 20000, |r, p, tmin, tmax, uv| unsafe {
                if uv {
                    hits16_avx512::<true>(r, p, tmin, tmax)
                } else {
                    hits16_avx512::<false>(r, p, tmin, tmax)
                }
            });
        }
    }

    #[test]
    fn slab_handles_parallel_rays_on_planes() {
        let b = [0.0, 0.0, 0.0, 1.0, 0.0, 1.0]; // flat box in y = 0
                                                // In the plane of the flat box, parallel to it.
        let r = RayPre::new(Vec3::new(-1.0, 0.0, 0.5), Vec3::X).unwrap();
        assert_eq!(r.slab(&b, 0.0, 10.0), Some(1.0));
        // Origin on the max plane (z = 1), direction parallel to it.
        let r = RayPre::new(Vec3::new(-1.0, 0.0, 1.0), Vec3::X).unwrap();
        assert!(r.slab(&b, 0.0, 10.0).is_some());
        // Negative-zero component.
        let r = RayPre::new(Vec3::new(-1.0, 0.0, 1.0), Vec3::new(1.0, -0.0, -0.0)).unwrap();
        assert!(r.slab(&b, 0.0, 10.0).is_some());
        // Parallel but off the plane.
        let r = RayPre::new(Vec3::new(-1.0, 0.1, 0.5), Vec3::X).unwrap();
        assert!(r.slab(&b, 0.0, 10.0).is_none());
        // Crossing the flat box.
        let r = RayPre::new(Vec3::new(0.5, 1.0, 0.5), -Vec3::Y).unwrap();
        assert_eq!(r.slab(&b, 0.0, 10.0), Some(1.0));
        assert!(r.slab(&b, 0.0, 0.5).is_none());
    }
}
