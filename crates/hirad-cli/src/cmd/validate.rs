//! `hirad validate SCENE`: ground truth as a command. Solves the scene, renders the solution
//! from the view, path-traces the same view with two seeds and prints the mean luminance ratio
//! and RMS ΔE*uv of the solution against the first reference, and the same figures of the
//! second reference against the first (the references' own noise).

use super::image_args::CameraArgs;
use crate::Global;
use hirad::cluster::{ClusterConfig, ClusterTree, Strategy};
use hirad::metrics::compare;
use hirad::progress::NoProgress;
use hirad::radiosity::output::radiosity_mesh;
use hirad::radiosity::{solve, SolverConfig};
use hirad::ray::RayCaster;
use hirad::render::{
    render_reference, render_solution, BackFaces, CameraView, RasterOptions, ReferenceOptions,
};
use hirad::scene::SceneOptions;
use serde::Serialize;
use std::time::Instant;

#[derive(clap::Args, Debug)]
pub struct Args {
    /// Scene: a file path or a built-in name.
    pub scene: String,
    /// Solver preset (fast, default, fine, reference).
    #[arg(long, default_value = "default")]
    pub preset: String,
    /// Clustering strategy of the solve.
    #[arg(long, default_value = "proxi")]
    pub clustering: String,
    /// Two-sided surfaces, in the solve and in the path tracer.
    #[arg(long)]
    pub two_sided: bool,
    /// Paths per pixel of each reference.
    #[arg(long, default_value_t = 64)]
    pub spp: u32,
    /// Seed of the first reference (the second takes the next one).
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    #[command(flatten)]
    pub camera: CameraArgs,
}

#[derive(Serialize)]
struct Report {
    scene: String,
    preset: String,
    clustering: String,
    two_sided: bool,
    spp: u32,
    width: u32,
    height: u32,
    links: usize,
    solve_seconds: f64,
    reference_seconds: f64,
    /// Mean luminance of the solution's image over the first reference's.
    mean_luminance_ratio: f64,
    rms_delta_e: f64,
    /// The second reference against the first.
    reference_luminance_ratio: f64,
    reference_rms_delta_e: f64,
}

pub fn run(a: Args, g: &Global) -> anyhow::Result<()> {
    let mut cfg = SolverConfig::preset(&a.preset)?;
    cfg.two_sided |= a.two_sided;
    let strategy = Strategy::parse(&a.clustering)?;
    let opts = SceneOptions {
        up: a.camera.scene_up(),
        ..Default::default()
    };
    let scene = super::load_scene(&a.scene, &opts)?;
    let view = a
        .camera
        .apply(CameraView::from_camera(&scene.default_camera()))?;
    let t = Instant::now();
    let tree = ClusterTree::build(&scene, strategy, &ClusterConfig::default());
    let sol = solve(&scene, &tree, &cfg, &NoProgress)?;
    let solve_seconds = t.elapsed().as_secs_f64();
    let raster = RasterOptions {
        back_faces: if cfg.two_sided {
            BackFaces::Cull
        } else {
            BackFaces::Black
        },
        ..Default::default()
    };
    let img = render_solution(&radiosity_mesh(&sol, &scene, false), &view, &raster)?;
    let t = Instant::now();
    let rtree = ClusterTree::build(&scene, Strategy::Sah, &ClusterConfig::default());
    let caster = RayCaster::new(&scene, &rtree);
    let reference = |seed: u64| {
        let ro = ReferenceOptions {
            spp: a.spp,
            seed,
            two_sided: cfg.two_sided,
            ..Default::default()
        };
        render_reference(&scene, &caster, &view, &ro, &NoProgress).map(|(i, _)| i)
    };
    let r1 = reference(a.seed)?;
    let r2 = reference(a.seed.wrapping_add(1))?;
    let reference_seconds = t.elapsed().as_secs_f64();
    let e = compare(&img, &r1)?;
    let er = compare(&r2, &r1)?;
    let r = Report {
        scene: a.scene.clone(),
        preset: a.preset.clone(),
        clustering: strategy.name().into(),
        two_sided: cfg.two_sided,
        spp: a.spp,
        width: view.width,
        height: view.height,
        links: sol.stats.links,
        solve_seconds,
        reference_seconds,
        mean_luminance_ratio: e.mean_luminance_ratio,
        rms_delta_e: e.rms_delta_e,
        reference_luminance_ratio: er.mean_luminance_ratio,
        reference_rms_delta_e: er.rms_delta_e,
    };
    if g.json {
        return super::print_json(&r);
    }
    println!(
        "{} ({}, {}{}), {}x{}, {} spp",
        r.scene,
        r.preset,
        r.clustering,
        if r.two_sided { ", two-sided" } else { "" },
        r.width,
        r.height,
        r.spp
    );
    println!("| | mean luminance / reference | RMS dE*uv |");
    println!("|---|---|---|");
    println!(
        "| solution ({} links, {:.2} s) | {:.4} | {:.3} |",
        r.links, r.solve_seconds, r.mean_luminance_ratio, r.rms_delta_e
    );
    println!(
        "| second reference ({:.2} s for both) | {:.4} | {:.3} |",
        r.reference_seconds, r.reference_luminance_ratio, r.reference_rms_delta_e
    );
    Ok(())
}
