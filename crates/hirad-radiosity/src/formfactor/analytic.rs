//! Analytic form factors: the point-to-disk estimate, the closed form of a parallel disk, and
//! the point-to-polygon form factor (Lambert's contour integral, as in Nusselt's analogy).

use glam::DVec3;
use std::f64::consts::PI;

/// Point-to-disk estimate of the form factor from a differential area to a disk of area
/// `area` at squared distance `r2`: `A cos θ_r cos θ_s / (π r² + A)` (zero when either cosine
/// is not positive). Exact for a coaxial, parallel disk.
#[inline]
pub fn point_to_disk(r2: f64, cos_r: f64, cos_s: f64, area: f64) -> f64 {
    if cos_r <= 0.0 || cos_s <= 0.0 {
        return 0.0;
    }
    area * cos_r * cos_s / (PI * r2 + area)
}

/// Closed-form form factor from a differential area to a parallel disk of radius `radius` at
/// height `h`, the receiving point offset by `a` from the disk axis (both facing each other).
pub fn parallel_disk_exact(h: f64, a: f64, radius: f64) -> f64 {
    let (h2, a2, r2) = (h * h, a * a, radius * radius);
    let z = h2 + a2 + r2;
    0.5 * (1.0 - (z - 2.0 * r2) / (z * z - 4.0 * a2 * r2).sqrt())
}

/// `atan2(y, x)` for `y ≥ 0` (an angle in [0, π]), to about 2 ulp: the Cephes rational
/// approximation of `atan` with its range reduction. The form factor kernel spends most of its
/// time here, and libm's correctly rounded `atan2` is several times slower.
#[inline]
pub fn angle_from(y: f64, x: f64) -> f64 {
    const P: [f64; 5] = [
        -8.750_608_600_031_904e-1,
        -1.615_753_718_733_365e1,
        -7.500_855_792_314_705e1,
        -1.228_866_684_490_136e2,
        -6.485_021_904_942_025e1,
    ];
    const Q: [f64; 5] = [
        2.485_846_490_142_306e1,
        1.650_270_098_316_988_5e2,
        4.328_810_604_912_903e2,
        4.853_903_996_359_137e2,
        1.945_506_571_482_614e2,
    ];
    const T3P8: f64 = 2.414_213_562_373_095; // tan(3π/8)
    const MOREBITS: f64 = 6.123_233_995_736_766e-17; // π/2 − fl(π/2)
    if y == 0.0 {
        return if x < 0.0 { PI } else { 0.0 };
    }
    if x == 0.0 {
        return PI / 2.0;
    }
    let r = y / x.abs();
    let (y0, z, more) = if r > T3P8 {
        (PI / 2.0, -1.0 / r, MOREBITS)
    } else if r <= 0.66 {
        (0.0, r, 0.0)
    } else {
        (PI / 4.0, (r - 1.0) / (r + 1.0), 0.5 * MOREBITS)
    };
    let zz = z * z;
    let p = (((P[0] * zz + P[1]) * zz + P[2]) * zz + P[3]) * zz + P[4];
    let q = ((((zz + Q[0]) * zz + Q[1]) * zz + Q[2]) * zz + Q[3]) * zz + Q[4];
    let t = y0 + (z * zz * p / q + more) + z;
    if x < 0.0 {
        PI - t
    } else {
        t
    }
}

/// Analytic form factor from a differential area at `x` with unit normal `n` to the planar
/// convex polygon `poly` (counter-clockwise around `poly_normal`, its emitting side).
///
/// The polygon is clipped to the hemisphere above `x`; zero when `x` lies behind the polygon
/// (one-sided emission) or the polygon is entirely below the receiver's horizon.
pub fn point_to_polygon(x: DVec3, n: DVec3, poly: &[DVec3], poly_normal: DVec3) -> f64 {
    if poly.len() < 3 || (x - poly[0]).dot(poly_normal) <= 0.0 {
        return 0.0;
    }
    let mut buf = [DVec3::ZERO; 16];
    // Clipped only when part of it lies below the horizon (the polygon as it is otherwise).
    let pts: &[DVec3] = if poly.iter().all(|&p| n.dot(p - x) >= 0.0) {
        poly
    } else {
        let m = clip_to_hemisphere(x, n, poly, &mut buf);
        if m < 3 {
            return 0.0;
        }
        &buf[..m]
    };
    let m = pts.len();
    let mut sum = 0.0;
    for e in 0..m {
        let a = pts[e] - x;
        let b = pts[(e + 1) % m] - x;
        let c = a.cross(b);
        let cl = c.length();
        if cl <= 0.0 {
            continue;
        }
        let theta = angle_from(cl, a.dot(b));
        sum += theta * c.dot(n) / cl;
    }
    (sum.abs() / (2.0 * PI)).min(1.0)
}

/// The part of the convex polygon `poly` above the plane through `x` with normal `n`
/// (Sutherland–Hodgman), written to `clipped`: the number of its corners (below 3: nothing is
/// above).
pub(super) fn clip_to_hemisphere(
    x: DVec3,
    n: DVec3,
    poly: &[DVec3],
    clipped: &mut [DVec3; 16],
) -> usize {
    let mut m = 0usize;
    let k = poly.len().min(15);
    for e in 0..k {
        let a = poly[e];
        let b = poly[(e + 1) % k];
        let da = n.dot(a - x);
        let db = n.dot(b - x);
        if da >= 0.0 {
            clipped[m] = a;
            m += 1;
        }
        if (da >= 0.0) != (db >= 0.0) && m < 16 {
            let t = da / (da - db);
            clipped[m] = a + (b - a) * t;
            m += 1;
        }
    }
    m
}
