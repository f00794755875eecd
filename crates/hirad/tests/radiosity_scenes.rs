//! Solver tests on built-in scenes (spec/radiosity.md correctness tests 1 and 4): the furnace
//! for every clustering strategy, and convergence on the Cornell box as ε → 0.

use hirad::cluster::{ClusterConfig, ClusterTree, Strategy};
use hirad::progress::NoProgress;
use hirad::radiosity::{solve, Solution, SolverConfig};
use hirad::scene::{Scene, SceneOptions};

/// Largest relative deviation of any root surface radiosity from E/(1 − ρ) = 2.
fn furnace_error(sol: &Solution) -> f64 {
    sol.elements
        .roots()
        .map(|r| {
            let b = sol.elements.b[r as usize];
            ((b - glam::DVec3::splat(2.0)).abs() / 2.0).max_element()
        })
        .fold(0.0, f64::max)
}

#[test]
fn furnace_every_strategy() {
    // Isotropic clusters misjudge flat clusters (a planar cluster facing its receiver shows
    // 4× the projected area ΣA/4); the oracle refines cluster links by the bound on that error
    // (`KernelCtx::anisotropy`), so the default tolerance meets the 2% bound for every strategy
    // (1.8% worst when this was written), and the error shrinks with ε.
    let scene = Scene::load("furnace:2", &SceneOptions::default()).unwrap();
    let presets = ["default", "fine"];
    let mut sums = [0.0f64; 2];
    for s in Strategy::ALL {
        let tree = ClusterTree::build(&scene, s, &ClusterConfig::default());
        let mut line = format!("furnace {:>6}:", s.name());
        for (k, p) in presets.iter().enumerate() {
            let cfg = SolverConfig::preset(p).unwrap();
            let sol = solve(&scene, &tree, &cfg, &NoProgress).unwrap();
            assert!(sol.stats.converged, "{s} {p}: not converged");
            let e = furnace_error(&sol);
            line += &format!(
                "  {p} (eps {:.1e}) max error {:.2}% [{} links, {:.1}% via clusters]",
                sol.stats.eps,
                100.0 * e,
                sol.stats.links,
                sol.stats.cluster_energy_percent
            );
            sums[k] += e;
            assert!(e < 0.02, "{s}: furnace error {e} at the {p} tolerance");
        }
        println!("{line}");
    }
    println!(
        "mean max error over strategies: default {:.2}%, fine {:.2}%",
        100.0 * sums[0] / 7.0,
        100.0 * sums[1] / 7.0
    );
    assert!(
        sums[1] < sums[0],
        "error does not shrink with eps: {sums:?}"
    );
}

/// Mean relative deviation of the root surface radiosities from E/(1 − ρ) = 2.
fn furnace_mean_error(sol: &Solution) -> f64 {
    let el = &sol.elements;
    let n = el.num_roots() as f64;
    el.roots()
        .map(|r| ((el.b[r as usize] - glam::DVec3::splat(2.0)).abs() / 2.0).max_element())
        .sum::<f64>()
        / n
}

#[test]
fn furnace_closed_scenes_keep_their_energy_through_clusters() {
    // In a closed scene every cluster sits on the enclosure, so an isotropic cluster sends
    // half of its power to where no surface is: with many cluster links the furnace comes
    // out 20–40% too dark. The directional model (sampled on the cluster's surfaces) keeps the
    // energy: the mean error stays at the level of the surface links' own error.
    use hirad::radiosity::ClusterEmission;
    for name in ["furnace", "furnace-sphere"] {
        let scene = Scene::load(name, &SceneOptions::default()).unwrap();
        for s in Strategy::ALL {
            let tree = ClusterTree::build(&scene, s, &ClusterConfig::default());
            let mut errs = Vec::new();
            for emission in [ClusterEmission::Directional, ClusterEmission::Isotropic] {
                let cfg = SolverConfig {
                    cluster_emission: emission,
                    ..SolverConfig::default()
                };
                let sol = solve(&scene, &tree, &cfg, &NoProgress).unwrap();
                errs.push((
                    furnace_mean_error(&sol),
                    furnace_error(&sol),
                    sol.stats.cluster_energy_percent,
                ));
            }
            let (d, i) = (errs[0], errs[1]);
            println!(
                "{name:>14} {:>6}: directional mean {:.2}% max {:.2}% ({:.0}% via clusters), \
                 isotropic mean {:.2}% max {:.2}% ({:.0}%)",
                s.name(),
                100.0 * d.0,
                100.0 * d.1,
                d.2,
                100.0 * i.0,
                100.0 * i.1,
                i.2
            );
            assert!(d.0 < 0.02, "{name} {s}: directional mean error {}", d.0);
            assert!(d.1 < 0.05, "{name} {s}: directional max error {}", d.1);
            if i.2 > 20.0 {
                assert!(i.0 > 0.05, "{name} {s}: isotropic mean error {}", i.0);
            }
        }
    }
}

