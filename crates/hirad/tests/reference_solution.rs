//! Solution-vs-reference comparisons through the image metric: the exact furnace solution
//! (B = E/(1−ρ) on every vertex) rasterised against the path-traced furnace, and the noise of
//! the Cornell reference shrinking as 1/√spp. The Cornell solver-vs-reference test
//! (`reference_cornell.rs`) uses the same helper, `reference_common::solution_error`.

mod reference_common;

use glam::Vec3;
use hirad::metrics::compare;
use hirad::render::ReferenceOptions;
use hirad::scene::export::ColoredMesh;
use reference_common::{reference, scene, solution_error, view};

#[test]
fn exact_furnace_solution_matches_the_path_tracer() {
    let s = scene("furnace");
    let v = view(&s, 32, 32);
    let (img, _) = reference(
        &s,
        &v,
        &ReferenceOptions {
            spp: 64,
            ..Default::default()
        },
    );
    // Exact radiosity B = E/(1 − ρ) = 1/(1 − 0.5) = 2 W/m² at every vertex.
    let mesh = ColoredMesh {
        positions: s.positions.clone(),
        triangles: s.triangles.clone(),
        colors: vec![Vec3::splat(2.0); s.positions.len()],
    };
    let e = solution_error(&mesh, &v, &img);
    println!("furnace exact solution vs reference: {e:?}");
    // Only the path tracer's noise remains: relative RMSE ≈ 6.5%/√2 per pixel at 64 spp.
    assert!(e.rel_rmse < 0.06, "{}", e.rel_rmse);
    assert!(e.rms_delta_e < 5.0, "{}", e.rms_delta_e);
    // A solution 10% too bright is clearly worse.
    let bright = ColoredMesh {
        colors: vec![Vec3::splat(2.2); s.positions.len()],
        ..mesh
    };
    let e2 = solution_error(&bright, &v, &img);
    assert!(
        e2.rms_delta_e > e.rms_delta_e + 1.0,
        "{} vs {}",
        e2.rms_delta_e,
        e.rms_delta_e
    );
}

#[test]
fn cornell_reference_noise_shrinks_with_spp() {
    let s = scene("cornell");
    let v = view(&s, 24, 24);
    let noise = |spp: u32| {
        let opts = |seed| ReferenceOptions {
            spp,
            seed,
            ..Default::default()
        };
        let (a, _) = reference(&s, &v, &opts(1));
        let (b, _) = reference(&s, &v, &opts(2));
        compare(&a, &b).unwrap().rel_rmse
    };
    let (n16, n64) = (noise(16), noise(64));
    let ratio = n16 / n64;
    println!("cornell seed-to-seed rel RMSE: 16 spp {n16:.4}, 64 spp {n64:.4}, ratio {ratio:.2}");
    // 4× the samples: 2× less noise (√4), with slack for the heavy tail of few-sample pixels.
    assert!(ratio > 1.5 && ratio < 3.5, "{ratio}");
    assert!(n64 < 0.1);
}
