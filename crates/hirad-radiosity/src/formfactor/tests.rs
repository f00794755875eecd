use super::analytic::{parallel_disk_exact, point_to_disk, point_to_polygon};
use super::kernel::{draw_weighted, point_pair_kernel};
use super::near_field::closest_on_triangle;
use super::sampling::{
    sample_triangle, sample_triangle_inset, sample_triangle_solid_angle, stratified_2d,
};
use glam::{DVec3, Vec3};
use hirad_core::rng::SplitMix64;
use std::f64::consts::PI;

fn square(z: f64, up: bool) -> Vec<DVec3> {
    let mut p = vec![
        DVec3::new(0.0, 0.0, z),
        DVec3::new(1.0, 0.0, z),
        DVec3::new(1.0, 1.0, z),
        DVec3::new(0.0, 1.0, z),
    ];
    if !up {
        p.reverse();
    }
    p
}

#[test]
fn disk_estimate_matches_coaxial_closed_form() {
    for (h, r) in [(1.0, 0.5), (0.3, 1.0), (5.0, 0.1)] {
        let exact = parallel_disk_exact(h, 0.0, r);
        let est = point_to_disk(h * h, 1.0, 1.0, PI * r * r);
        assert!((exact - est).abs() < 1e-12, "{exact} {est}");
    }
    // Off axis, far away the estimate with the true cosines converges to the closed form.
    let (h, a, r) = (10.0, 3.0, 0.2);
    let exact = parallel_disk_exact(h, a, r);
    let d2 = h * h + a * a;
    let c = h / d2.sqrt();
    let est = point_to_disk(d2, c, c, PI * r * r);
    assert!(((exact - est) / exact).abs() < 1e-3, "{exact} {est}");
}

#[test]
fn polygon_form_factor_analytic_values() {
    // Point under the corner of a unit square at height 1: F = 0.13853 (tables).
    let sq = square(1.0, false);
    let f = point_to_polygon(DVec3::ZERO, DVec3::Z, &sq, -DVec3::Z);
    let a = 1.0 / 2f64.sqrt();
    let exact = (1.0 / (2.0 * PI)) * 2.0 * (a * (1.0f64 / 2f64.sqrt()).atan());
    assert!((f - exact).abs() < 1e-9, "{f} {exact}");
    assert!((f - 0.138_53).abs() < 1e-4);
    // Behind the emitting side: zero; a huge polygon fills the hemisphere: 1.
    assert_eq!(
        point_to_polygon(DVec3::ZERO, DVec3::Z, &square(1.0, true), DVec3::Z),
        0.0
    );
    let big = [
        DVec3::new(-1e4, -1e4, 1.0),
        DVec3::new(-1e4, 1e4, 1.0),
        DVec3::new(1e4, 1e4, 1.0),
        DVec3::new(1e4, -1e4, 1.0),
    ];
    let f = point_to_polygon(DVec3::ZERO, DVec3::Z, &big, -DVec3::Z);
    assert!((f - 1.0).abs() < 1e-3, "{f}");
    // A tilted receiver sees part of the polygon clipped by its horizon.
    let f = point_to_polygon(DVec3::ZERO, DVec3::X, &big, -DVec3::Z);
    assert!((f - 0.5).abs() < 1e-3, "{f}");
}

/// An edge's contour term against `atan2` written out, over many decades, both signs of the
/// dot product and the range boundaries of the reduction.
#[test]
fn edge_term_matches_atan2() {
    use super::analytic::edge_term;
    let mut rng = SplitMix64::new(8);
    let mut worst = 0.0f64;
    for i in 0..200_000 {
        let s = 10f64.powf(rng.next_f64() * 12.0 - 6.0);
        let cl = (rng.next_f64() + 1e-9) * s;
        let dot = (rng.next_f64() * 2.0 - 1.0) * 10f64.powf(rng.next_f64() * 12.0 - 6.0);
        let dot = match i % 1000 {
            0 => 0.0,
            1 => cl,
            2 => -cl,
            3 => cl / 2.414_213_562_373_095,
            4 => -cl / 0.66,
            _ => dot,
        };
        let cn = (rng.next_f64() * 2.0 - 1.0) * cl;
        let want = cl.atan2(dot) * cn / cl;
        let got = edge_term(cl, dot, cn);
        worst = worst.max((got - want).abs() / want.abs().max(1e-300));
    }
    assert!(worst < 4e-15, "worst relative error {worst:e}");
}

