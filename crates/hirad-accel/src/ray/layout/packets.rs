//! Triangle storage, four ([`Packet`]) or sixteen ([`Wide`]) to a packet in structure-of-arrays
//! form, and the tests of a triangle run: in the baseline, SIMD candidate masks then the
//! scalar watertight test; in the AVX2 copies of the traversals, packet tests that decide every
//! lane as the scalar test would (sixteen lanes in one pass where the CPU has AVX-512).

use super::super::watertight::{
    candidates4, candidates4_at, intersect, tri_of, RayPre, Tri16, Tri4,
};
#[cfg(target_arch = "x86_64")]
use super::super::watertight::{hits16_avx512, hits4_avx, hits4_avx_at, Hits};
use super::Layout;

/// Shortest triangle run stored in [`Wide`] packets.
pub(in crate::ray) const WIDE_MIN: usize = 9;

/// Sixteen triangles (structure of arrays) and their scene ids (`u32::MAX` in unused lanes).
#[derive(Clone, Copy, Debug)]
#[repr(C, align(64))]
pub(in crate::ray) struct Wide {
    pub v: Tri16,
    pub id: [u32; 16],
}

/// Whether the AVX-512 edge test can run here (checked once, then cached by std).
#[inline(always)]
pub(in crate::ray) fn has_avx512() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::arch::is_x86_feature_detected!("avx512f")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// Candidate mask of the lanes `valid` of a wide packet (see
/// [`candidates4`]).
#[inline(always)]
pub(super) fn wide_candidates(r: &RayPre, w: &Wide, valid: u32, avx512: bool) -> u32 {
    #[cfg(target_arch = "x86_64")]
    if avx512 {
        // SAFETY: `avx512` is true only when the CPU has AVX-512F (`has_avx512`).
        return unsafe { super::super::watertight::candidates16_avx512(r, &w.v) } & valid;
    }
    let _ = avx512;
    let mut m = 0;
    for q in 0..4 {
        if valid >> (4 * q) & 0xF != 0 {
            m |= candidates4_at(r, &w.v, 4 * q) << (4 * q);
        }
    }
    m & valid
}

/// Four triangles (structure of arrays) and their scene ids (`u32::MAX` in unused lanes).
#[derive(Clone, Copy, Debug)]
#[repr(C, align(16))]
pub(in crate::ray) struct Packet {
    pub v: Tri4,
    pub id: [u32; 4],
}

/// Mask of the lanes used by packet `k` (of `W` lanes: 4 for a [`Packet`], 16 for a
/// [`Wide`]) of a run of `n` triangles.
#[inline(always)]
pub(in crate::ray) fn lane_mask<const W: usize>(n: usize, k: usize) -> u32 {
    let rest = n - W * k;
    if rest >= W {
        u32::MAX >> (32 - W)
    } else {
        (1 << rest) - 1
    }
}

impl Layout {
    /// A triangle of the run `(ps, n)` that `skip` does not leave out and that is hit in
    /// `[tmin, tmax]` (its id), if any. Adds the triangles tested to `*tested`.
    ///
    /// `AVX`: the packets of four are decided by [`hits4_avx`] (only in the AVX2 copies of the
    /// traversals).
    #[inline(always)]
    pub(in crate::ray) fn any_hit<const AVX: bool, F: Fn(u32) -> bool>(
        &self,
        r: &RayPre,
        (ps, n): (usize, usize),
        tmin: f32,
        tmax: f32,
        tested: &mut u64,
        skip: &F,
    ) -> Option<u32> {
        if n >= WIDE_MIN {
            #[cfg(target_arch = "x86_64")]
            if AVX {
                // SAFETY: `AVX` is set only in the AVX2 copies of the traversals; AVX-512F is
                // checked.
                return unsafe {
                    if has_avx512() {
                        self.any_hit_wide_avx512(r, (ps, n), (tmin, tmax), tested, skip)
                    } else {
                        self.any_hit_wide_avx2(r, (ps, n), (tmin, tmax), tested, skip)
                    }
                };
            }
            return self.any_hit_wide(r, ps, n, tmin, tmax, tested, skip);
        }
        for k in 0..n.div_ceil(4) {
            let p = &self.packets[ps + k];
            let valid = lane_mask::<4>(n, k);
            *tested += valid.count_ones() as u64;
            #[cfg(target_arch = "x86_64")]
            if AVX {
                // SAFETY: `AVX` is set only in the AVX2 copies of the traversals.
                let h = unsafe { hits4_avx::<false>(r, &p.v, tmin, tmax) };
                let hit = any_of_hits(r, (&p.v, &p.id, 0), &h, valid, (tmin, tmax), skip);
                if hit.is_some() {
                    return hit;
                }
                continue;
            }
            let hit = any_of(
                r,
                &p.v,
                &p.id,
                candidates4(r, &p.v) & valid,
                (tmin, tmax),
                skip,
            );
            if hit.is_some() {
                return hit;
            }
        }
        None
    }

