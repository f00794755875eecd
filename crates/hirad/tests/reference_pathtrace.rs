//! Path tracer against analytic values: furnace, a square emitter over a floor (next-event
//! estimation with MIS), sun, sky, one-sided back faces; determinism for 1 and 2 threads.

mod reference_common;

use glam::Vec3;
use hirad::cluster::{ClusterConfig, ClusterTree, Strategy};
use hirad::ray::RayCaster;
use hirad::render::{PathTracer, ReferenceOptions};
use hirad::rng::SplitMix64;
use hirad::scene::{Material, RawScene, Scene, SceneOptions, Sun};
use reference_common::{reference, scene, view};
use std::f64::consts::PI;

#[test]
fn furnace_radiance_is_emission_over_one_minus_rho() {
    // Furnace: ρ = 0.5, L_e = 1/π everywhere: L = L_e / (1 − ρ) = E/(1 − ρ)/π = 2/π.
    let s = scene("furnace");
    let v = view(&s, 32, 32);
    let opts = ReferenceOptions {
        spp: 32,
        ..Default::default()
    };
    let (img, stats) = reference(&s, &v, &opts);
    let want = 2.0 / PI;
    let mean = img.mean();
    for c in mean.to_array() {
        let rel = (c as f64 - want).abs() / want;
        println!("furnace mean {c} want {want} rel {rel:.5}");
        assert!(rel < 0.01);
    }
    // Per-pixel noise: the standard deviation over pixels is well below 10% at 32 spp.
    let var = img
        .pixels
        .iter()
        .map(|p| (p.x as f64 - want).powi(2))
        .sum::<f64>()
        / img.len() as f64;
    println!("furnace per-pixel relative std {:.4}", var.sqrt() / want);
    assert!(var.sqrt() < 0.1 * want);
    assert_eq!(stats.paths, 32 * 32 * 32);
    // Path length in the closed box: 3 segments before Russian roulette starts (rr_depth 3),
    // survival 1/8 at depth 3 (throughput ρ³), then 1/2 per bounce: 3 + 2/8 = 3.25 expected.
    let per_path = stats.segments as f64 / stats.paths as f64;
    println!("segments per path {per_path}");
    assert!((per_path - 3.25).abs() < 0.02, "{per_path}");
}

/// Floor y = 0 of ρ = 0.5 (large, facing +Y), plus `extra` triangles.
fn floor_scene(extra: impl FnOnce(&mut RawScene)) -> Scene {
    let h = 200.0;
    let mut raw = RawScene {
        name: "floor".into(),
        positions: vec![
            Vec3::new(-h, 0.0, -h),
            Vec3::new(-h, 0.0, h),
            Vec3::new(h, 0.0, h),
            Vec3::new(h, 0.0, -h),
        ],
        triangles: vec![[0, 1, 2], [0, 2, 3]],
        tri_material: vec![0, 0],
        tri_object: vec![0, 0],
        materials: vec![Material::diffuse("floor", Vec3::splat(0.5))],
        ..Default::default()
    };
    extra(&mut raw);
    let s = Scene::from_raw(raw, &SceneOptions::default()).unwrap();
    assert_eq!(s.normals[0], Vec3::Y);
    s
}

/// Mean radiance of `n` paths from `origin` along `dir`.
fn mean_radiance(s: &Scene, opts: &ReferenceOptions, origin: Vec3, dir: Vec3, n: u32) -> Vec3 {
    let tree = ClusterTree::build(s, Strategy::Sah, &ClusterConfig::default());
    let caster = RayCaster::new(s, &tree);
    let pt = PathTracer::new(s, &caster, opts);
    let mut rng = SplitMix64::new(99);
    let mut sum = glam::DVec3::ZERO;
    for _ in 0..n {
        sum += pt.radiance(origin, dir, &mut rng).as_dvec3();
    }
    (sum / n as f64).as_vec3()
}

