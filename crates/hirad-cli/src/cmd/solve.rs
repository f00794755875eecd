//! `hirad solve SCENE`: hierarchical radiosity with clustering; writes `solution.glb`,
//! `solution.ply` (per-vertex radiosity) and `stats.json` into `--out`, prints a summary (or the
//! statistics as JSON with `--json` / `--bench`).

use crate::progress::Bars;
use crate::Global;
use anyhow::Context;
use hirad::cluster::{ClusterConfig, ClusterTree, Strategy};
use hirad::progress::{NoProgress, Progress};
use hirad::radiosity::config::parse_bytes;
use hirad::radiosity::{
    memory, output, solve_recording, ClusterEmission, Oracle, Reception, SolverConfig,
    VisibilityMode,
};
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Instant;

#[derive(clap::Args, Debug)]
pub struct Args {
    /// Scene: a file path or a built-in name.
    pub scene: String,
    #[command(flatten)]
    pub reflectance: super::info::SceneFileArgs,
    /// Viewpoint of the image (`--up y|z` also sets the scene's up axis).
    #[command(flatten)]
    pub camera: super::image_args::CameraArgs,
    /// The solver's settings.
    #[command(flatten)]
    pub solver: SolverArgs,
    /// Seed of the random choices, and of the final gather's per-pixel generators (`--gather`)
    /// [default: 1].
    #[arg(long)]
    pub seed: Option<u64>,
    /// Output directory.
    #[arg(long, default_value = "hirad-out/solve")]
    pub out: PathBuf,
    /// Image of the solution from the scene's default viewpoint (always written into --out as
    /// image.exr and image.png; --image FILE.png|.exr|DIR writes it there instead).
    #[command(flatten)]
    pub image: super::image_args::ImageArgs,
    #[command(flatten)]
    pub raster: super::image_args::RasterArgs,
    /// Final gather of the image from the solution (`--gather N`; seeded by --seed).
    #[command(flatten)]
    pub gather: super::image_args::GatherArgs,
    /// Discontinuous per-element colours instead of the smooth mesh (vertex values fitted to
    /// the elements' means).
    #[arg(long)]
    pub flat: bool,
    /// Benchmark: solve, print the statistics as JSON, write no files.
    #[arg(long)]
    pub bench: bool,
    /// Also write the scene's triangles and one in 16 of the solve's shadow segments to FILE,
    /// in the format of `hirad raybench --export`, for timing the solver's own rays
    /// (`raybench --segments`, `benches/embree/`); they are held in memory until the end, 32
    /// bytes each [default: none]
    #[arg(long, value_name = "FILE")]
    pub export_rays: Option<PathBuf>,
}

/// `--export-rays` keeps one in this many shadow segments.
const EXPORT_EVERY: u32 = 16;

/// The flags that set up a solve, shared by `solve` and `validate`.
#[derive(clap::Args, Debug)]
pub struct SolverArgs {
    /// Clustering strategy (kdt, obt, okdt, okdt-p, tf-oct, proxi, sah, objr).
    #[arg(long, default_value = "proxi")]
    pub clustering: String,
    /// Solver preset the other flags override (fast, default, fine, reference).
    #[arg(long, default_value = "default")]
    pub preset: String,
    /// Refinement oracle: bf or error [default: bf, every preset].
    #[arg(long)]
    pub refine: Option<String>,
    /// Absolute refinement threshold ε in W/m² (default: --eps-rel × emitted power / area).
    #[arg(long)]
    pub eps: Option<f64>,
    /// Refinement threshold relative to the scene's emitted power per unit area [default: the
    /// preset's: fast 0.2, default 0.05, fine 0.0125, reference 0.003125].
    #[arg(long)]
    pub eps_rel: Option<f64>,
    /// Give every surface a back face with its own radiosity (implied by an MGF file whose
    /// non-emitting materials are all `sides 2`, the MGF default).
    #[arg(long)]
    pub two_sided: bool,
    /// Visibility: rays, volume or none [default: rays].
    #[arg(long)]
    pub visibility: Option<String>,
    /// Shadow rays per link [default: the preset's: fast 1, default 4, fine 8, reference 16].
    #[arg(long)]
    pub shadow_rays: Option<u32>,
    /// Minimum element area (scene units²; default --min-area-rel × total area).
    #[arg(long)]
    pub min_area: Option<f64>,
    /// Minimum element area relative to the total surface area, both faces of two-sided
    /// surfaces counted (used without --min-area; default 1e-3, preset `reference` 2.5e-4).
    #[arg(long)]
    pub min_area_rel: Option<f64>,
    /// Levels of subdivision below the minimum area where a shadow boundary or a close source's
    /// light crosses an element whose light the oracle would still refine [default: 2].
    #[arg(long)]
    pub shadow_levels: Option<u32>,
    /// Maximum refine+gather iterations [default: 100].
    #[arg(long)]
    pub max_iters: Option<u32>,
    /// Convergence threshold on the relative change of total power [default: 1e-4].
    #[arg(long)]
    pub tol_converge: Option<f64>,
    /// Memory budget of the whole process, e.g. 4GB: the scene, cluster tree and images are
    /// counted first (a budget below them is an error before any work), refinement stops
    /// before the rest would pass it [default: none; `hirad info` estimates a solve's need].
    #[arg(long)]
    pub max_memory: Option<String>,
    /// Cluster reception: oriented or isotropic [default: oriented].
    #[arg(long)]
    pub cluster_receive: Option<String>,
    /// Cluster emission: directional (default: sampled on the cluster's surfaces, estimated
    /// from their normals) or isotropic (the paper's Φ/4π with projected area ΣA/4).
    #[arg(long)]
    pub cluster_emission: Option<String>,
    /// Volume visibility: a cluster smaller than this × the segment length is used as a
    /// volume (default 0.1, > 0); smaller is more precise and slower.
    #[arg(long)]
    pub vol_ratio: Option<f32>,
}