    /// Closest hit among the triangles of the run `(ps, n)` nearer than `*best_t`: updates
    /// `*best_t` and `*best = (triangle id, u, v)`; equal distances keep the lowest id.
    ///
    /// `AVX`: the packets of four are tested by [`hits4_avx`] (only in the AVX2 copies of the
    /// traversals).
    #[inline(always)]
    pub(in crate::ray) fn closest_hit<const AVX: bool>(
        &self,
        r: &RayPre,
        ps: usize,
        n: usize,
        tmin: f32,
        best_t: &mut f32,
        best: &mut Option<(u32, f32, f32)>,
    ) {
        if n >= WIDE_MIN {
            #[cfg(target_arch = "x86_64")]
            if AVX {
                // SAFETY: as in `any_hit`.
                unsafe {
                    if has_avx512() {
                        self.closest_wide_avx512(r, (ps, n), tmin, best_t, best);
                    } else {
                        self.closest_wide_avx2(r, (ps, n), tmin, best_t, best);
                    }
                }
                return;
            }
            let avx512 = has_avx512();
            for k in 0..n.div_ceil(16) {
                let w = &self.wide[ps + k];
                let m = wide_candidates(r, w, lane_mask::<16>(n, k), avx512);
                closest_of(r, &w.v, &w.id, m, tmin, best_t, best);
            }
            return;
        }
        for k in 0..n.div_ceil(4) {
            let p = &self.packets[ps + k];
            #[cfg(target_arch = "x86_64")]
            if AVX {
                // SAFETY: `AVX` is set only in the AVX2 copies of the traversals.
                let h = unsafe { hits4_avx::<true>(r, &p.v, tmin, *best_t) };
                let m = lane_mask::<4>(n, k);
                closest_of_hits(r, (&p.v, &p.id, 0), &h, m, tmin, best_t, best);
                continue;
            }
            let m = candidates4(r, &p.v) & lane_mask::<4>(n, k);
            closest_of(r, &p.v, &p.id, m, tmin, best_t, best);
        }
    }

    /// [`Layout::any_hit`] of a run stored in wide packets.
    #[inline(never)]
    #[allow(clippy::too_many_arguments)]
    pub(in crate::ray) fn any_hit_wide<F: Fn(u32) -> bool>(
        &self,
        r: &RayPre,
        ps: usize,
        n: usize,
        tmin: f32,
        tmax: f32,
        tested: &mut u64,
        skip: &F,
    ) -> Option<u32> {
        let avx512 = has_avx512();
        for k in 0..n.div_ceil(16) {
            let w = &self.wide[ps + k];
            let valid = lane_mask::<16>(n, k);
            *tested += valid.count_ones() as u64;
            let m = wide_candidates(r, w, valid, avx512);
            let hit = any_of(r, &w.v, &w.id, m, (tmin, tmax), skip);
            if hit.is_some() {
                return hit;
            }
        }
        None
    }

    /// [`Layout::any_hit`] of a run stored in wide packets, each decided by one
    /// [`hits16_avx512`].
    ///
    /// # Safety
    /// The CPU must support AVX-512F.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx512f,avx2,popcnt,bmi1,bmi2,lzcnt")]
    #[inline(never)]
    pub(in crate::ray) unsafe fn any_hit_wide_avx512<F: Fn(u32) -> bool>(
        &self,
        r: &RayPre,
        (ps, n): (usize, usize),
        range: (f32, f32),
        tested: &mut u64,
        skip: &F,
    ) -> Option<u32> {
        self.in_parts::<16>((ps, n), tested, |w, _, m| {
            // SAFETY: the caller's CPU has AVX-512F.
            let h = unsafe { hits16_avx512::<false>(r, &w.v, range.0, range.1) };
            any_of_hits(r, (&w.v, &w.id, 0), &h, m, range, skip)
        })
    }

