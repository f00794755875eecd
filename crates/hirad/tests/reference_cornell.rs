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
        let img = hirad::render::render_solution(
            &mesh,
            &v,
            &hirad::render::RasterOptions {
                supersample: 2,
                ..Default::default()
            },
        )
        .unwrap();
        let ratio = img.mean() / refimg.mean();
        println!(
            "cornell {preset}: RMS dE {:.3}, rel RMSE {:.4}, mean ratio {ratio} (reference noise: RMS dE {:.3}, rel RMSE {:.4})",
            e.rms_delta_e, e.rel_rmse, noise.rms_delta_e, noise.rel_rmse
        );
        errors.push(e);
    }
    let d = &errors[1];
    // Close agreement: within a few times the noise of a 64-spp reference, and under 15% in
    // linear RGB.
    assert!(d.rel_rmse < 0.15, "rel RMSE {}", d.rel_rmse);
    assert!(d.rms_delta_e < 3.0 * noise.rms_delta_e.max(2.0), "{}", d.rms_delta_e);
}