/// Area-weighted mean relative difference of per-triangle radiosity (all channels).
fn rel_diff(a: &Solution, b: &Solution, scene: &Scene) -> f64 {
    let (mut num, mut den) = (0.0, 0.0);
    for t in 0..scene.num_triangles() as u32 {
        let w = scene.areas[t as usize] as f64;
        let x = a.triangle_radiosity(t, false);
        let y = b.triangle_radiosity(t, false);
        num += w * (x - y).abs().element_sum();
        den += w * y.abs().element_sum();
    }
    num / den
}

#[test]
fn cornell_converges_as_eps_shrinks() {
    let scene = Scene::load("cornell", &SceneOptions::default()).unwrap();
    let tree = ClusterTree::build(&scene, Strategy::Proxi, &ClusterConfig::default());
    let cfg = |eps_rel: f64| SolverConfig {
        eps_rel,
        min_area_rel: 1e-4,
        ..SolverConfig::default()
    };
    let reference = solve(&scene, &tree, &cfg(0.004), &NoProgress).unwrap();
    let epss = [0.32, 0.16, 0.08, 0.04, 0.02];
    let mut errs = Vec::new();
    for &e in &epss {
        let sol = solve(&scene, &tree, &cfg(e), &NoProgress).unwrap();
        let err = rel_diff(&sol, &reference, &scene);
        println!(
            "cornell eps_rel {e}: {} links, error vs eps_rel 0.004: {:.4}",
            sol.stats.links, err
        );
        errs.push(err);
    }
    // Least-squares slope of log(error) against log(eps).
    let n = epss.len() as f64;
    let xs: Vec<f64> = epss.iter().map(|e| e.ln()).collect();
    let ys: Vec<f64> = errs.iter().map(|e| e.ln()).collect();
    let mx = xs.iter().sum::<f64>() / n;
    let my = ys.iter().sum::<f64>() / n;
    let slope = xs
        .iter()
        .zip(&ys)
        .map(|(x, y)| (x - mx) * (y - my))
        .sum::<f64>()
        / xs.iter().map(|x| (x - mx) * (x - mx)).sum::<f64>();
    println!("cornell convergence: fitted slope d log(error) / d log(eps) = {slope:.3}");
    assert!(
        slope > 0.2,
        "error does not decrease with eps (slope {slope})"
    );
    assert!(errs[4] < 0.5 * errs[0], "{errs:?}");
}

/// The number of shadow rays per link sets a link's noise, not its expectation: the office's
/// light (Σ A·B over its surfaces) with one ray per link matches sixteen. Refinement that
/// splits or keeps a link on its own rays' outcome, and receivers whose few points all fell
/// under a cover (read as receiving nothing), left one ray 8.8% short of sixteen here, and
/// judging the estimate on the kernel with visibility 2.1%; 1.8% remain (links kept because
/// their sample points' kernel came out below the estimate, and the isotropic cluster
/// sources, which keep the rays they split on).
#[test]
fn office_light_does_not_depend_on_the_shadow_rays_per_link() {
    let scene = Scene::load("office", &SceneOptions::default()).unwrap();
    let tree = ClusterTree::build(&scene, Strategy::Proxi, &ClusterConfig::default());
    let light = |rays: u32| {
        let cfg = SolverConfig {
            shadow_rays: rays,
            ..SolverConfig::default()
        };
        let sol = solve(&scene, &tree, &cfg, &NoProgress).unwrap();
        sol.stats.power.radiosity
    };
    let (one, many) = (light(1), light(16));
    println!(
        "Σ A·B: 1 ray {one:.2} W, 16 rays {many:.2} W, ratio {:.4}",
        one / many
    );
    assert!(
        (one / many - 1.0).abs() < 0.03,
        "1 ray {one} W, 16 rays {many} W"
    );
}

/// No leaf gathers more irradiance than the scene's light can give: irradiance is at most the
/// brightest radiosity seen, and only an emitter (or a surface the sun or sky lights) can be
/// the brightest, so [`SolveStats::leaves_above_brightest`] (twice that, for sampling) stays
/// 0. On the Franka arm, a polygon soup of tiny triangles, one ray per link used to give
/// a whole cluster's light to the one speck whose sample saw the source: 14 and 7 such
/// leaves on these seeds, one at 200× the panel's radiosity.
///
/// [`SolveStats::leaves_above_brightest`]: hirad::radiosity::SolveStats::leaves_above_brightest
#[test]
fn franka_panda_leaves_get_no_more_light_than_the_panel_gives() {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../scenes/franka_panda.toml"
    );
    let scene = Scene::load(path, &SceneOptions::default()).unwrap();
    let tree = ClusterTree::build(&scene, Strategy::Proxi, &ClusterConfig::default());
    for seed in [1, 3] {
        let cfg = SolverConfig {
            seed,
            ..SolverConfig::preset("fast").unwrap()
        };
        let sol = solve(&scene, &tree, &cfg, &NoProgress).unwrap();
        let n = sol.stats.leaves_above_brightest;
        println!("seed {seed}: {n} leaves above the brightest radiosity");
        assert_eq!(
            n, 0,
            "seed {seed}: {n} leaves got more light than the panel gives"
        );
    }
}