/// Adds the corners of the square [−1, 1]² at height 1 (counter-clockwise seen from below)
/// to `r`; returns the first one's index.
fn square_at_height_one(r: &mut RawScene) -> u32 {
    let b = r.positions.len() as u32;
    r.positions.extend([
        Vec3::new(-1.0, 1.0, -1.0),
        Vec3::new(1.0, 1.0, -1.0),
        Vec3::new(1.0, 1.0, 1.0),
        Vec3::new(-1.0, 1.0, 1.0),
    ]);
    b
}

#[test]
fn square_emitter_over_a_floor() {
    // Emitter: square [−1, 1]² at height 1 facing down, L_e = 1, ρ = 0. The floor under its
    // centre has radiance ρ·L_e·F, F = 4 × corner-rectangle form factor with X = Y = 1:
    // F_corner = (1/2π)·2·(1/√2)·atan(1/√2).
    let s = floor_scene(|r| {
        let b = square_at_height_one(r);
        r.triangles.extend([[b, b + 1, b + 2], [b, b + 2, b + 3]]);
        r.tri_material.extend([1, 1]);
        r.tri_object.extend([0, 0]);
        r.materials.push(Material {
            name: "light".into(),
            rho: Vec3::ZERO,
            emission: Vec3::ONE,
        });
    });
    assert!(s.normals[2].dot(Vec3::NEG_Y) > 0.999);
    let want = floor_under_unit_square();
    let opts = ReferenceOptions::default();
    let got = mean_radiance(&s, &opts, Vec3::new(0.0, 0.5, 0.0), Vec3::NEG_Y, 20000);
    println!("emitter: got {got}, want {want}");
    assert!((got.x as f64 - want).abs() < 0.01 * want);
    // Looking at the emitter from below: L_e exactly (camera ray, weight 1).
    let up = mean_radiance(&s, &opts, Vec3::new(0.3, 0.5, 0.2), Vec3::Y, 10);
    assert!((up - Vec3::ONE).abs().max_element() < 1e-6);
}

#[test]
fn a_ray_sees_the_face_of_coincident_faces_that_faces_it() {
    // A double-sided lamp panel modelled as two one-sided emitters back to back, the
    // down-facing one first (lower ids win ties) and triangulated along the other diagonal,
    // over the floor: looking down at it from above shows the up-facing one's L_e exactly
    // (a camera ray, weight 1), not the back of the other; from below, the down-facing one's.
    let s = floor_scene(|r| {
        let b = square_at_height_one(r);
        r.triangles.extend([
            [b, b + 1, b + 2],
            [b, b + 2, b + 3],
            [b + 1, b, b + 3],
            [b + 1, b + 3, b + 2],
        ]);
        r.tri_material.extend([1, 1, 2, 2]);
        r.tri_object.extend([0, 0, 0, 0]);
        for (name, e) in [("down", Vec3::ONE), ("up", Vec3::new(2.0, 3.0, 4.0))] {
            r.materials.push(Material {
                name: name.into(),
                rho: Vec3::ZERO,
                emission: e,
            });
        }
    });
    assert!(s.normals[2].dot(Vec3::NEG_Y) > 0.999 && s.normals[4].dot(Vec3::Y) > 0.999);
    for two_sided in [false, true] {
        let opts = ReferenceOptions {
            two_sided,
            ..Default::default()
        };
        let mut rng = SplitMix64::new(5);
        for _ in 0..200 {
            let (x, z) = (rng.next_f32() * 1.8 - 0.9, rng.next_f32() * 1.8 - 0.9);
            let top = Vec3::new(x, 2.0, z);
            let down = Vec3::new(x * 0.3, 0.0, z * 0.3) - top;
            let got = mean_radiance(&s, &opts, top, down.normalize(), 1);
            assert_eq!(got, Vec3::new(2.0, 3.0, 4.0), "from above at {top}");
            let bottom = Vec3::new(x, 0.5, z);
            let got = mean_radiance(&s, &opts, bottom, Vec3::Y, 1);
            assert_eq!(got, Vec3::ONE, "from below at {bottom}");
        }
    }
}

