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

/// Cephes' rational approximation of `atan` on [−0.42, 0.42]: numerator and denominator
/// ([`edge_term`]).
const ATAN_P: [f64; 5] = [
    -8.750_608_600_031_904e-1,
    -1.615_753_718_733_365e1,
    -7.500_855_792_314_705e1,
    -1.228_866_684_490_136e2,
    -6.485_021_904_942_025e1,
];
const ATAN_Q: [f64; 5] = [
    2.485_846_490_142_306e1,
    1.650_270_098_316_988_5e2,
    4.328_810_604_912_903e2,
    4.853_903_996_359_137e2,
    1.945_506_571_482_614e2,
];
/// tan(3π/8).
const T3P8: f64 = 2.414_213_562_373_095;
/// π/2 − fl(π/2).
const MOREBITS: f64 = 6.123_233_995_736_766e-17;

/// One edge's term `θ (c·n)/|c|` of Lambert's contour sum, from `cl = |c| > 0` (`c` the cross
/// product of the edge's ends seen from the point), `dot` (their dot product, so that `θ` is
/// `atan2(cl, dot)`) and `cn = c·n`, to a few ulp. `θ` is Cephes' rational approximation of
/// `atan` with its range reduction (libm's correctly rounded `atan2` is several times slower),
/// arranged for two divisions: the reduced argument `z` straight from `cl` and `|dot|`, and
/// `θ = A + B/q` (`A = y₀ + z + more`, `B = z³p`) brought over the final division by `cl`:
/// `θ·cn/cl = (A·q + B)·cn / (q·cl)`. The form factor kernel waits on these divisions.
#[inline]
pub(super) fn edge_term(cl: f64, dot: f64, cn: f64) -> f64 {
    let ad = dot.abs();
    let big = cl > T3P8 * ad;
    let mid = !big && cl > 0.66 * ad;
    let (y0, more, num, den) = if big {
        (PI / 2.0, MOREBITS, -ad, cl)
    } else if mid {
        (PI / 4.0, 0.5 * MOREBITS, cl - ad, cl + ad)
    } else {
        (0.0, 0.0, cl, ad)
    };
    let z = num / den;
    let zz = z * z;
    let [p0, p1, p2, p3, p4] = ATAN_P;
    let [q0, q1, q2, q3, q4] = ATAN_Q;
    let p = (((p0 * zz + p1) * zz + p2) * zz + p3) * zz + p4;
    let q = ((((zz + q0) * zz + q1) * zz + q2) * zz + q3) * zz + q4;
    let a = y0 + more + z;
    let b = z * zz * p;
    // θ q: π − θ when the edge's ends are more than 90° apart.
    let tq = if dot < 0.0 {
        (PI - a) * q - b
    } else {
        a * q + b
    };
    tq * cn / (q * cl)
}

/// Analytic form factor from a differential area at `x` with unit normal `n` to the planar
/// convex polygon `poly` (counter-clockwise around `poly_normal`, its emitting side).
///
/// The polygon is clipped to the hemisphere above `x`; zero when `x` lies behind the polygon
/// (one-sided emission) or the polygon is entirely below the receiver's horizon.
pub fn point_to_polygon(x: DVec3, n: DVec3, poly: &[DVec3], poly_normal: DVec3) -> f64 {
    let mut out = [0.0];
    point_to_polygon_many(&[x], n, poly, poly_normal, &mut out);
    out[0]
}

/// Points done together by [`point_to_polygon_many`].
const BATCH: usize = 8;

/// [`point_to_polygon`] at each point of `xs` (all with normal `n`), written to `out`, with the
/// same bits: the parts of the polygon the points see are found first, then their contour
/// sums computed one after the other without a branch between them, so that the processor
/// overlaps one point's chain of divisions with the next point's.
pub fn point_to_polygon_many(
    xs: &[DVec3],
    n: DVec3,
    poly: &[DVec3],
    poly_normal: DVec3,
    out: &mut [f64],
) {
    assert_eq!(xs.len(), out.len(), "one output per point");
    let mut buf = [DVec3::ZERO; 16];
    for (xs, out) in xs.chunks(BATCH).zip(out.chunks_mut(BATCH)) {
        // Contours of at most four corners, padded to four (a repeated last corner adds a
        // zero edge): (output index, point, corners).
        let mut quads = [(0usize, DVec3::ZERO, [DVec3::ZERO; 4]); BATCH];
        let mut k = 0;
        for (i, &x) in xs.iter().enumerate() {
            out[i] = match facing_part(x, n, poly, poly_normal, &mut buf) {
                None => 0.0,
                Some(pts) if pts.len() <= 4 => {
                    let last = pts[pts.len() - 1];
                    let mut q = [last; 4];
                    q[..pts.len()].copy_from_slice(pts);
                    quads[k] = (i, x, q);
                    k += 1;
                    continue;
                }
                Some(pts) => contour_scalar(x, n, pts),
            };
        }
        contours(&quads[..k], n, out);
    }
}

/// The part of `poly` that a point at `x` with normal `n` sees of it: `None` when `x` lies
/// behind the polygon (one-sided emission) or nothing of it is above the horizon; the polygon
/// itself when all of it is above; else its part above, clipped into `buf`.
pub(super) fn facing_part<'a>(
    x: DVec3,
    n: DVec3,
    poly: &'a [DVec3],
    poly_normal: DVec3,
    buf: &'a mut [DVec3; 16],
) -> Option<&'a [DVec3]> {
    if poly.len() < 3 || (x - poly[0]).dot(poly_normal) <= 0.0 {
        return None;
    }
    if poly.iter().all(|&p| n.dot(p - x) >= 0.0) {
        return Some(poly);
    }
    let m = clip_to_hemisphere(x, n, poly, buf);
    (m >= 3).then(|| &buf[..m])
}