impl SolverArgs {
    /// The solver configuration these flags give, with the random choices seeded by `seed`
    /// (the preset's when `None`), validated.
    pub fn config(&self, seed: Option<u64>) -> anyhow::Result<SolverConfig> {
        let mut c = SolverConfig::preset(&self.preset)?;
        if let Some(r) = &self.refine {
            c.refine = Oracle::parse(r)?;
        }
        if self.eps.is_some() {
            c.eps = self.eps;
        }
        if let Some(e) = self.eps_rel {
            c.eps_rel = e;
        }
        c.two_sided |= self.two_sided;
        if let Some(v) = &self.visibility {
            c.visibility = VisibilityMode::parse(v)?;
        }
        if let Some(n) = self.shadow_rays {
            c.shadow_rays = n;
        }
        if self.min_area.is_some() {
            c.min_area = self.min_area;
        }
        if let Some(a) = self.min_area_rel {
            c.min_area_rel = a;
        }
        if let Some(n) = self.shadow_levels {
            c.shadow_levels = n;
        }
        if let Some(n) = self.max_iters {
            c.max_iters = n;
        }
        if let Some(t) = self.tol_converge {
            c.tol_converge = t;
        }
        if let Some(m) = &self.max_memory {
            c.max_memory = Some(parse_bytes(m)?);
        }
        if let Some(r) = &self.cluster_receive {
            c.cluster_receive = Reception::parse(r)?;
        }
        if let Some(e) = &self.cluster_emission {
            c.cluster_emission = ClusterEmission::parse(e)?;
        }
        if let Some(s) = seed {
            c.seed = s;
        }
        if let Some(v) = self.vol_ratio {
            c.vol_ratio = v;
        }
        c.validate()?;
        Ok(c)
    }
}