    /// [`Layout::any_hit`] of a run stored in wide packets, four lanes at a time by
    /// [`hits4_avx_at`] (CPUs without AVX-512).
    ///
    /// # Safety
    /// The CPU must support AVX2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,popcnt,bmi1,bmi2,lzcnt")]
    #[inline(never)]
    pub(in crate::ray) unsafe fn any_hit_wide_avx2<F: Fn(u32) -> bool>(
        &self,
        r: &RayPre,
        (ps, n): (usize, usize),
        range: (f32, f32),
        tested: &mut u64,
        skip: &F,
    ) -> Option<u32> {
        self.in_parts::<4>((ps, n), tested, |w, off, m| {
            // SAFETY: the caller's CPU has AVX2; `off + 4 <= 16`.
            let h = unsafe { hits4_avx_at::<16, false>(r, &w.v, off, range.0, range.1) };
            any_of_hits(r, (&w.v, &w.id, off), &h, m, range, skip)
        })
    }

    /// The wide packets of the run `(ps, n)` in parts of `P` lanes (16 or 4): `part(packet,
    /// first lane, lanes to decide)` for each part with lanes in the run, until one returns a
    /// triangle (occlusion; closest hits return none). Adds the triangles to `*tested`.
    #[inline(always)]
    fn in_parts<const P: usize>(
        &self,
        (ps, n): (usize, usize),
        tested: &mut u64,
        mut part: impl FnMut(&Wide, usize, u32) -> Option<u32>,
    ) -> Option<u32> {
        for k in 0..n.div_ceil(16) {
            let w = &self.wide[ps + k];
            let valid = lane_mask::<16>(n, k);
            *tested += valid.count_ones() as u64;
            for off in (0..16).step_by(P) {
                let m = valid >> off & (u32::MAX >> (32 - P));
                if m != 0 {
                    if let Some(id) = part(w, off, m) {
                        return Some(id);
                    }
                }
            }
        }
        None
    }

    /// [`Layout::closest_hit`] of a run stored in wide packets, each tested by one
    /// [`hits16_avx512`].
    ///
    /// # Safety
    /// The CPU must support AVX-512F.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx512f,avx2,popcnt,bmi1,bmi2,lzcnt")]
    #[inline(never)]
    pub(in crate::ray) unsafe fn closest_wide_avx512(
        &self,
        r: &RayPre,
        (ps, n): (usize, usize),
        tmin: f32,
        best_t: &mut f32,
        best: &mut Option<(u32, f32, f32)>,
    ) {
        self.in_parts::<16>((ps, n), &mut 0, |w, _, m| {
            // SAFETY: the caller's CPU has AVX-512F.
            let h = unsafe { hits16_avx512::<true>(r, &w.v, tmin, *best_t) };
            closest_of_hits(r, (&w.v, &w.id, 0), &h, m, tmin, best_t, best);
            None
        });
    }

    /// [`Layout::closest_hit`] of a run stored in wide packets, four lanes at a time by
    /// [`hits4_avx_at`] (CPUs without AVX-512).
    ///
    /// # Safety
    /// The CPU must support AVX2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,popcnt,bmi1,bmi2,lzcnt")]
    #[inline(never)]
    pub(in crate::ray) unsafe fn closest_wide_avx2(
        &self,
        r: &RayPre,
        (ps, n): (usize, usize),
        tmin: f32,
        best_t: &mut f32,
        best: &mut Option<(u32, f32, f32)>,
    ) {
        self.in_parts::<4>((ps, n), &mut 0, |w, off, m| {
            // SAFETY: the caller's CPU has AVX2; `off + 4 <= 16`.
            let h = unsafe { hits4_avx_at::<16, true>(r, &w.v, off, tmin, *best_t) };
            closest_of_hits(r, (&w.v, &w.id, off), &h, m, tmin, best_t, best);
            None
        });
    }
}

