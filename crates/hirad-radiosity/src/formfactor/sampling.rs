//! Sampling helpers: points of triangles (whole, or the part above a plane), area-uniform or
//! by the solid angle they subtend; stratified and jittered-grid 2-D samples.

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
    let (i, u) = pick(&areas, u1 as f64, total);
    let t = [c[0], c[i + 1], c[i + 2]].map(|p| p.as_vec3());
    Some((sample_triangle_inset(&t, u as f32, u2, margin), 0.5 * total))
}

/// A point of the part of triangle `v` (area `area`) above the plane through `x` with normal
/// `n`, drawn nearly in proportion to its point-to-point kernel from `x`, i.e. to the solid
/// angle times `cos θ_x` (a bilinear warp of Arvo's; a clipped part's fan
/// triangle picked by solid angle), kept `margin` from the edges, with `cos θ_x / (π p)` (`p`
/// the density of the direction per solid angle) and the part's area. The mean of that
/// weight over the draws is the point-to-polygon form factor `F(x)`, so `weight · V / F(x)`
/// has the visible share of `F(x)` as its mean: visibility weighed by the point-to-point
/// kernel, where area-uniform points would weigh the near and far parts of a close source
/// alike. `None` when no part is above or its solid angle vanishes.
pub fn sample_triangle_solid_angle(
    x: Vec3,
    n: Vec3,
    v: &[Vec3; 3],
    (u1, u2): (f32, f32),
    margin: f32,
    area: f64,
) -> Option<(Vec3, f64, f64)> {
    let xd = x.as_dvec3();
    let nd = n.as_dvec3();
    let vd = v.map(|p| p.as_dvec3());
    // `scale`: the drawn direction's solid angle per unit density (`1 / p`).
    let (w, scale, over, p0, pn) = if vd.iter().all(|p| nd.dot(*p - xd) >= 0.0) {
        let dirs = vd.map(|p| (p - xd).normalize_or_zero());
        let (w, scale) = sample_cosine_spherical_triangle(dirs, nd, u1 as f64, u2 as f64)?;
        let pn = (vd[1] - vd[0]).cross(vd[2] - vd[0]);
        (w, scale, area, vd[0], pn)
    } else {
        let mut c = [DVec3::ZERO; 16];
        let m = clip_to_hemisphere(xd, nd, &vd, &mut c);
        if m < 3 {
            return None;
        }
        let mut dirs = [DVec3::ZERO; 16];
        for (d, p) in dirs.iter_mut().zip(&c[..m]) {
            *d = (*p - xd).normalize_or_zero();
        }
        // Solid angles of the fan's triangles.
        let mut omegas = [0.0f64; 14];
        for i in 1..m - 1 {
            omegas[i - 1] = solid_angle([dirs[0], dirs[i], dirs[i + 1]]);
        }
        let omegas = &omegas[..m - 2];
        let total: f64 = omegas.iter().sum();
        if total.is_nan() || total <= 1e-12 {
            return None;
        }
        let (i, u) = pick(omegas, u1 as f64, total);
        let tri = [dirs[0], dirs[i + 1], dirs[i + 2]];
        let (w, scale) = sample_cosine_spherical_triangle(tri, nd, u, u2 as f64)?;
        // The fan triangle's own weight `Ω_i / pdf` over its chance `Ω_i / Ω`.
        let scale = scale / omegas[i] * total;
        let over: f64 = (1..m - 1)
            .map(|i| 0.5 * (c[i] - c[0]).cross(c[i + 1] - c[0]).length())
            .sum();
        (w, scale, over, c[0], (c[1] - c[0]).cross(c[2] - c[0]))
    };
    if scale.is_nan() || scale <= 1e-12 {
        return None;
    }
    // The point where direction w meets the triangle's plane.
    let t = pn.dot(p0 - xd) / pn.dot(w);
    if !(t.is_finite() && t > 0.0) {
        return None;
    }
    let y = (xd + w * t).as_vec3();
    let weight = nd.dot(w).max(0.0) * scale / std::f64::consts::PI;
    Some((inset_point(v, y, margin), weight, over))
}

/// The entry of `weights` (summing to `total`) that `u · total` falls in, and `u` rescaled to
/// [0, 1) within it.
fn pick(weights: &[f64], u: f64, total: f64) -> (usize, f64) {
    let mut target = u * total;
    let mut i = 0;
    while i + 1 < weights.len() && target >= weights[i] {
        target -= weights[i];
        i += 1;
    }
    (i, (target / weights[i].max(1e-300)).clamp(0.0, 0.999_999_9))
}

