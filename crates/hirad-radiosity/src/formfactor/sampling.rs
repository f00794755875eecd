//! Sampling helpers: area-uniform points of triangles (whole, or the part above a plane),
//! stratified and jittered-grid 2-D samples.

use super::analytic::clip_to_hemisphere;
use glam::{DVec3, Vec3};
use hirad_core::rng::SplitMix64;

/// Area-uniform point, from two uniform numbers in [0, 1), of the part of triangle `v` that
/// lies above the plane through `x` with normal `n`; `None` when no part of it does. A shadow
/// ray from `x` is aimed at the part of the source that its kernel counts.
/// Points keep `margin` from the triangle's edges ([`sample_triangle_inset`]).
pub fn sample_triangle_above(
    x: Vec3,
    n: Vec3,
    v: &[Vec3; 3],
    uv: (f32, f32),
    margin: f32,
) -> Option<Vec3> {
    sample_triangle_above_area(x, n, v, uv, margin, 0.0).map(|p| p.0)
}

/// [`sample_triangle_above`] with the area of the part above the plane, over which the point
/// is uniform (`area`, the triangle's, when all of it is above).
pub fn sample_triangle_above_area(
    x: Vec3,
    n: Vec3,
    v: &[Vec3; 3],
    (u1, u2): (f32, f32),
    margin: f32,
    area: f64,
) -> Option<(Vec3, f64)> {
    let xd = x.as_dvec3();
    let nd = n.as_dvec3();
    if v.iter().all(|p| nd.dot(p.as_dvec3() - xd) >= 0.0) {
        return Some((sample_triangle_inset(v, u1, u2, margin), area));
    }
    let mut c = [DVec3::ZERO; 16];
    let m = clip_to_hemisphere(xd, nd, &v.map(|p| p.as_dvec3()), &mut c);
    if m < 3 {
        return None;
    }
    // Pick a triangle of the fan (c0, ci, ci+1) by area, then a point on it.
    let areas: Vec<f64> = (1..m - 1)
        .map(|i| (c[i] - c[0]).cross(c[i + 1] - c[0]).length())
        .collect();
    let total: f64 = areas.iter().sum();
    if total <= 0.0 {
        return None;
    }
    let mut target = u1 as f64 * total;
    let mut i = 0;
    while i + 1 < areas.len() && target >= areas[i] {
        target -= areas[i];
        i += 1;
    }
    let u = (target / areas[i].max(1e-300)).clamp(0.0, 0.999_999_9) as f32;
    let t = [c[0], c[i + 1], c[i + 2]].map(|p| p.as_vec3());
    Some((sample_triangle_inset(&t, u, u2, margin), 0.5 * total))
}

/// Point of a triangle from two uniform numbers in [0, 1) (area-uniform warp).
#[inline]
pub fn sample_triangle(v: &[Vec3; 3], u1: f32, u2: f32) -> Vec3 {
    at(v, warp(u1, u2))
}

/// Barycentric coordinates of the area-uniform warp of `(u1, u2)`.
#[inline]
fn warp(u1: f32, u2: f32) -> [f32; 3] {
    let s = u1.sqrt();
    [1.0 - s, s * (1.0 - u2), s * u2]
}

/// The point of triangle `v` with barycentric coordinates `b`.
#[inline]
fn at(v: &[Vec3; 3], b: [f32; 3]) -> Vec3 {
    v[0] * b[0] + v[1] * b[1] + v[2] * b[2]
}

/// [`sample_triangle`] kept `margin` (a length) away from the triangle's edges, at most a
/// tenth of the way to the opposite vertex. Where surfaces meet at an edge, a point on it
/// rounds to either side of the other surface, and a shadow ray from there would pass
/// behind that surface (a floor lit through the foot of the wall standing on it).
#[inline]
pub fn sample_triangle_inset(v: &[Vec3; 3], u1: f32, u2: f32, margin: f32) -> Vec3 {
    let mut b = warp(u1, u2);
    if b.iter().any(|&x| x < MAX_INSET) {
        // Barycentric coordinate i is the distance to edge i over the altitude to it,
        // `2A / |e_i|`: a point is within the margin of edge i when `b_i·2A < margin·|e_i|`,
        // compared squared (no roots) and a little generously before the exact pass.
        let e = [v[2] - v[1], v[0] - v[2], v[1] - v[0]];
        let cross2 = e[2].cross(v[2] - v[0]).length_squared();
        let m2 = 1.01 * margin * margin;
        if (0..3).any(|i| b[i] < MAX_INSET && b[i] * b[i] * cross2 < m2 * e[i].length_squared()) {
            let twice_area = cross2.sqrt();
            let mut lo = [0.0f32; 3];
            for i in 0..3 {
                lo[i] = (margin * e[i].length() / twice_area.max(f32::MIN_POSITIVE)).min(MAX_INSET);
            }
            // Raise the coordinates below their floor and take the excess from the others in
            // proportion to what they have above theirs.
            let deficit: f32 = (0..3).map(|i| (lo[i] - b[i]).max(0.0)).sum();
            if deficit > 0.0 {
                let spare: f32 = (0..3).map(|i| (b[i] - lo[i]).max(0.0)).sum();
                for i in 0..3 {
                    b[i] = if b[i] <= lo[i] {
                        lo[i]
                    } else {
                        b[i] - deficit * (b[i] - lo[i]) / spare
                    };
                }
            }
        }
    }
    at(v, b)
}

/// Largest barycentric margin [`sample_triangle_inset`] keeps.
const MAX_INSET: f32 = 0.1;

/// `n` stratified (Latin hypercube) jittered 2-D samples in [0, 1)², appended to `out`.
pub fn stratified_2d(n: usize, rng: &mut SplitMix64, out: &mut impl Extend<[f32; 2]>) {
    let mut perm: smallvec::SmallVec<[usize; 16]> = (0..n).collect();
    for i in (1..n).rev() {
        let j = (rng.next_u64() % (i as u64 + 1)) as usize;
        perm.swap(i, j);
    }
    let inv = 1.0 / n as f32;
    out.extend(perm.iter().enumerate().map(|(k, &p)| {
        let u = ((k as f32 + rng.next_f32()) * inv).min(0.999_999_9);
        let v = ((p as f32 + rng.next_f32()) * inv).min(0.999_999_9);
        [u, v]
    }));
}

/// `k × k` jittered 2-D samples in [0, 1)², one per cell of a regular grid: stratified in
/// both dimensions together, unlike [`stratified_2d`], whose error on a function peaked in a
/// small region (a receiver close above a source) is that of plain Monte Carlo. Appended to
/// `out`.
pub fn jittered_grid(k: usize, rng: &mut SplitMix64, out: &mut impl Extend<[f32; 2]>) {
    let inv = 1.0 / k as f32;
    out.extend((0..k * k).map(|c| {
        let (i, j) = (c / k, c % k);
        let u = ((i as f32 + rng.next_f32()) * inv).min(0.999_999_9);
        let v = ((j as f32 + rng.next_f32()) * inv).min(0.999_999_9);
        [u, v]
    }));
}
