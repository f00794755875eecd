//! Rasteriser: coverage, watertightness, perspective-correct Gouraud interpolation, depth test,
//! near-plane clipping, supersampling, back faces, determinism.

use glam::Vec3;
use hirad::render::raster::{rasterize_with_stats, RasterStats};
use hirad::render::{
    rasterize, render_solution, BackFaces, CameraView, Image, MeshColors, RasterMesh, RasterOptions,
};
use hirad::rng::SplitMix64;
use hirad::scene::export::ColoredMesh;

/// Camera at z = 5 looking down −Z, +Y up, 90° vertical fov, square image of `n` pixels.
fn front_view(n: u32) -> CameraView {
    CameraView {
        eye: Vec3::new(0.0, 0.0, 5.0),
        target: Vec3::ZERO,
        up: Vec3::Y,
        fov_deg: 90.0,
        width: n,
        height: n,
    }
}

/// Counter-clockwise (seen from +Z) quad [x0, x1] × [y0, y1] at height z.
fn quad(x0: f32, y0: f32, x1: f32, y1: f32, z: f32) -> (Vec<Vec3>, Vec<[u32; 3]>) {
    (
        vec![
            Vec3::new(x0, y0, z),
            Vec3::new(x1, y0, z),
            Vec3::new(x1, y1, z),
            Vec3::new(x0, y1, z),
        ],
        vec![[0, 1, 2], [0, 2, 3]],
    )
}

fn covered(img: &Image) -> usize {
    img.pixels.iter().filter(|p| p.x > 0.5).count()
}

fn white(n: usize) -> Vec<Vec3> {
    vec![Vec3::ONE; n]
}

#[test]
fn axis_aligned_quad_covers_exactly_the_pixel_centres_inside() {
    // 100 px image, 90° fov at distance 5: 1 world unit = 10 px, x_px = 50 + 10·x.
    let view = front_view(100);
    let (p, t) = quad(-2.025, -1.075, 3.125, 0.5125, 0.0);
    let c = white(p.len());
    let mesh = RasterMesh {
        positions: &p,
        triangles: &t,
        colors: MeshColors::PerVertex(&c),
    };
    let img = rasterize(&mesh, &view, &RasterOptions::default()).unwrap();
    // x_px ∈ [29.75, 81.25] → centres 30.5 ..= 80.5 → 51 columns.
    // y_px = 50 − 10·y ∈ [44.875, 60.75] → centres 45.5 ..= 60.5 → 16 rows.
    let mut expect = 0;
    for y in 0..100 {
        for x in 0..100 {
            let inside = (30..=80).contains(&x) && (45..=60).contains(&y);
            assert_eq!(img.get(x, y).x > 0.5, inside, "pixel ({x}, {y})");
            expect += inside as usize;
        }
    }
    assert_eq!(expect, 51 * 16);
    assert_eq!(covered(&img), 51 * 16);
}

#[test]
fn rotated_quad_coverage_is_its_area_within_the_edge_band() {
    let view = front_view(200);
    // A square of side 6 world units (120 px: 1 unit = 20 px) rotated by 30°, inside the
    // image (corners at 85 px from the centre).
    let (s, c) = 30f32.to_radians().sin_cos();
    let rot = |x: f32, y: f32| Vec3::new(c * x - s * y, s * x + c * y, 0.0);
    let p = vec![
        rot(-3.0, -3.0),
        rot(3.0, -3.0),
        rot(3.0, 3.0),
        rot(-3.0, 3.0),
    ];
    let t = vec![[0, 1, 2], [0, 2, 3]];
    let col = white(4);
    let mesh = RasterMesh {
        positions: &p,
        triangles: &t,
        colors: MeshColors::PerVertex(&col),
    };
    let img = rasterize(&mesh, &view, &RasterOptions::default()).unwrap();
    let n = covered(&img) as f64;
    let area = 120.0 * 120.0;
    // Pixels whose centre lies within half a pixel diagonal of the boundary can go either way.
    let band = 4.0 * 120.0 * std::f64::consts::FRAC_1_SQRT_2;
    assert!((n - area).abs() <= band, "covered {n}, area {area}");
    // Supersampled coverage is much closer to the area.
    let opts = RasterOptions {
        supersample: 4,
        ..Default::default()
    };
    let img = rasterize(&mesh, &view, &opts).unwrap();
    let sum: f64 = img.pixels.iter().map(|p| p.x as f64).sum();
    assert!((sum - area).abs() < 0.002 * area, "ss coverage {sum}");
}

