//! `hirad reference SCENE --spp N`: path-traced reference image with the solver's conventions
//! (diffuse, one-sided surfaces unless `--two-sided`, front-face emitters, next-event estimation
//! with MIS, sun and sky, Russian roulette). Pixels are radiance. Prints path and segment counts
//! and the path-segment rate.

use super::image_args::{CameraArgs, ImageArgs};
use crate::progress::Bars;
use crate::Global;
use hirad::cluster::{ClusterConfig, ClusterTree, Strategy};
use hirad::ray::RayCaster;
use hirad::render::{CameraView, PathTracer, ReferenceOptions};
use hirad::scene::SceneOptions;
use serde::Serialize;
use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

#[derive(clap::Args, Debug)]
pub struct Args {
    /// Scene: a file path or a built-in name.
    pub scene: String,
    /// Paths per pixel.
    #[arg(long, default_value_t = 64, value_parser = clap::value_parser!(u32).range(1..))]
    pub spp: u32,
    /// Seed of the per-pixel generators.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Give every surface a diffuse back face (default: back faces are black and absorb).
    #[arg(long)]
    pub two_sided: bool,
    /// Bounces before Russian roulette starts.
    #[arg(long, default_value_t = 3)]
    pub rr_depth: u32,
    /// Maximum bounces.
    #[arg(long, default_value_t = 1000)]
    pub max_depth: u32,
    /// Cluster tree used as the ray-casting accelerator.
    #[arg(long, default_value = "sah")]
    pub clustering: String,
    /// Reflectance channels equal to 1 are clamped to this value.
    #[arg(long, default_value_t = 0.95)]
    pub max_reflectance: f32,
    #[command(flatten)]
    pub camera: CameraArgs,
    #[command(flatten)]
    pub out: ImageArgs,
}

#[derive(Serialize)]
struct Report {
    scene: String,
    triangles: usize,
    width: u32,
    height: u32,
    spp: u32,
    seed: u64,
    threads: usize,
    tree_seconds: f64,
    render_seconds: f64,
    paths: u64,
    segments: u64,
    shadow_rays: u64,
    msegments_per_s: f64,
    mrays_per_s: f64,
    mean_radiance: [f32; 3],
    images: Vec<String>,
}

pub fn run(a: Args, g: &Global) -> anyhow::Result<()> {
    let opts = SceneOptions {
        max_reflectance: a.max_reflectance,
        up: a.camera.scene_up(),
    };
    let scene = super::load_scene(&a.scene, &opts)?;
    let view = a
        .camera
        .apply(CameraView::from_camera(&scene.default_camera()))?;
    let strategy = Strategy::parse(&a.clustering)?;
    let t0 = std::time::Instant::now();
    let tree = ClusterTree::build(&scene, strategy, &ClusterConfig::default());
    let tree_seconds = t0.elapsed().as_secs_f64();
    let caster = RayCaster::new(&scene, &tree);
    let ropts = ReferenceOptions {
        spp: a.spp,
        seed: a.seed,
        two_sided: a.two_sided,
        rr_depth: a.rr_depth,
        max_depth: a.max_depth,
    };
    let cancel = Arc::new(AtomicBool::new(false));
    {
        let c = cancel.clone();
        let _ = ctrlc::set_handler(move || {
            if c.swap(true, Ordering::SeqCst) {
                std::process::exit(130);
            }
        });
    }
    let bars = Bars::new(g.quiet);
    let tracer = PathTracer::new(&scene, &caster, &ropts);
    let (img, stats) = tracer.render(&view, &bars, Some(&cancel))?;
    let stem = format!("reference-{}", sanitize(&scene.name));
    let files = a.out.write(&img, Path::new("hirad-out"), &stem)?;
    let r = Report {
        scene: a.scene.clone(),
        triangles: scene.num_triangles(),
        width: view.width,
        height: view.height,
        spp: a.spp,
        seed: a.seed,
        threads: rayon::current_num_threads(),
        tree_seconds,
        render_seconds: stats.seconds,
        paths: stats.paths,
        segments: stats.segments,
        shadow_rays: stats.shadow_rays,
        msegments_per_s: stats.segments_per_second() * 1e-6,
        mrays_per_s: stats.rays_per_second() * 1e-6,
        mean_radiance: img.mean().to_array(),
        images: files.iter().map(|f| f.display().to_string()).collect(),
    };
    if g.json {
        return super::print_json(&r);
    }
    println!(
        "{}: {} triangles, {}x{} at {} spp, {} threads",
        r.scene, r.triangles, r.width, r.height, r.spp, r.threads
    );
    println!(
        "paths {}  segments {}  shadow rays {}  in {:.2} s: {:.2} M segments/s, {:.2} M rays/s",
        r.paths, r.segments, r.shadow_rays, r.render_seconds, r.msegments_per_s, r.mrays_per_s
    );
    println!(
        "mean radiance {:.4} {:.4} {:.4}",
        r.mean_radiance[0], r.mean_radiance[1], r.mean_radiance[2]
    );
    for f in &r.images {
        println!("wrote {f}");
    }
    Ok(())
}

/// File-name-safe version of a scene name.
pub fn sanitize(name: &str) -> String {
    let s: String = name
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '-' || c == '_' {
                c
            } else {
                '_'
            }
        })
        .collect();
    if s.is_empty() {
        "scene".into()
    } else {
        s
    }
}
