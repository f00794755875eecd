//! `hirad validate SCENE`: ground truth as a command. Solves the scene, renders the solution
//! from the view, path-traces the same view with two seeds and prints the mean luminance ratio
//! and RMS ΔE*uv of the solution against the first reference, and the same figures of the
//! second reference against the first (the references' own noise). Directly seen emitters are
//! exact in both images yet can carry most of the mean luminance (the lamps of the built-in
//! office: 65%), so the ratio over the other pixels is printed too. The solution is drawn with
//! 8 × 8 samples per pixel: the edges of a bright lamp aligned with the pixel rows otherwise move
//! the mean by several per cent (`docs/perf-log.md`, 2026-12-02 (3)).

use super::image_args::CameraArgs;
use crate::Global;
use hirad::cluster::{ClusterConfig, ClusterTree, Strategy};
use hirad::metrics::{compare, luminance};
use hirad::progress::NoProgress;
use hirad::radiosity::output::radiosity_mesh;
use hirad::radiosity::solve;
use hirad::ray::RayCaster;
use hirad::render::{
    render_reference, render_solution, BackFaces, CameraView, Image, RasterOptions,
    ReferenceOptions,
};
use serde::Serialize;
use std::time::Instant;

#[derive(clap::Args, Debug)]
pub struct Args {
    /// Scene: a file path or a built-in name.
    pub scene: String,
    /// The solve's settings, as `solve` takes them (`--two-sided` also in the path tracer).
    #[command(flatten)]
    pub solver: super::solve::SolverArgs,
    /// Paths per pixel of each reference.
    #[arg(long, default_value_t = 64)]
    pub spp: u32,
    /// Seed of the first reference (the second takes the next one).
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    #[command(flatten)]
    pub reflectance: super::info::SceneFileArgs,
    #[command(flatten)]
    pub camera: CameraArgs,
}

#[derive(Serialize)]
struct Report {
    scene: String,
    preset: String,
    clustering: String,
    two_sided: bool,
    /// The solver's visibility, refinement oracle and cluster emission.
    visibility: String,
    refine: String,
    cluster_emission: String,
    spp: u32,
    width: u32,
    height: u32,
    links: usize,
    solve_seconds: f64,
    reference_seconds: f64,
    /// Mean luminance of the solution's image over the first reference's.
    mean_luminance_ratio: f64,
    /// The same over the pixels that do not see an emitter (nor touch one that does).
    surface_luminance_ratio: f64,
    /// Share of the first reference's luminance in emitter pixels.
    emitter_luminance_share: f64,
    rms_delta_e: f64,
    /// The second reference against the first.
    reference_luminance_ratio: f64,
    reference_rms_delta_e: f64,
    /// The second reference against the first, over the pixels that do not see an emitter.
    reference_surface_luminance_ratio: f64,
}