/// A jittered grid of `k × k` cells over [−3, 3]², each split into two triangles (shared
/// edges): every interior pixel is covered exactly by the union, no cracks.
#[test]
fn tessellated_square_has_no_cracks() {
    let view = front_view(128);
    let k = 24;
    let mut rng = SplitMix64::new(7);
    let mut p = Vec::new();
    for j in 0..=k {
        for i in 0..=k {
            let mut x = -3.0 + 6.0 * i as f32 / k as f32;
            let mut y = -3.0 + 6.0 * j as f32 / k as f32;
            if i > 0 && i < k && j > 0 && j < k {
                x += (rng.next_f32() - 0.5) * 0.2;
                y += (rng.next_f32() - 0.5) * 0.2;
            }
            p.push(Vec3::new(x, y, 0.0));
        }
    }
    let mut t = Vec::new();
    for j in 0..k {
        for i in 0..k {
            let a = j * (k + 1) + i;
            let (b, c, d) = (a + 1, a + k + 2, a + k + 1);
            t.push([a, b, c]);
            t.push([a, c, d]);
        }
    }
    let col = white(p.len());
    let mesh = RasterMesh {
        positions: &p,
        triangles: &t,
        colors: MeshColors::PerVertex(&col),
    };
    let (img, stats) = rasterize_with_stats(&mesh, &view, &RasterOptions::default()).unwrap();
    // The square spans x_px = 64 + 12.8·x ∈ [25.6, 102.4] (same for rows).
    let mut holes = 0;
    for y in 27..=101 {
        for x in 27..=101 {
            holes += (img.get(x, y).x < 0.5) as usize;
        }
    }
    assert_eq!(holes, 0);
    // No sample was written twice (a sample on a shared edge belongs to one triangle only,
    // else the second write of a coplanar neighbour could pass the depth test).
    assert_eq!(stats.fragments, covered(&img) as u64);
    assert_eq!(
        stats,
        RasterStats {
            triangles: t.len(),
            screen_triangles: t.len(),
            clipped: 0,
            fragments: stats.fragments
        }
    );
}

