//! The hierarchical radiosity solution of the Cornell box against the path-traced reference
//! (`experiments.md` §3: "the two must agree closely on the Cornell box"). Both images show
//! radiance from the scene's default camera; the solution is rasterised with Gouraud shading of
//! the per-vertex radiosity B/π.

mod reference_common;

use hirad::cluster::{ClusterConfig, ClusterTree, Strategy};
use hirad::metrics::compare;
use hirad::progress::NoProgress;
use hirad::radiosity::output::radiosity_mesh;
use hirad::radiosity::{solve, SolverConfig};
use hirad::render::ReferenceOptions;
use reference_common::{reference, scene, solution_error, view};

#[test]
fn cornell_solution_agrees_with_the_path_tracer() {
    let s = scene("cornell");
    let v = view(&s, 48, 48);
    let opts = |seed| ReferenceOptions {
        spp: 256,
        seed,
        ..Default::default()
    };
    let (refimg, _) = reference(&s, &v, &opts(1));
    // Noise floor: a second reference with another seed.
    let (other, _) = reference(&s, &v, &opts(2));
    let noise = compare(&other, &refimg).unwrap();

    let tree = ClusterTree::build(&s, Strategy::Sah, &ClusterConfig::default());
    let mut errors = Vec::new();
    for preset in ["fast", "default", "fine"] {
        let cfg = SolverConfig::preset(preset).unwrap();
        let sol = solve(&s, &tree, &cfg, &NoProgress).unwrap();
        let mesh = radiosity_mesh(&sol, &s, false);
        let e = solution_error(&mesh, &v, &refimg);
        println!(
            "cornell {preset}: RMS dE {:.3}, rel RMSE {:.4} (reference noise: RMS dE {:.3}, rel RMSE {:.4})",
            e.rms_delta_e, e.rel_rmse, noise.rms_delta_e, noise.rel_rmse
        );
        errors.push(e);
    }
    let d = &errors[1];
    // Close agreement: the default solution is within 3× the noise of a 256-spp reference
    // in ΔE, and its linear error (dominated by the edges of the bright light) under 15%.
    assert!(d.rel_rmse < 0.15, "rel RMSE {}", d.rel_rmse);
    assert!(
        d.rms_delta_e < 3.0 * noise.rms_delta_e,
        "{} vs noise {}",
        d.rms_delta_e,
        noise.rms_delta_e
    );
    // Finer presets get closer to the reference.
    assert!(errors[0].rms_delta_e > errors[1].rms_delta_e);
    assert!(errors[1].rms_delta_e > errors[2].rms_delta_e);
}

/// The Cornell box with every triangle given twice (a model merged with itself): the solver
/// gives each place to one copy, and the output mesh leaves the other out, so the solution
/// draws as close to the path tracer as the box's own does. Drawn, the unlit copies fought
/// the lit ones in the depth test and speckled the walls dark.
#[test]
fn a_duplicated_model_draws_as_the_model() {
    let raw = hirad::scene::builtin::cornell::cornell();
    let mut twice = raw.clone();
    twice.triangles.extend(raw.triangles.iter().copied());
    twice.tri_material.extend(raw.tri_material.iter().copied());
    twice.tri_object.extend(raw.tri_object.iter().copied());
    let opts = hirad::scene::SceneOptions::default();
    let once = hirad::scene::Scene::from_raw(raw, &opts).unwrap();
    let twice = hirad::scene::Scene::from_raw(twice, &opts).unwrap();
    let v = view(&once, 48, 48);
    let refopts = ReferenceOptions {
        spp: 256,
        ..Default::default()
    };
    let (refimg, _) = reference(&once, &v, &refopts);
    let cfg = SolverConfig::preset("default").unwrap();
    let error = |s: &hirad::scene::Scene| {
        let tree = ClusterTree::build(s, Strategy::Proxi, &ClusterConfig::default());
        let sol = solve(s, &tree, &cfg, &NoProgress).unwrap();
        let e = solution_error(&radiosity_mesh(&sol, s, false), &v, &refimg);
        (e, sol.under_face.len(), sol.leaves().len())
    };
    let (a, hidden_a, _) = error(&once);
    let (b, hidden_b, leaves_b) = error(&twice);
    println!(
        "against the path tracer: once RMS dE {:.3} (luminance {:.4}), twice {:.3} ({:.4}); \
         {hidden_b} of {leaves_b} leaves under a face",
        a.rms_delta_e, a.mean_luminance_ratio, b.rms_delta_e, b.mean_luminance_ratio
    );
    assert!(
        hidden_b > hidden_a && hidden_b < leaves_b,
        "{hidden_b} of {leaves_b}"
    );
    assert!((b.mean_luminance_ratio - a.mean_luminance_ratio).abs() < 0.01);
    assert!(b.rms_delta_e < 1.1 * a.rms_delta_e, "{b:?} against {a:?}");
}