pub fn run(args: Args, g: &Global) -> anyhow::Result<()> {
    let mut cfg = args.solver.config(args.seed)?;
    if args.export_rays.is_some() && cfg.visibility != VisibilityMode::Rays {
        return Err(hirad::Error::Config(format!(
            "--export-rays writes shadow rays, which --visibility {} does not cast",
            cfg.visibility.name()
        ))
        .into());
    }
    let strategy = Strategy::parse(&args.solver.clustering)?;
    let opts = args.reflectance.options(args.camera.scene_up());
    let scene = super::load_scene(&args.scene, &opts)?;
    // A file whose surfaces all have back faces (MGF `sides 2`) is solved two-sided.
    cfg.two_sided |= scene.two_sided;
    let view = args.camera.apply(hirad::render::CameraView::from_camera(
        &scene.default_camera(),
    ))?;
    if !args.bench {
        cfg.reserved_memory = image_bytes(&view);
    }
    // A budget below what the scene needs before any refinement fails before the tree is built.
    let estimate = memory::estimate(
        &scene,
        &cfg,
        rayon::current_num_threads(),
        cfg.reserved_memory,
    );
    memory::check_fixed(&estimate, &cfg)?;
    let t = Instant::now();
    let tree = ClusterTree::build(&scene, strategy, &ClusterConfig::default());
    let cluster_seconds = t.elapsed().as_secs_f64();
    tracing::info!(
        "{} clusters ({}) built in {cluster_seconds:.3} s",
        tree.nodes.len(),
        strategy
    );
    let cancel = Arc::new(AtomicBool::new(false));
    {
        let c = cancel.clone();
        // A second handler cannot be installed in the same process; ignore that case.
        let _ = ctrlc::set_handler(move || c.store(true, Ordering::Relaxed));
    }
    let bars = Bars::new(g.quiet || args.bench || g.json);
    let progress: &dyn Progress = if g.quiet { &NoProgress } else { &bars };
    let every = args.export_rays.as_ref().map(|_| EXPORT_EVERY);
    let (mut sol, rays) = solve_recording(&scene, &tree, &cfg, progress, &cancel, every)?;
    if let Some(p) = &args.export_rays {
        hirad::ray::sample::export_segments(p, &scene, &rays)?;
        tracing::info!("{} shadow segments written to {}", rays.len(), p.display());
    }
    let st = &sol.stats;
    if args.bench {
        let mut v = serde_json::to_value(st)?;
        v["cluster_build_seconds"] = serde_json::json!(cluster_seconds);
        v["history"] = serde_json::json!(st.history.len());
        return super::print_json(&v);
    }
    // The outputs need the elements only: give the links' memory back first.
    sol.links = Default::default();
    let mut files = output::write_outputs(&sol, &scene, &args.out, args.flat)
        .with_context(|| format!("writing the solution into {}", args.out.display()))?;
    {
        let mesh = output::radiosity_mesh(&sol, &scene, args.flat);
        let img = match args.gather.gather {
            Some(n) => {
                args.gather
                    .gather(
                        n,
                        &scene,
                        &mesh,
                        &view,
                        cfg.seed,
                        cfg.two_sided,
                        progress,
                        Some(&cancel),
                    )?
                    .image
            }
            None => {
                let mut ropts = args.raster.options();
                if sol.elements.two_sided {
                    // The solution mesh carries explicit back faces.
                    ropts.back_faces = hirad::render::BackFaces::Cull;
                }
                hirad::render::render_solution(&mesh, &view, &ropts)?
            }
        };
        let written = args.image.write(&img, &args.out, "image")?;
        files.images = written;
    }
    if g.json {
        return super::print_json(&serde_json::json!({
            "stats": st,
            "files": files,
            "cluster_build_seconds": cluster_seconds,
        }));
    }
    println!(
        "{}: {} triangles, {} ({} nodes), {} eps {:.4e}",
        st.scene, st.triangles, st.strategy, st.cluster_nodes, st.refine, st.eps
    );
    println!(
        "elements {} ({} leaves), links {} (ss {}, cs {}, cc {}), {:.1}% of the gathered \
         energy through cluster links",
        st.elements,
        st.leaf_elements,
        st.links,
        st.links_ss,
        st.links_cs,
        st.links_cc,
        st.cluster_energy_percent
    );
    println!(
        "{} iterations ({}), {} rays; time {:.3} s (refine {:.3}, gather {:.3}, push-pull \
         {:.3}); peak memory {:.1} MB counted{}",
        st.iterations,
        if st.converged {
            "converged"
        } else {
            "NOT converged"
        },
        st.rays,
        st.time.total,
        st.time.refine,
        st.time.gather,
        st.time.push_pull,
        st.memory.peak_counted_bytes as f64 / 1e6,
        st.memory
            .vm_hwm_bytes
            .map(|b| format!(", {:.1} MB process peak", b as f64 / 1e6))
            .unwrap_or_default()
    );
    println!(
        "power: emitted {:.4e} W, absorbed {:.4e} W, escaping {:.4e} W",
        st.power.emitted, st.power.absorbed, st.power.escaping
    );
    for w in &st.warnings {
        println!("warning: {w}");
    }
    println!(
        "wrote {}, {}, {}",
        files.glb.display(),
        files.ply.display(),
        files.stats.display()
    );
    for f in &files.images {
        println!("wrote {}", f.display());
    }
    Ok(())
}

/// Bytes the image of `view` holds while it is rendered and written: linear RGB, depth and ids
/// per pixel, and the encoded file.
fn image_bytes(view: &hirad::render::CameraView) -> u64 {
    view.width as u64 * view.height as u64 * 64
}