/// A floor seen at a grazing angle with a linear ramp f(x, z) = 0.2 + 0.3·x + 0.1·z: every
/// pixel must show f at the surface point its centre sees (perspective-correct), which a
/// screen-linear interpolation would miss by far.
#[test]
fn gouraud_reproduces_a_linear_ramp_perspective_correctly() {
    let view = CameraView {
        eye: Vec3::new(0.3, 1.0, 6.0),
        target: Vec3::new(0.0, 0.0, -2.0),
        up: Vec3::Y,
        fov_deg: 60.0,
        width: 160,
        height: 120,
    };
    let f = |p: Vec3| 0.2 + 0.3 * (p.x + 5.0) / 10.0 + 0.1 * (p.z + 10.0) / 12.0;
    // Floor y = 0, x ∈ [−5, 5], z ∈ [−10, 2], 3 × 4 cells, normal +Y (counter-clockwise from
    // above).
    let (nx, nz) = (3, 4);
    let mut p = Vec::new();
    for j in 0..=nz {
        for i in 0..=nx {
            p.push(Vec3::new(
                -5.0 + 10.0 * i as f32 / nx as f32,
                0.0,
                2.0 - 12.0 * j as f32 / nz as f32,
            ));
        }
    }
    let mut t = Vec::new();
    for j in 0..nz {
        for i in 0..nx {
            let a = j * (nx + 1) + i;
            t.push([a, a + 1, a + nx + 2]);
            t.push([a, a + nx + 2, a + nx + 1]);
        }
    }
    let col: Vec<Vec3> = p.iter().map(|&q| Vec3::splat(f(q))).collect();
    let mesh = RasterMesh {
        positions: &p,
        triangles: &t,
        colors: MeshColors::PerVertex(&col),
    };
    let img = rasterize(&mesh, &view, &RasterOptions::default()).unwrap();
    let frame = view.frame();
    let mut checked = 0;
    let mut worst = 0.0f32;
    for y in 0..view.height {
        for x in 0..view.width {
            let d = frame.direction(x as f32 + 0.5, y as f32 + 0.5);
            if d.y >= 0.0 {
                assert_eq!(img.get(x, y), Vec3::ZERO);
                continue;
            }
            let hit = frame.eye + d * (-frame.eye.y / d.y);
            let inside = hit.x.abs() < 4.99 && hit.z > -9.99 && hit.z < 1.99;
            if !inside {
                continue;
            }
            let want = f(hit);
            let got = img.get(x, y);
            worst = worst.max((got.x - want).abs());
            checked += 1;
        }
    }
    assert!(checked > 2000, "{checked}");
    assert!(worst < 2e-4, "worst ramp error {worst}");
}

#[test]
fn flat_mode_uses_one_colour_per_triangle() {
    let view = front_view(64);
    let (p, t) = quad(-3.0, -3.0, 3.0, 3.0, 0.0);
    let cols = [Vec3::new(0.25, 0.5, 0.75), Vec3::new(1.0, 0.0, 2.0)];
    let mesh = RasterMesh {
        positions: &p,
        triangles: &t,
        colors: MeshColors::PerTriangle(&cols),
    };
    let img = rasterize(&mesh, &view, &RasterOptions::default()).unwrap();
    let mut seen = [0usize; 2];
    for px in &img.pixels {
        if *px == cols[0] {
            seen[0] += 1;
        } else if *px == cols[1] {
            seen[1] += 1;
        } else {
            assert_eq!(*px, Vec3::ZERO);
        }
    }
    // The diagonal splits the square into two equal halves (±1 row of the diagonal).
    assert!(seen[0].abs_diff(seen[1]) <= 40, "{seen:?}");
    assert!(seen[0] + seen[1] > 1300);
}

#[test]
fn nearest_surface_wins_in_any_order() {
    let view = front_view(64);
    let (mut p, mut t) = quad(-2.0, -2.0, 2.0, 2.0, 0.0);
    let (p2, t2) = quad(-1.0, -1.0, 1.0, 1.0, 1.0);
    let mut col = vec![Vec3::X; 4];
    col.extend([Vec3::Y; 4]);
    p.extend(p2);
    t.extend(t2.iter().map(|tr| tr.map(|v| v + 4)));
    let run = |t: &[[u32; 3]]| {
        let mesh = RasterMesh {
            positions: &p,
            triangles: t,
            colors: MeshColors::PerVertex(&col),
        };
        rasterize(&mesh, &view, &RasterOptions::default()).unwrap()
    };
    let a = run(&t);
    let rev: Vec<[u32; 3]> = t.iter().rev().cloned().collect();
    let b = run(&rev);
    assert_eq!(a, b);
    // Centre: the front (green) quad; between 1 and 2 units: red.
    assert_eq!(a.get(32, 32), Vec3::Y);
    assert_eq!(a.get(32 + 10, 32), Vec3::X);
}