/// The floor's radiance under the centre of a square emitter of `L_e = 1` at height 1
/// ([`square_emitter_over_a_floor`]).
fn floor_under_unit_square() -> f64 {
    0.5 * 4.0 / (2.0 * PI) * 2.0 * (0.5f64).sqrt() * (0.5f64).sqrt().atan()
}

#[test]
fn a_duplicated_lamp_shines_once() {
    // The square emitter twice in the same place, the second copy triangulated along the other
    // diagonal and brighter: a ray onto the lamp sees the first (lower ids win ties between
    // faces alike), and the floor gets its light once: the light samples on the second copy
    // count nowhere, where that copy is not what a ray sees.
    let s = floor_scene(|r| {
        let b = square_at_height_one(r);
        r.triangles.extend([
            [b, b + 1, b + 2],
            [b, b + 2, b + 3],
            [b + 1, b + 2, b + 3],
            [b + 1, b + 3, b],
        ]);
        r.tri_material.extend([1, 1, 2, 2]);
        r.tri_object.extend([1, 1, 2, 2]);
        r.objects = ["floor", "lamp", "copy"].map(String::from).to_vec();
        for (name, e) in [("lamp", 1.0), ("copy", 3.0)] {
            r.materials.push(Material {
                name: name.into(),
                rho: Vec3::ZERO,
                emission: Vec3::splat(e),
            });
        }
    });
    assert!(s.normals[4].dot(Vec3::NEG_Y) > 0.999);
    let want = floor_under_unit_square();
    let opts = ReferenceOptions::default();
    let got = mean_radiance(&s, &opts, Vec3::new(0.0, 0.5, 0.0), Vec3::NEG_Y, 20000);
    println!("duplicated lamp: got {got}, want {want}");
    assert!((got.x as f64 - want).abs() < 0.01 * want);
    let up = mean_radiance(&s, &opts, Vec3::new(0.3, 0.5, 0.2), Vec3::Y, 10);
    assert_eq!(up, Vec3::ONE);
}

#[test]
fn a_lamp_flush_with_a_ceiling_shines() {
    // A black ceiling [−2, 2]² at height 1 facing down, listed first (lower ids), and the
    // square emitter in its plane: rays onto the lamp see the lamp (an emitter comes before
    // a coincident non-emitter, as the solver gives it the overlap), so the floor gets the
    // analytic light through both light samples and the bounce rays that hit the lamp.
    let s = floor_scene(|r| {
        let c = r.positions.len() as u32;
        r.positions.extend([
            Vec3::new(-2.0, 1.0, -2.0),
            Vec3::new(2.0, 1.0, -2.0),
            Vec3::new(2.0, 1.0, 2.0),
            Vec3::new(-2.0, 1.0, 2.0),
        ]);
        let b = square_at_height_one(r);
        r.triangles.extend([
            [c, c + 1, c + 2],
            [c, c + 2, c + 3],
            [b, b + 1, b + 2],
            [b, b + 2, b + 3],
        ]);
        r.tri_material.extend([1, 1, 2, 2]);
        r.tri_object.extend([1, 1, 2, 2]);
        r.objects = ["floor", "ceiling", "lamp"].map(String::from).to_vec();
        r.materials.push(Material::diffuse("ceiling", Vec3::ZERO));
        r.materials.push(Material {
            name: "lamp".into(),
            rho: Vec3::ZERO,
            emission: Vec3::ONE,
        });
    });
    assert!(s.normals[2].dot(Vec3::NEG_Y) > 0.999 && s.normals[4].dot(Vec3::NEG_Y) > 0.999);
    let want = floor_under_unit_square();
    let opts = ReferenceOptions::default();
    let got = mean_radiance(&s, &opts, Vec3::new(0.0, 0.5, 0.0), Vec3::NEG_Y, 20000);
    println!("flush lamp: got {got}, want {want}");
    assert!((got.x as f64 - want).abs() < 0.01 * want);
    let up = mean_radiance(&s, &opts, Vec3::new(0.3, 0.5, 0.2), Vec3::Y, 10);
    assert_eq!(up, Vec3::ONE);
    // Beside the lamp, the ceiling.
    let side = mean_radiance(&s, &opts, Vec3::new(1.5, 0.5, 0.2), Vec3::Y, 10);
    assert_eq!(side, Vec3::ZERO);
}

