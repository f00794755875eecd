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