/// A floor under and behind the camera: triangles cross the near plane and reach far behind
/// the eye; every pixel whose ray hits the floor is covered, the others are not.
#[test]
fn near_plane_clipping() {
    let view = CameraView {
        eye: Vec3::new(0.0, 1.0, 0.0),
        target: Vec3::new(0.0, 0.7, -1.0),
        up: Vec3::Y,
        fov_deg: 70.0,
        width: 96,
        height: 64,
    };
    let (p, t) = {
        let (mut p, t) = quad(-100.0, -100.0, 100.0, 100.0, 0.0);
        // Rotate into the y = 0 plane facing +Y: (x, y, 0) → (x, 0, −y).
        for q in &mut p {
            *q = Vec3::new(q.x, 0.0, -q.y);
        }
        (p, t)
    };
    let col = white(4);
    let mesh = RasterMesh {
        positions: &p,
        triangles: &t,
        colors: MeshColors::PerVertex(&col),
    };
    let (img, stats) = rasterize_with_stats(&mesh, &view, &RasterOptions::default()).unwrap();
    assert!(stats.clipped >= 1);
    let frame = view.frame();
    for y in 0..view.height {
        for x in 0..view.width {
            let d = frame.direction(x as f32 + 0.5, y as f32 + 0.5);
            let t_hit = -frame.eye.y / d.y;
            let hits = d.y < 0.0 && {
                let h = frame.eye + d * t_hit;
                h.x.abs() < 100.0 && h.z.abs() < 100.0
            };
            // Near the horizon the far edge of the floor projects within a pixel: skip.
            if d.y < 0.0 && d.y > -0.02 {
                continue;
            }
            assert_eq!(img.get(x, y).x > 0.5, hits, "pixel ({x}, {y})");
        }
    }
}

#[test]
fn supersampling_averages_partial_coverage() {
    // Left edge at x_px = 50 + 10·x = 40.0 (a pixel boundary), right edge at 60.5 (a pixel
    // centre): with 2×2 samples at 0.25/0.75, pixel 60 is half covered.
    let view = front_view(100);
    let (p, t) = quad(-1.0, -2.0, 1.05, 2.0, 0.0);
    let col = white(4);
    let mesh = RasterMesh {
        positions: &p,
        triangles: &t,
        colors: MeshColors::PerVertex(&col),
    };
    let opts = RasterOptions {
        supersample: 2,
        background: Vec3::ZERO,
        ..Default::default()
    };
    let img = rasterize(&mesh, &view, &opts).unwrap();
    assert_eq!(img.get(39, 50).x, 0.0);
    assert_eq!(img.get(40, 50).x, 1.0);
    assert_eq!(img.get(59, 50).x, 1.0);
    assert_eq!(img.get(60, 50).x, 0.5);
    assert_eq!(img.get(61, 50).x, 0.0);
}

#[test]
fn back_faces_black_culled_or_shaded() {
    let view = front_view(32);
    let (p, t) = quad(-2.0, -2.0, 2.0, 2.0, 0.0);
    let t: Vec<[u32; 3]> = t.iter().map(|&[a, b, c]| [a, c, b]).collect(); // facing −Z
    let col = vec![Vec3::splat(0.7); 4];
    let mesh = RasterMesh {
        positions: &p,
        triangles: &t,
        colors: MeshColors::PerVertex(&col),
    };
    let bg = Vec3::new(0.1, 0.2, 0.3);
    let run = |back_faces| {
        let opts = RasterOptions {
            back_faces,
            background: bg,
            ..Default::default()
        };
        rasterize(&mesh, &view, &opts).unwrap().get(16, 16)
    };
    assert_eq!(run(BackFaces::Black), Vec3::ZERO);
    assert_eq!(run(BackFaces::Cull), bg);
    assert!((run(BackFaces::Shade) - Vec3::splat(0.7)).length() < 1e-6);
}