/// The first of the lanes `m` (of the `M` that the packet test `h` decided, lanes `off..off +
/// M` of the block `(v, ids)`) whose triangle `skip` does not leave out and that
/// [`intersect`] hits in `range` (its id), if any: `h`'s hits as they are, its unsure lanes by
/// [`intersect`]. `h` was made with `range`.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn any_of_hits<const N: usize, const M: usize, F: Fn(u32) -> bool>(
    r: &RayPre,
    (v, ids, off): (&[[f32; N]; 9], &[u32; N], usize),
    h: &Hits<M>,
    m: u32,
    range: (f32, f32),
    skip: &F,
) -> Option<u32> {
    let mut m = (h.hit | h.unsure) & m;
    while m != 0 {
        let i = m.trailing_zeros() as usize;
        m &= m - 1;
        let id = ids[off + i];
        if !skip(id)
            && (h.hit >> i & 1 == 1
                || intersect(r, &tri_of(v, off + i), range.0, range.1).is_some())
        {
            return Some(id);
        }
    }
    None
}

/// [`closest_of`] over the lanes `m` of a packet test `h` made with the range `[tmin,
/// *best_t]` (lanes `off..off + M` of the block `(v, ids)`): a hit lane is taken with its
/// distance checked against the current `*best_t`, an unsure one from [`intersect`], as
/// [`closest_of`] would find them.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn closest_of_hits<const N: usize, const M: usize>(
    r: &RayPre,
    (v, ids, off): (&[[f32; N]; 9], &[u32; N], usize),
    h: &Hits<M>,
    m: u32,
    tmin: f32,
    best_t: &mut f32,
    best: &mut Option<(u32, f32, f32)>,
) {
    let mut m = (h.hit | h.unsure) & m;
    while m != 0 {
        let i = m.trailing_zeros() as usize;
        m &= m - 1;
        let x = if h.hit >> i & 1 == 1 {
            (h.t[i] <= *best_t).then_some((h.t[i], h.u[i], h.v[i]))
        } else {
            intersect(r, &tri_of(v, off + i), tmin, *best_t)
        };
        if let Some(x) = x {
            take_closer(best_t, best, ids[off + i], x);
        }
    }
}

/// Keep hit `(t, u, v)` of triangle `id` (found within `[tmin, *best_t]`) when it is nearer than
/// the best so far, or as near with a lower id.
#[inline(always)]
fn take_closer(
    best_t: &mut f32,
    best: &mut Option<(u32, f32, f32)>,
    id: u32,
    (t, u, v): (f32, f32, f32),
) {
    let better = match *best {
        None => true,
        Some(_) if t < *best_t => true,
        Some((bid, _, _)) => id < bid,
    };
    if better {
        *best_t = t;
        *best = Some((id, u, v));
    }
}

/// Store triangle `id` with corners `tv` in `lane` of a packet.
pub(super) fn put<const N: usize>(
    v: &mut [[f32; N]; 9],
    ids: &mut [u32; N],
    lane: usize,
    tv: [glam::Vec3; 3],
    id: u32,
) {
    for (k, p) in tv.iter().enumerate() {
        for a in 0..3 {
            v[3 * k + a][lane] = p[a];
        }
    }
    ids[lane] = id;
}

/// The first of the candidate lanes `m` of a packet (four or sixteen wide) whose triangle
/// `skip` does not leave out and is hit in `[tmin, tmax]` (its id), if any.
#[inline(always)]
pub(super) fn any_of<const N: usize, F: Fn(u32) -> bool>(
    r: &RayPre,
    v: &[[f32; N]; 9],
    ids: &[u32; N],
    mut m: u32,
    (tmin, tmax): (f32, f32),
    skip: &F,
) -> Option<u32> {
    while m != 0 {
        let i = m.trailing_zeros() as usize;
        m &= m - 1;
        if !skip(ids[i]) && intersect(r, &tri_of(v, i), tmin, tmax).is_some() {
            return Some(ids[i]);
        }
    }
    None
}

/// Closest hit among the candidate lanes `m` of a packet (four or sixteen wide) nearer than
/// `*best_t` (see [`Layout::closest_hit`]).
#[inline(always)]
pub(super) fn closest_of<const N: usize>(
    r: &RayPre,
    v: &[[f32; N]; 9],
    ids: &[u32; N],
    mut m: u32,
    tmin: f32,
    best_t: &mut f32,
    best: &mut Option<(u32, f32, f32)>,
) {
    while m != 0 {
        let i = m.trailing_zeros() as usize;
        m &= m - 1;
        if let Some(x) = intersect(r, &tri_of(v, i), tmin, *best_t) {
            take_closer(best_t, best, ids[i], x);
        }
    }
}