pub fn run(a: Args, g: &Global) -> anyhow::Result<()> {
    let mut cfg = a.solver.config(None)?;
    let strategy = Strategy::parse(&a.solver.clustering)?;
    let opts = a.reflectance.options(a.camera.scene_up());
    let scene = super::load_scene(&a.scene, &opts)?;
    cfg.two_sided |= scene.two_sided;
    let view = a
        .camera
        .apply(CameraView::from_camera(&scene.default_camera()))?;
    let t = Instant::now();
    let tree = ClusterTree::build(&scene, strategy, &ClusterConfig::default());
    let sol = solve(&scene, &tree, &cfg, &NoProgress)?;
    let solve_seconds = t.elapsed().as_secs_f64();
    let raster = RasterOptions {
        // Back faces are explicit in the mesh when any triangle has one.
        back_faces: if sol.elements.two_sided {
            BackFaces::Cull
        } else {
            BackFaces::Black
        },
        supersample: 8,
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
    if r1.pixels.iter().all(|&p| luminance(p) <= 0.0) {
        anyhow::bail!(
            "the path-traced reference of {} is black from this view (eye {}): is the camera \
             outside a closed room? Place it inside with --eye and --target",
            a.scene,
            view.eye
        );
    }
    let r2 = reference(a.seed.wrapping_add(1))?;
    let reference_seconds = t.elapsed().as_secs_f64();
    let e = compare(&img, &r1)?;
    let er = compare(&r2, &r1)?;
    let lamps = emitter_pixels(&scene, &caster, &view);
    let (surf, share) = surface_ratio(&img, &r1, &lamps);
    let (surf_ref, _) = surface_ratio(&r2, &r1, &lamps);
    let r = Report {
        scene: a.scene.clone(),
        preset: a.solver.preset.clone(),
        clustering: strategy.name().into(),
        two_sided: sol.elements.two_sided,
        visibility: cfg.visibility.name().into(),
        refine: cfg.refine.name().into(),
        cluster_emission: cfg.cluster_emission.name().into(),
        spp: a.spp,
        width: view.width,
        height: view.height,
        links: sol.stats.links,
        solve_seconds,
        reference_seconds,
        mean_luminance_ratio: e.mean_luminance_ratio,
        surface_luminance_ratio: surf,
        emitter_luminance_share: share,
        reference_surface_luminance_ratio: surf_ref,
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
    println!(
        "| | mean luminance / reference | without emitter pixels ({:.0}% of the luminance) | RMS dE*uv |",
        100.0 * r.emitter_luminance_share
    );
    println!("|---|---|---|---|");
    println!(
        "| solution ({} links, {:.2} s) | {:.4} | {:.4} | {:.3} |",
        r.links, r.solve_seconds, r.mean_luminance_ratio, r.surface_luminance_ratio, r.rms_delta_e
    );
    println!(
        "| second reference ({:.2} s for both) | {:.4} | {:.4} | {:.3} |",
        r.reference_seconds,
        r.reference_luminance_ratio,
        r.reference_surface_luminance_ratio,
        r.reference_rms_delta_e
    );
    Ok(())
}

/// Pixels whose centre ray first meets the front of an emitter, grown by one pixel (the
/// pixels its edges cross).
fn emitter_pixels(scene: &hirad::scene::Scene, caster: &RayCaster, view: &CameraView) -> Vec<bool> {
    let frame = view.frame();
    let (w, h) = (view.width as usize, view.height as usize);
    let hit: Vec<bool> = (0..w * h)
        .map(|i| {
            let d = frame
                .direction((i % w) as f32 + 0.5, (i / w) as f32 + 0.5)
                .normalize();
            caster
                .closest(frame.eye, d, 0.0, f32::INFINITY)
                .is_some_and(|hit| {
                    let t = hit.tri as usize;
                    scene.material_of(t).is_emitter() && scene.normals[t].dot(d) < 0.0
                })
        })
        .collect();
    (0..w * h)
        .map(|i| {
            let (x, y) = ((i % w) as i64, (i / w) as i64);
            (-1..=1).any(|dy| {
                (-1..=1).any(|dx| {
                    let (xx, yy) = (x + dx, y + dy);
                    xx >= 0
                        && yy >= 0
                        && xx < w as i64
                        && yy < h as i64
                        && hit[yy as usize * w + xx as usize]
                })
            })
        })
        .collect()
}

/// Mean luminance of `img` over that of `reference` on the pixels not in `mask`, and the
/// share of the reference's luminance in `mask`.
fn surface_ratio(img: &Image, reference: &Image, mask: &[bool]) -> (f64, f64) {
    let (mut a, mut r, mut m) = (0.0, 0.0, 0.0);
    for ((&p, &q), &k) in img.pixels.iter().zip(&reference.pixels).zip(mask) {
        if k {
            m += luminance(q);
        } else {
            a += luminance(p);
            r += luminance(q);
        }
    }
    (a / r, m / (m + r))
}