/// Two-sided meshes carry each surface twice (reversed winding for the back): the front face
/// wins over the coinciding back face in either order, in every back-face mode.
#[test]
fn front_face_wins_over_a_coinciding_back_face() {
    let view = front_view(40);
    let (mut p, mut t) = quad(-2.0, -2.0, 2.0, 2.0, 0.3);
    p.extend(p.clone());
    t.extend([[4u32, 6, 5], [4, 7, 6]]); // the same quad facing away
    let mut col = vec![Vec3::new(0.2, 0.4, 0.6); 4];
    col.extend([Vec3::new(0.9, 0.1, 0.1); 4]);
    for rev in [false, true] {
        let tris: Vec<[u32; 3]> = if rev {
            t.iter().rev().cloned().collect()
        } else {
            t.clone()
        };
        let mesh = RasterMesh {
            positions: &p,
            triangles: &tris,
            colors: MeshColors::PerVertex(&col),
        };
        for back_faces in [BackFaces::Black, BackFaces::Cull, BackFaces::Shade] {
            let opts = RasterOptions {
                back_faces,
                ..Default::default()
            };
            let img = rasterize(&mesh, &view, &opts).unwrap();
            let n = img
                .pixels
                .iter()
                .filter(|px| (**px - col[0]).length() < 1e-5)
                .count();
            assert_eq!(n, covered_quad_pixels(), "{back_faces:?} reversed {rev}");
        }
    }
}

/// Pixels covered by the [−2, 2]² quad at z = 0.3 alone in `front_view(40)` (20/4.7 pixels per
/// unit: x_px ∈ [11.49, 28.51], centres 11.5 ..= 28.5, an 18 × 18 pixel square).
fn covered_quad_pixels() -> usize {
    let view = front_view(40);
    let (p, t) = quad(-2.0, -2.0, 2.0, 2.0, 0.3);
    let c = white(4);
    let mesh = RasterMesh {
        positions: &p,
        triangles: &t,
        colors: MeshColors::PerVertex(&c),
    };
    let n = covered(&rasterize(&mesh, &view, &RasterOptions::default()).unwrap());
    assert_eq!(n, 18 * 18);
    n
}

#[test]
fn solution_pixels_are_radiosity_over_pi() {
    let view = front_view(32);
    let (p, t) = quad(-2.0, -2.0, 2.0, 2.0, 0.0);
    let mesh = ColoredMesh {
        positions: p,
        triangles: t,
        colors: vec![Vec3::new(1.0, 2.0, 3.0); 4],
    };
    let img = render_solution(&mesh, &view, &RasterOptions::default()).unwrap();
    let want = Vec3::new(1.0, 2.0, 3.0) / std::f32::consts::PI;
    assert!((img.get(16, 16) - want).length() < 1e-6);
}

#[test]
fn same_image_with_one_and_two_threads() {
    let view = CameraView {
        eye: Vec3::new(0.5, 0.8, 3.0),
        target: Vec3::ZERO,
        up: Vec3::Y,
        fov_deg: 50.0,
        width: 97,
        height: 61,
    };
    let mut rng = SplitMix64::new(11);
    let mut p = Vec::new();
    let mut t = Vec::new();
    for i in 0..3000u32 {
        let c = Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 2.0 - 1.0;
        for _ in 0..3 {
            p.push(c + (Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) - 0.5) * 0.3);
        }
        t.push([3 * i, 3 * i + 1, 3 * i + 2]);
    }
    let col: Vec<Vec3> = (0..p.len())
        .map(|_| Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()))
        .collect();
    let mesh = RasterMesh {
        positions: &p,
        triangles: &t,
        colors: MeshColors::PerVertex(&col),
    };
    let opts = RasterOptions {
        supersample: 2,
        ..Default::default()
    };
    let run = |n| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(n)
            .build()
            .unwrap()
            .install(|| rasterize(&mesh, &view, &opts).unwrap())
    };
    let a = run(1);
    let b = run(2);
    assert!(a
        .pixels
        .iter()
        .zip(&b.pixels)
        .all(|(x, y)| x.to_array() == y.to_array()));
    assert!(a.pixels.iter().filter(|p| p.max_element() > 0.0).count() > 1000);
}