#[test]
fn closest_on_triangle_matches_a_dense_search() {
    let v = [
        Vec3::new(0.0, 0.0, 0.0),
        Vec3::new(2.0, 0.0, 0.0),
        Vec3::new(0.5, 1.5, 0.0),
    ];
    let mut rng = SplitMix64::new(5);
    let grid: Vec<Vec3> = (0..=200)
        .flat_map(|i| (0..=200 - i).map(move |j| (i, j)))
        .map(|(i, j)| {
            let (a, b) = (i as f32 / 200.0, j as f32 / 200.0);
            v[0] * (1.0 - a - b) + v[1] * a + v[2] * b
        })
        .collect();
    for _ in 0..200 {
        // Points in every Voronoi region: around, beside and above the triangle.
        let p = Vec3::new(
            rng.next_f32() * 5.0 - 1.5,
            rng.next_f32() * 4.0 - 1.5,
            rng.next_f32() * 2.0 - 1.0,
        );
        let q = closest_on_triangle(&v, p);
        let best = grid
            .iter()
            .map(|g| g.distance(p))
            .fold(f32::INFINITY, f32::min);
        assert!(
            q.distance(p) <= best + 1e-5,
            "{p:?}: {q:?} at {} > {best}",
            q.distance(p)
        );
        assert!(
            q.distance(p) >= best - 0.02,
            "{p:?}: {q:?} not on the triangle"
        );
    }
}

#[test]
fn stratified_samples_cover_strata() {
    let mut rng = SplitMix64::new(3);
    let mut s = Vec::new();
    stratified_2d(8, &mut rng, &mut s);
    let mut cu = [0; 8];
    let mut cv = [0; 8];
    for p in &s {
        cu[(p[0] * 8.0) as usize] += 1;
        cv[(p[1] * 8.0) as usize] += 1;
    }
    assert_eq!(cu, [1; 8]);
    assert_eq!(cv, [1; 8]);
}

#[test]
fn draws_follow_the_weights() {
    // Four points of seven weights: each item is drawn in proportion to its weight (the
    // expected count per draw is 4 w / Σw), a zero weight never; without positive weights,
    // evenly.
    let w = [1.0, 0.0, 3.0, 0.5, 0.5, 2.0, 1.0];
    let items: Vec<(Vec3, Vec3, f64)> = w.iter().map(|&w| (Vec3::ZERO, Vec3::ZERO, w)).collect();
    let mut rng = SplitMix64::new(3);
    let mut count = [0usize; 7];
    let draws = 20_000;
    for _ in 0..draws {
        let d = draw_weighted(&items, &mut rng);
        assert_eq!(d.len(), 4);
        for i in d {
            count[i] += 1;
        }
    }
    let total: f64 = w.iter().sum();
    for (i, &c) in count.iter().enumerate() {
        let expected = draws as f64 * 4.0 * w[i] / total;
        assert!(
            (c as f64 - expected).abs() <= 0.02 * expected + 1e-9,
            "item {i}: {c} draws, expected {expected}"
        );
    }
    let flat: Vec<(Vec3, Vec3, f64)> = (0..8).map(|_| (Vec3::ZERO, Vec3::ZERO, 0.0)).collect();
    let mut seen = [0usize; 8];
    for _ in 0..1000 {
        for i in draw_weighted(&flat, &mut rng) {
            seen[i] += 1;
        }
    }
    assert!(seen.iter().all(|&c| c > 400 && c < 600), "{seen:?}");
}

#[test]
fn point_pair_kernel_is_cos_cos_over_r_squared() {
    // Points 2 apart along z facing each other: 1/4; tilted by 60° at one end: 1/8; facing
    // away: 0; no normal at x counts as facing y. With a cell of radius R around y: the
    // coaxial disk's form factor per unit area, 1/(r² + R²), which stays finite at r = 0.
    let (x, y) = (Vec3::ZERO, Vec3::new(0.0, 0.0, 2.0));
    assert!((point_pair_kernel(x, Some(Vec3::Z), y, -Vec3::Z, 0.0) - 0.25).abs() < 1e-12);
    let tilted = Vec3::new((60f32).to_radians().sin(), 0.0, (60f32).to_radians().cos());
    assert!((point_pair_kernel(x, Some(tilted), y, -Vec3::Z, 0.0) - 0.125).abs() < 1e-7);
    assert_eq!(point_pair_kernel(x, Some(-Vec3::Z), y, -Vec3::Z, 0.0), 0.0);
    assert_eq!(point_pair_kernel(x, Some(Vec3::Z), y, Vec3::Z, 0.0), 0.0);
    assert!((point_pair_kernel(x, None, y, -Vec3::Z, 0.0) - 0.25).abs() < 1e-12);
    let r2_cell = 0.5;
    let disk = point_to_disk(4.0, 1.0, 1.0, PI * r2_cell);
    let k = point_pair_kernel(x, Some(Vec3::Z), y, -Vec3::Z, r2_cell);
    assert!((k - disk / r2_cell).abs() < 1e-9, "{k} against {disk}");
}