/// Unit direction in the spherical triangle of unit vectors `[a, b, c]` drawn nearly in
/// proportion to its cosine with `n` (Arvo's warp of a bilinear warp whose corners weigh the
/// cosines at the vertices, as pbrt-v4 samples triangles), with its solid angle over its
/// density relative to the uniform one (`Ω / p`, `p` the bilinear density): so that
/// `cos θ · Ω / p` has the projected solid angle `π F` as its mean and nearly no spread.
fn sample_cosine_spherical_triangle(
    [a, b, c]: [DVec3; 3],
    n: DVec3,
    u1: f64,
    u2: f64,
) -> Option<(DVec3, f64)> {
    let cos = |d: DVec3| n.dot(d).max(0.01);
    let wts = [cos(b), cos(b), cos(a), cos(c)];
    // The bilinear density over [0, 1)² with these corner weights ((0, 0), (1, 0), (0, 1),
    // (1, 1)), drawn one coordinate after the other.
    let lerp = |t: f64, p: f64, q: f64| (1.0 - t) * p + t * q;
    let linear = |u: f64, p: f64, q: f64| {
        let x = u * (p + q) / (p + lerp(u, p * p, q * q).sqrt());
        x.min(1.0 - 1e-9)
    };
    let y = linear(u2, wts[0] + wts[1], wts[2] + wts[3]);
    let x = linear(u1, lerp(y, wts[0], wts[2]), lerp(y, wts[1], wts[3]));
    let pdf = 4.0
        * ((1.0 - x) * (1.0 - y) * wts[0]
            + x * (1.0 - y) * wts[1]
            + (1.0 - x) * y * wts[2]
            + x * y * wts[3])
        / wts.iter().sum::<f64>();
    let (w, omega) = sample_spherical_triangle([a, b, c], x, y)?;
    Some((w, omega / pdf))
}

/// Solid angle of the spherical triangle of unit vectors `[a, b, c]` (Van Oosterom and
/// Strackee).
fn solid_angle([a, b, c]: [DVec3; 3]) -> f64 {
    2.0 * a
        .dot(b.cross(c))
        .abs()
        .atan2(1.0 + a.dot(b) + b.dot(c) + c.dot(a))
}

/// Unit direction in the spherical triangle of unit vectors `[a, b, c]`, uniform in solid
/// angle, from two uniform numbers in [0, 1) (Arvo, "Stratified sampling of spherical
/// triangles", SIGGRAPH 1995), with the triangle's solid angle. `None` for a degenerate
/// triangle.
fn sample_spherical_triangle([a, b, c]: [DVec3; 3], u1: f64, u2: f64) -> Option<(DVec3, f64)> {
    let (nab, nca) = (a.cross(b), c.cross(a));
    if nab.length_squared() <= 0.0 || nca.length_squared() <= 0.0 {
        return None;
    }
    let (nab, nca) = (nab.normalize(), nca.normalize());
    // The angle α at a between the great circles through (a, b) and (a, c).
    let (cos_alpha, sin_alpha) = (-nab.dot(nca), nab.cross(nca).length());
    let area = solid_angle([a, b, c]);
    if area.is_nan() || area <= 0.0 {
        return None;
    }
    // The sub-triangle of area u1·A: its third vertex c' on the arc from a to c.
    let ap_pi = std::f64::consts::PI + u1 * area;
    let (s, co) = ap_pi.sin_cos();
    let sin_phi = s * cos_alpha - co * sin_alpha;
    let cos_phi = co * cos_alpha + s * sin_alpha;
    let k1 = cos_phi + cos_alpha;
    let k2 = sin_phi - sin_alpha * a.dot(b);
    let cos_bp = ((k2 + (k2 * cos_phi - k1 * sin_phi) * cos_alpha)
        / ((k2 * sin_phi + k1 * cos_phi) * sin_alpha))
        .clamp(-1.0, 1.0);
    if cos_bp.is_nan() {
        return None;
    }
    let sin_bp = (1.0 - cos_bp * cos_bp).max(0.0).sqrt();
    let cp = cos_bp * a + sin_bp * (c - c.dot(a) * a).normalize_or_zero();
    // Then a point on the arc from b to c', uniform in solid angle.
    let cos_theta = 1.0 - u2 * (1.0 - cp.dot(b));
    let sin_theta = (1.0 - cos_theta * cos_theta).max(0.0).sqrt();
    let w = cos_theta * b + sin_theta * (cp - cp.dot(b) * b).normalize_or_zero();
    (w.length_squared() > 0.5).then_some((w, area))
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
    at(v, inset(v, warp(u1, u2), margin))
}

/// Point `y` of triangle `v` kept `margin` from its edges as [`sample_triangle_inset`] keeps
/// its points.
#[inline]
fn inset_point(v: &[Vec3; 3], y: Vec3, margin: f32) -> Vec3 {
    let (e0, e1, p) = (v[1] - v[0], v[2] - v[0], y - v[0]);
    let (d00, d01, d11) = (e0.dot(e0), e0.dot(e1), e1.dot(e1));
    let (d20, d21) = (p.dot(e0), p.dot(e1));
    let den = d00 * d11 - d01 * d01;
    if den.is_nan() || den <= 0.0 {
        return y;
    }
    let b1 = ((d11 * d20 - d01 * d21) / den).clamp(0.0, 1.0);
    let b2 = ((d00 * d21 - d01 * d20) / den).clamp(0.0, 1.0 - b1);
    at(v, inset(v, [1.0 - b1 - b2, b1, b2], margin))
}

/// Barycentric coordinates `b` of triangle `v` moved `margin` (a length) away from its
/// edges, at most [`MAX_INSET`] of the way to the opposite vertex.
#[inline(always)]
fn inset(v: &[Vec3; 3], mut b: [f32; 3], margin: f32) -> [f32; 3] {
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
    b
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