#[test]
fn bad_input_is_an_error_not_a_panic() {
    let view = front_view(16);
    let (p, _) = quad(-1.0, -1.0, 1.0, 1.0, 0.0);
    let col = white(4);
    let bad = [[0u32, 1, 9]];
    let mesh = RasterMesh {
        positions: &p,
        triangles: &bad,
        colors: MeshColors::PerVertex(&col),
    };
    assert!(rasterize(&mesh, &view, &RasterOptions::default()).is_err());
    let ok = [[0u32, 1, 2]];
    let few = white(2);
    let mesh = RasterMesh {
        positions: &p,
        triangles: &ok,
        colors: MeshColors::PerVertex(&few),
    };
    assert!(rasterize(&mesh, &view, &RasterOptions::default()).is_err());
    let mesh = RasterMesh {
        positions: &p,
        triangles: &ok,
        colors: MeshColors::PerVertex(&col),
    };
    let opts = RasterOptions {
        supersample: 0,
        ..Default::default()
    };
    assert!(rasterize(&mesh, &view, &opts).is_err());
    let big = RasterOptions {
        supersample: 16,
        ..Default::default()
    };
    let mut v = view.clone();
    v.width = 8192;
    assert!(rasterize(&mesh, &v, &big).is_err());
    let mut v = view.clone();
    v.fov_deg = 0.0;
    assert!(rasterize(&mesh, &v, &RasterOptions::default()).is_err());
    // Non-finite vertices are skipped.
    let nan = [Vec3::NAN, Vec3::X, Vec3::Y];
    let mesh = RasterMesh {
        positions: &nan,
        triangles: &ok,
        colors: MeshColors::PerVertex(&col[..3]),
    };
    assert_eq!(
        covered(&rasterize(&mesh, &view, &RasterOptions::default()).unwrap()),
        0
    );
}

/// Signed distance (pixels) from `p` to the inside of the screen triangle `t` (positive
/// inside): the minimum over the three edges.
fn inside_distance(t: [(f32, f32); 3], p: (f32, f32)) -> f32 {
    let area = (t[1].0 - t[0].0) * (t[2].1 - t[0].1) - (t[1].1 - t[0].1) * (t[2].0 - t[0].0);
    let s = area.signum();
    (0..3)
        .map(|k| {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            let (ex, ey) = (b.0 - a.0, b.1 - a.1);
            s * (ex * (p.1 - a.1) - ey * (p.0 - a.0)) / (ex * ex + ey * ey).sqrt()
        })
        .fold(f32::INFINITY, f32::min)
}

proptest::proptest! {
    #![proptest_config(proptest::prelude::ProptestConfig::with_cases(64))]
    /// Every pixel whose centre is inside a random triangle (by more than the 1/256-pixel
    /// snapping) is covered, and no pixel whose centre is outside is.
    #[test]
    fn coverage_matches_the_exact_triangle(
        c in proptest::collection::vec(-4.0f32..4.0, 6),
        z in proptest::collection::vec(-1.0f32..1.0, 3),
    ) {
        let view = front_view(48);
        let p: Vec<Vec3> = (0..3).map(|i| Vec3::new(c[2 * i], c[2 * i + 1], z[i])).collect();
        let t = [[0u32, 1, 2]];
        let col = white(3);
        let opts = RasterOptions { back_faces: BackFaces::Shade, ..Default::default() };
        let mesh = RasterMesh { positions: &p, triangles: &t, colors: MeshColors::PerVertex(&col) };
        let img = rasterize(&mesh, &view, &opts).unwrap();
        let f = view.frame();
        let s = [0, 1, 2].map(|i| f.project(p[i]).unwrap());
        for y in 0..48 {
            for x in 0..48 {
                let d = inside_distance(s, (x as f32 + 0.5, y as f32 + 0.5));
                let cov = img.get(x, y).x > 0.5;
                if d > 0.01 {
                    proptest::prop_assert!(cov, "({x}, {y}) inside by {d} not covered");
                } else if d < -0.01 {
                    proptest::prop_assert!(!cov, "({x}, {y}) outside by {d} covered");
                }
            }
        }
    }
}