/// Lambert's contour sums of `quads` (output index, point, four corners), written to `out`:
/// the AVX path where the CPU has it, the same operations lane by lane, so the same bits as
/// [`contour_scalar`].
fn contours(quads: &[(usize, DVec3, [DVec3; 4])], n: DVec3, out: &mut [f64]) {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx") {
        // SAFETY: the CPU supports AVX (checked above).
        return unsafe { contours_avx(quads, n, out) };
    }
    for &(i, x, q) in quads {
        out[i] = contour_scalar(x, n, &q);
    }
}

/// Lambert's contour sum `Σ_e θ_e (c_e·n)/|c_e|` over the edges of `pts` seen from `x`
/// (`c_e` the cross product of an edge's ends, `θ_e` the angle between them), over 2π, one
/// edge at a time.
pub(super) fn contour_scalar(x: DVec3, n: DVec3, pts: &[DVec3]) -> f64 {
    let m = pts.len();
    let mut sum = 0.0;
    for e in 0..m {
        let a = pts[e] - x;
        let b = pts[if e + 1 == m { 0 } else { e + 1 }] - x;
        let c = a.cross(b);
        let cl = c.length();
        if cl <= 0.0 {
            continue;
        }
        sum += edge_term(cl, a.dot(b), c.dot(n));
    }
    (sum.abs() / (2.0 * PI)).min(1.0)
}

/// [`contours`], the four edges of a contour in the four AVX lanes: glam's cross and dot
/// products and [`edge_term`] written out with the same operations in the same order, and the
/// edges' terms summed in edge order (a zero edge adds nothing).
///
/// # Safety
/// The CPU must support AVX.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx")]
pub(super) unsafe fn contours_avx(quads: &[(usize, DVec3, [DVec3; 4])], n: DVec3, out: &mut [f64]) {
    use std::arch::x86_64::*;
    for &(i, x, pts) in quads {
        // [component][edge]: the edge's first and second end relative to x.
        let (mut a, mut b) = ([[0.0f64; 4]; 3], [[0.0f64; 4]; 3]);
        for e in 0..4 {
            let p = pts[e] - x;
            let q = pts[(e + 1) % 4] - x;
            for (k, (pk, qk)) in [(p.x, q.x), (p.y, q.y), (p.z, q.z)].into_iter().enumerate() {
                a[k][e] = pk;
                b[k][e] = qk;
            }
        }
        let (add, sub, mul, div) = (_mm256_add_pd, _mm256_sub_pd, _mm256_mul_pd, _mm256_div_pd);
        let splat = _mm256_set1_pd;
        let [ax, ay, az] = a.map(|v| _mm256_loadu_pd(v.as_ptr()));
        let [bx, by, bz] = b.map(|v| _mm256_loadu_pd(v.as_ptr()));
        let cx = sub(mul(ay, bz), mul(by, az));
        let cy = sub(mul(az, bx), mul(bz, ax));
        let cz = sub(mul(ax, by), mul(bx, ay));
        let cl = _mm256_sqrt_pd(add(add(mul(cx, cx), mul(cy, cy)), mul(cz, cz)));
        let dot = add(add(mul(ax, bx), mul(ay, by)), mul(az, bz));
        let cn = add(
            add(mul(cx, splat(n.x)), mul(cy, splat(n.y))),
            mul(cz, splat(n.z)),
        );
        // edge_term(cl, dot, cn), cl > 0 on the lanes that count.
        let ad = _mm256_andnot_pd(splat(-0.0), dot);
        let big = _mm256_cmp_pd::<_CMP_GT_OQ>(cl, mul(splat(T3P8), ad));
        let mid = _mm256_andnot_pd(big, _mm256_cmp_pd::<_CMP_GT_OQ>(cl, mul(splat(0.66), ad)));
        let pick = |low: __m256d, m: __m256d, b: __m256d| {
            _mm256_blendv_pd(_mm256_blendv_pd(low, m, mid), b, big)
        };
        let y0 = pick(splat(0.0), splat(PI / 4.0), splat(PI / 2.0));
        let more = pick(splat(0.0), splat(0.5 * MOREBITS), splat(MOREBITS));
        let num = pick(cl, sub(cl, ad), _mm256_xor_pd(ad, splat(-0.0)));
        let den = pick(ad, add(cl, ad), cl);
        let z = div(num, den);
        let zz = mul(z, z);
        let mut p = splat(ATAN_P[0]);
        for &c in &ATAN_P[1..] {
            p = add(mul(p, zz), splat(c));
        }
        let mut q = add(zz, splat(ATAN_Q[0]));
        for &c in &ATAN_Q[1..] {
            q = add(mul(q, zz), splat(c));
        }
        let a = add(add(y0, more), z);
        let b = mul(mul(z, zz), p);
        let neg = _mm256_cmp_pd::<_CMP_LT_OQ>(dot, splat(0.0));
        let tq = _mm256_blendv_pd(add(mul(a, q), b), sub(mul(sub(splat(PI), a), q), b), neg);
        let term = div(mul(tq, cn), mul(q, cl));
        let counts = _mm256_cmp_pd::<_CMP_GT_OQ>(cl, splat(0.0));
        let mut t = [0.0f64; 4];
        _mm256_storeu_pd(t.as_mut_ptr(), _mm256_and_pd(term, counts));
        let sum = ((t[0] + t[1]) + t[2]) + t[3];
        out[i] = (sum.abs() / (2.0 * PI)).min(1.0);
    }
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