#[test]
fn a_poster_on_the_floor_is_seen_over_it() {
    // A dark square "poster" lying in the floor's plane, listed after the floor (higher ids),
    // under the sun: a ray onto it sees the poster (the smaller object, as the solver gives it
    // the overlap), ρ·E·cos/π exactly (the bounce escapes, no sky); beside it, the floor.
    let dir = Vec3::new(1.0, 2.0, 0.0).normalize();
    let e = 3.0f32;
    let s = floor_scene(|r| {
        let b = r.positions.len() as u32;
        r.positions.extend([
            Vec3::new(-1.0, 0.0, -1.0),
            Vec3::new(-1.0, 0.0, 1.0),
            Vec3::new(1.0, 0.0, 1.0),
            Vec3::new(1.0, 0.0, -1.0),
        ]);
        r.triangles.extend([[b, b + 1, b + 2], [b, b + 2, b + 3]]);
        r.tri_material.extend([1, 1]);
        r.tri_object.extend([1, 1]);
        r.objects = ["floor", "poster"].map(String::from).to_vec();
        r.materials
            .push(Material::diffuse("poster", Vec3::splat(0.1)));
        r.sun = Some(Sun {
            direction: dir,
            irradiance: Vec3::splat(e),
        });
    });
    assert_eq!(s.normals[2], Vec3::Y);
    let opts = ReferenceOptions::default();
    for (x, rho) in [(0.3, 0.1f32), (1.5, 0.5)] {
        let got = mean_radiance(&s, &opts, Vec3::new(x, 1.0, 0.2), Vec3::NEG_Y, 10);
        let want = rho * e * dir.y / std::f32::consts::PI;
        assert!(
            (got.x - want).abs() < 1e-5 * want,
            "at x = {x}: {got} vs {want}"
        );
    }
}

#[test]
fn sun_and_sky_on_a_floor() {
    let dir = Vec3::new(1.0, 2.0, 0.0).normalize();
    let e = 3.0f32;
    let s = floor_scene(|r| {
        r.sun = Some(Sun {
            direction: dir,
            irradiance: Vec3::splat(e),
        })
    });
    let opts = ReferenceOptions::default();
    let got = mean_radiance(&s, &opts, Vec3::new(0.0, 1.0, 0.0), Vec3::NEG_Y, 100);
    // ρ · E · cos / π, exact (the bounce escapes, no sky).
    let want = 0.5 * e * dir.y / std::f32::consts::PI;
    assert!((got.x - want).abs() < 1e-5 * want, "{got} vs {want}");
    // Uniform sky L over the upper hemisphere: irradiance π·L, radiance ρ·L.
    let s = floor_scene(|r| r.sky = Some(Vec3::new(1.0, 2.0, 4.0)));
    let got = mean_radiance(&s, &opts, Vec3::new(0.0, 1.0, 0.0), Vec3::NEG_Y, 100);
    assert!(
        (got - Vec3::new(0.5, 1.0, 2.0)).abs().max_element() < 1e-5,
        "{got}"
    );
}