/// Inset points keep the margin from every edge (also at the corners, where two
/// coordinates are raised), stay inside, and elsewhere are the plain area-uniform points.
#[test]
fn inset_points_keep_their_margin_from_the_edges() {
    let v = [
        Vec3::new(1.0, 0.0, 0.0),
        Vec3::new(1.0, 0.0, 0.125),
        Vec3::new(1.125, 0.0, 0.125),
    ];
    let margin = 1e-3f32;
    let dist = |p: Vec3, a: Vec3, b: Vec3| (p - a).cross((b - a).normalize()).length();
    let mut rng = SplitMix64::new(11);
    let mut moved = 0;
    let corners = [0.0, 1e-9, 1e-4, 0.5, 1.0 - 1e-7];
    let mut us: Vec<(f32, f32)> = corners
        .iter()
        .flat_map(|&a| corners.iter().map(move |&b| (a, b)))
        .collect();
    us.extend((0..10_000).map(|_| (rng.next_f32(), rng.next_f32())));
    for (u1, u2) in us {
        let p = sample_triangle_inset(&v, u1, u2, margin);
        let q = sample_triangle(&v, u1, u2);
        let d = [
            dist(p, v[1], v[2]),
            dist(p, v[2], v[0]),
            dist(p, v[0], v[1]),
        ];
        for d in d {
            assert!(d >= 0.999 * margin, "{u1} {u2}: {d}");
        }
        let dq = [
            dist(q, v[1], v[2]),
            dist(q, v[2], v[0]),
            dist(q, v[0], v[1]),
        ];
        if dq.iter().all(|&d| d >= 1.001 * margin) {
            assert!((p - q).length() < 1e-6, "{u1} {u2}: moved {p} from {q}");
        } else {
            moved += 1;
        }
    }
    // Only points within the margin move: the strip along the perimeter, of area about
    // perimeter × margin, holds that share of the random points (the 25 corner cases aside).
    let perimeter = (v[1] - v[0]).length() + (v[2] - v[1]).length() + (v[0] - v[2]).length();
    let area = 0.5 * (v[1] - v[0]).cross(v[2] - v[0]).length();
    let expected = 10_000.0 * perimeter * margin / area;
    let random = (moved as f32 - 25.0).max(0.0);
    assert!(
        (random - expected).abs() < 0.2 * expected,
        "{moved} points moved, expected about {expected}"
    );
}

#[cfg(target_arch = "x86_64")]
#[test]
fn contour_avx_gives_the_bits_of_the_scalar_sum() {
    use super::analytic::{contour_scalar, contours_avx};
    if !std::arch::is_x86_feature_detected!("avx") {
        return;
    }
    let mut rng = hirad_core::rng::SplitMix64::new(11);
    let mut v = |s: f64| {
        let e = (rng.next_u64() % 12) as i32 - 6;
        DVec3::new(
            rng.next_f64() - 0.5,
            rng.next_f64() - 0.5,
            rng.next_f64() - 0.5,
        ) * s
            * 2f64.powi(e)
    };
    for i in 0..50_000 {
        // Five contours of three or four corners (padded to four), done together.
        let n = v(1.0).normalize_or(DVec3::Z);
        let corners = |k: usize| 3 + (i + k) % 2;
        let quads: Vec<(usize, DVec3, [DVec3; 4])> = (0..5)
            .map(|k| {
                let m = corners(k);
                let mut q = [DVec3::ZERO; 4];
                for c in q.iter_mut().take(m) {
                    *c = v(1.0);
                }
                q[3] = q[m - 1];
                let x = if (i + k) % 7 == 0 { q[0] } else { v(4.0) };
                (k, x, q)
            })
            .collect();
        let mut fast = [f64::NAN; 5];
        // SAFETY: AVX is present (checked above).
        unsafe { contours_avx(&quads, n, &mut fast) };
        for &(k, x, q) in &quads {
            let m = corners(k);
            assert_eq!(
                fast[k].to_bits(),
                contour_scalar(x, n, &q[..m]).to_bits(),
                "{q:?} {x} {n}"
            );
        }
    }
}

