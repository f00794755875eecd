//! `hirad reference SCENE --spp N`: path-traced reference image with the solver's conventions
//! (diffuse, one-sided surfaces unless `--two-sided`, front-face emitters, next-event estimation
//! with MIS, sun and sky, Russian roulette). Pixels are radiance. Prints path, segment and
//! shadow-ray counts, the segment and ray rates (wall clock, and per CPU second × threads, which
//! stays meaningful on a shared machine). `--bench` also replays the recorded rays of a subset of
//! rows through the same caster and prints the share of the render spent casting rays.

use super::image_args::{CameraArgs, ImageArgs};
use crate::progress::Bars;
use crate::Global;
use hirad::cluster::{ClusterConfig, ClusterTree, Strategy};
use hirad::ray::RayCaster;
use hirad::render::{CameraView, PathTracer, ReferenceOptions};
use serde::Serialize;
use std::path::Path;

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
    /// Give every surface a diffuse back face (default: back faces are black and absorb;
    /// implied by an MGF file whose non-emitting materials are all `sides 2`).
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
    #[command(flatten)]
    pub reflectance: super::info::SceneFileArgs,
    /// Benchmark: also record the rays of a subset of rows (about 4 million rays), cast them
    /// again through the same caster and report the share of the render time that is ray
    /// casting. Writes no image unless `--image` is given.
    #[arg(long)]
    pub bench: bool,
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
    /// CPU seconds of all threads during the render (Linux).
    render_cpu_seconds: Option<f64>,
    /// Segments per CPU second × threads: the rate the threads would reach with the cores to
    /// themselves (on a shared machine the wall-clock rate is lower).
    msegments_per_cpu_s_x_threads: Option<f64>,
    rays_per_segment: f64,
    mean_radiance: [f32; 3],
    images: Vec<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    bench: Option<Bench>,
}

/// `--bench`: the recorded rays cast again.
#[derive(Serialize)]
struct Bench {
    clustering: String,
    /// Every `row_stride`-th row was recorded.
    row_stride: u32,
    replay_closest_rays: u64,
    replay_shadow_rays: u64,
    replay_closest_mrays_per_s: f64,
    replay_shadow_mrays_per_s: f64,
    /// Seconds ray casting alone takes for the render's counts at the replayed rates.
    ray_seconds: f64,
    /// `ray_seconds / render_seconds`.
    ray_share: f64,
    /// CPU seconds of all threads during the render (Linux; robust to a busy machine).
    render_cpu_seconds: Option<f64>,
    /// CPU seconds of the replay, scaled to the render's ray counts.
    ray_cpu_seconds: Option<f64>,
    /// `ray_cpu_seconds / render_cpu_seconds`.
    ray_share_cpu: Option<f64>,
}

/// Rays recorded by `--bench`, about.
const BENCH_RAYS: u64 = 4_000_000;

pub fn run(a: Args, g: &Global) -> anyhow::Result<()> {
    let opts = a.reflectance.options(a.camera.scene_up());
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
        two_sided: a.two_sided || scene.two_sided,
        rr_depth: a.rr_depth,
        max_depth: a.max_depth,
    };
    let cancel = super::cancel_on_ctrl_c(None);
    let bars = Bars::new(g.quiet);
    let tracer = PathTracer::new(&scene, &caster, &ropts);
    let cpu0 = cpu_seconds();
    let (img, stats) = tracer.render(&view, &bars, Some(&cancel))?;
    let render_cpu = cpu_seconds().zip(cpu0).map(|(b, a)| b - a);
    let stem = format!("reference-{}", sanitize(&scene.name));
    let files = if a.bench && a.out.image.is_none() {
        Vec::new()
    } else {
        a.out.write(&img, Path::new("hirad-out"), &stem)?
    };
    let bench = if a.bench {
        let total = stats.segments + stats.shadow_rays;
        let row_stride = total.div_ceil(BENCH_RAYS).clamp(1, view.height as u64) as u32;
        let log = tracer.record_rays(&view, row_stride)?;
        let cpu1 = cpu_seconds();
        let (rep, _, _) = log.replay(&caster);
        let replay_cpu = cpu_seconds().zip(cpu1).map(|(b, a)| b - a);
        let recorded = (rep.closest_rays + rep.shadow_rays).max(1) as f64;
        let ray_cpu = replay_cpu.map(|c| c * total as f64 / recorded);
        let ray_seconds = rep.ray_seconds_for(&stats);
        Some(Bench {
            clustering: strategy.name().to_string(),
            row_stride,
            replay_closest_rays: rep.closest_rays,
            replay_shadow_rays: rep.shadow_rays,
            replay_closest_mrays_per_s: rep.closest_per_second() * 1e-6,
            replay_shadow_mrays_per_s: rep.shadow_per_second() * 1e-6,
            ray_seconds,
            ray_share: ray_seconds / stats.seconds.max(1e-12),
            render_cpu_seconds: render_cpu,
            ray_cpu_seconds: ray_cpu,
            ray_share_cpu: ray_cpu.zip(render_cpu).map(|(r, c)| r / c.max(1e-12)),
        })
    } else {
        None
    };
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
        render_cpu_seconds: render_cpu,
        msegments_per_cpu_s_x_threads: render_cpu.map(|c| {
            stats.segments as f64 / c.max(1e-12) * rayon::current_num_threads() as f64 * 1e-6
        }),
        rays_per_segment: (stats.segments + stats.shadow_rays) as f64
            / stats.segments.max(1) as f64,
        mean_radiance: img.mean().to_array(),
        images: files.iter().map(|f| f.display().to_string()).collect(),
        bench,
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
    if let (Some(c), Some(m)) = (r.render_cpu_seconds, r.msegments_per_cpu_s_x_threads) {
        println!(
            "CPU {c:.2} s: {m:.2} M segments per CPU second x {} threads",
            r.threads
        );
    }
    println!(
        "mean radiance {:.4} {:.4} {:.4}",
        r.mean_radiance[0], r.mean_radiance[1], r.mean_radiance[2]
    );
    if let Some(b) = &r.bench {
        println!(
            "rays per segment {:.3}; replay ({}, every {}th row): closest {:.2} M rays/s, shadow {:.2} M rays/s",
            r.rays_per_segment,
            b.clustering,
            b.row_stride,
            b.replay_closest_mrays_per_s,
            b.replay_shadow_mrays_per_s
        );
        println!(
            "ray casting alone {:.2} s of {:.2} s: {:.1}% of the render",
            b.ray_seconds,
            r.render_seconds,
            100.0 * b.ray_share
        );
        if let (Some(r), Some(c), Some(f)) =
            (b.ray_cpu_seconds, b.render_cpu_seconds, b.ray_share_cpu)
        {
            println!(
                "CPU time: ray casting alone {r:.2} s of {c:.2} s: {:.1}% of the render",
                100.0 * f
            );
        }
    }
    for f in &r.images {
        println!("wrote {f}");
    }
    Ok(())
}

/// CPU time of all threads of this process so far (Linux: the sum of the first field of
/// `/proc/self/task/*/schedstat`, nanoseconds); `None` elsewhere.
fn cpu_seconds() -> Option<f64> {
    let mut ns = 0u64;
    for e in std::fs::read_dir("/proc/self/task").ok()? {
        let p = e.ok()?.path().join("schedstat");
        let text = std::fs::read_to_string(p).ok()?;
        ns += text.split_whitespace().next()?.parse::<u64>().ok()?;
    }
    Some(ns as f64 * 1e-9)
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