#[test]
fn back_faces_absorb_unless_two_sided() {
    // Sun from below: the floor's back face is lit.
    let dir = Vec3::new(0.0, -1.0, 0.0);
    let s = floor_scene(|r| {
        r.sun = Some(Sun {
            direction: dir,
            irradiance: Vec3::ONE,
        })
    });
    let one = ReferenceOptions::default();
    let from_below = mean_radiance(&s, &one, Vec3::new(0.0, -1.0, 0.0), Vec3::Y, 10);
    assert_eq!(from_below, Vec3::ZERO);
    let from_above = mean_radiance(&s, &one, Vec3::new(0.0, 1.0, 0.0), Vec3::NEG_Y, 10);
    assert_eq!(from_above, Vec3::ZERO);
    let two = ReferenceOptions {
        two_sided: true,
        ..Default::default()
    };
    let from_below = mean_radiance(&s, &two, Vec3::new(0.0, -1.0, 0.0), Vec3::Y, 10);
    let want = 0.5 / std::f32::consts::PI;
    assert!((from_below.x - want).abs() < 1e-6, "{from_below}");
}

#[test]
fn same_image_with_one_and_two_threads() {
    let s = scene("cornell");
    let v = view(&s, 20, 16);
    let opts = ReferenceOptions {
        spp: 4,
        seed: 5,
        ..Default::default()
    };
    let run = |n| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(n)
            .build()
            .unwrap()
            .install(|| reference(&s, &v, &opts))
    };
    let (a, sa) = run(1);
    let (b, sb) = run(2);
    assert!(a
        .pixels
        .iter()
        .zip(&b.pixels)
        .all(|(x, y)| x.to_array() == y.to_array()));
    assert_eq!((sa.segments, sa.shadow_rays), (sb.segments, sb.shadow_rays));
    assert!(a.mean().max_element() > 0.0);
    // A different seed gives a different image.
    let (c, _) = reference(
        &s,
        &v,
        &ReferenceOptions {
            seed: 6,
            ..opts.clone()
        },
    );
    assert_ne!(a, c);
}

#[test]
fn recorded_rays_are_the_rays_of_the_render() {
    // `record_rays` (the `hirad reference --bench` replay) logs exactly the queries the render
    // casts: same counts, camera rays from the eye, and a row stride keeps those rows only.
    let s = scene("office");
    let v = view(&s, 24, 18);
    let opts = ReferenceOptions {
        spp: 3,
        seed: 9,
        ..Default::default()
    };
    let tree = ClusterTree::build(&s, Strategy::Sah, &ClusterConfig::default());
    let caster = RayCaster::new(&s, &tree);
    let tracer = PathTracer::new(&s, &caster, &opts);
    let (_, stats) = tracer
        .render(&v, &hirad::progress::NoProgress, None)
        .unwrap();
    let log = tracer.record_rays(&v, 1).unwrap();
    assert_eq!(log.closest.len() as u64, stats.segments);
    assert_eq!(log.shadow.len() as u64, stats.shadow_rays);
    let eye = v.frame().eye;
    let camera_rays = log.closest.iter().filter(|r| r.origin == eye).count() as u64;
    assert_eq!(camera_rays, stats.paths);
    assert!(log
        .closest
        .iter()
        .all(|r| (r.dir.length() - 1.0).abs() < 1e-5));
    // Shadow rays of the ceiling lights end just short of the light: t ≤ 1 − 1e-4.
    assert!(log.shadow.iter().all(|r| r.tmax == 1.0 - 1e-4));
    // Replaying them finds the same number of rays; most camera rays hit the closed office.
    let (rep, hits, occluded) = log.replay(&caster);
    assert_eq!(rep.closest_rays, stats.segments);
    assert_eq!(rep.shadow_rays, stats.shadow_rays);
    assert!(hits >= stats.paths * 9 / 10 && hits <= stats.segments);
    assert!(occluded < stats.shadow_rays);
    // Every third row: the rays of rows 0, 3, 6, … (18 rows → 6 rows), a subset of the log.
    let third = tracer.record_rays(&v, 3).unwrap();
    let third_cameras = third.closest.iter().filter(|r| r.origin == eye).count() as u64;
    assert_eq!(third_cameras, stats.paths / 3);
    assert_eq!(log.closest[..8], third.closest[..8]);
    assert!(tracer.record_rays(&v, 0).is_err());
}