/// Many points at once give each point's value one edge at a time, bit for bit: points
/// behind the polygon, above it, beside it (clipped), more than one batch.
#[test]
fn many_points_give_the_bits_of_one_point_at_a_time() {
    use super::analytic::{contour_scalar, facing_part, point_to_polygon_many};
    let mut rng = SplitMix64::new(5);
    let mut r = || rng.next_f64() - 0.5;
    for m in [3usize, 4, 6] {
        for _ in 0..2_000 {
            // A convex polygon in the plane z = 0 (regular, scaled, shifted), facing ±z.
            let (s, dx, dy) = (1.0 + r(), r(), r());
            let mut poly: Vec<DVec3> = (0..m)
                .map(|k| {
                    let a = std::f64::consts::TAU * k as f64 / m as f64;
                    DVec3::new(dx + s * a.cos(), dy + s * a.sin(), 0.0)
                })
                .collect();
            let up = r() > 0.0;
            if !up {
                poly.reverse();
            }
            let normal = if up { DVec3::Z } else { -DVec3::Z };
            let n = DVec3::new(r(), r(), r()).normalize_or(DVec3::Z);
            let xs: Vec<DVec3> = (0..19)
                .map(|_| DVec3::new(4.0 * r(), 4.0 * r(), 2.0 * r()))
                .collect();
            let mut out = vec![f64::NAN; xs.len()];
            point_to_polygon_many(&xs, n, &poly, normal, &mut out);
            for (j, &x) in xs.iter().enumerate() {
                let mut buf = [DVec3::ZERO; 16];
                let one = facing_part(x, n, &poly, normal, &mut buf)
                    .map_or(0.0, |pts| contour_scalar(x, n, pts));
                assert_eq!(out[j].to_bits(), one.to_bits(), "point {j}, {m} corners");
            }
        }
    }
}

/// Points drawn by (cosine-weighted) solid angle: their weights' mean is the analytic
/// point-to-polygon form factor (which an error in the warps, their densities or the fan's
/// solid angles would miss), each point lies on the part of the triangle above the receiver's
/// plane, and the weights give a sub-region the share of the form factor it subtends.
#[test]
fn solid_angle_draws_average_to_the_form_factor() {
    let tris = [
        // Under the receiver, far and near; a wall beside it, partly behind its plane; tilted.
        [
            Vec3::new(-1.0, -1.0, 1.0),
            Vec3::new(2.0, -1.0, 1.0),
            Vec3::new(0.0, 2.0, 1.0),
        ],
        [
            Vec3::new(0.1, 0.0, 0.02),
            Vec3::new(0.3, 0.1, 0.02),
            Vec3::new(0.0, 0.3, 0.02),
        ],
        [
            Vec3::new(0.2, -1.0, -0.5),
            Vec3::new(0.2, 1.0, -0.5),
            Vec3::new(0.2, 0.0, 1.5),
        ],
        [
            Vec3::new(-0.5, 0.3, 0.1),
            Vec3::new(0.5, 0.6, 0.9),
            Vec3::new(0.4, -0.7, 0.3),
        ],
    ];
    let (x, n) = (Vec3::ZERO, Vec3::Z);
    let mut rng = SplitMix64::new(7);
    for v in tris {
        let poly = v.map(|p| p.as_dvec3());
        let pn = (poly[1] - poly[0]).cross(poly[2] - poly[0]).normalize();
        // The form factor counts the side facing x.
        let pn = if pn.dot(poly[0]) > 0.0 { -pn } else { pn };
        let exact = point_to_polygon(x.as_dvec3(), n.as_dvec3(), &poly, pn);
        let area = 0.5 * (v[1] - v[0]).cross(v[2] - v[0]).length() as f64;
        let centre = (v[0] + v[1] + v[2]) / 3.0;
        let mut samples = Vec::new();
        stratified_2d(4096, &mut rng, &mut samples);
        let (mut sum, mut near) = (0.0, 0.0);
        for u in &samples {
            let (y, w, _) = sample_triangle_solid_angle(x, n, &v, (u[0], u[1]), 0.0, area)
                .expect("a part above the plane");
            assert!(n.dot(y - x) >= -1e-5, "{y} below the plane");
            let on_plane = pn.as_vec3().dot(y - v[0]).abs();
            assert!(
                on_plane < 1e-4,
                "{y} off the triangle's plane by {on_plane}"
            );
            sum += w;
            if y.distance(x) < centre.distance(x) {
                near += w;
            }
        }
        let mean = sum / samples.len() as f64;
        assert!(
            (mean / exact - 1.0).abs() < 0.01,
            "mean weight {mean} against F = {exact}"
        );
        // The weights' share nearer than the centre against brute force over a fine
        // area-uniform grid of the same triangle (the kernel `cos θ_x cos θ_y / r²`).
        let (mut f_near, mut f_all) = (0.0, 0.0);
        let k = 400;
        for i in 0..k {
            for j in 0..k {
                let y =
                    sample_triangle(&v, (i as f32 + 0.5) / k as f32, (j as f32 + 0.5) / k as f32);
                let d = (y - x).as_dvec3();
                let cx = n.as_dvec3().dot(d);
                if cx <= 0.0 {
                    continue;
                }
                let f = cx * pn.dot(-d).abs() / d.length_squared().powi(2);
                f_all += f;
                if y.distance(x) < centre.distance(x) {
                    f_near += f;
                }
            }
        }
        let share = near / sum;
        assert!(
            (share - f_near / f_all).abs() < 0.02,
            "weights nearer than the centre {share}, form factor share {}",
            f_near / f_all
        );
    }
}
