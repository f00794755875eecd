//! The study driver (`experiments.md` §1–6): plans the units of work of a study, runs the ones
//! that are not on disk yet, and writes tables, plots and the report.
//!
//! Units of work and their keys in the [`Store`]:
//! - `clusters/<strategy>`: statistics and median build time (§1);
//! - `raybench/<strategy>`: the ray-casting test (§2);
//! - `reference/<viewpoint>`: the reference image of a viewpoint (§3), path traced;
//! - `solve/<strategy>/<eps>`: one solve of the sweep, its images and errors (§4);
//! - `volume/<strategy>`: volumetric against exact visibility (§5).
//!
//! Every unit is written atomically when it completes, so a study that is stopped (Ctrl-C, a
//! killed job) and started again skips finished units. [`plan`] lists the units so that
//! `hirad study --jobs` can print one command per unit for a batch scheduler; results of several
//! output directories are merged with [`merge`].
//!
//! The ε sweep: `tolerances` values of the solver's relative threshold `eps_rel`, a geometric
//! series from `eps_hi` down to `eps_lo` (defaults 0.2 → 0.002, i.e. 10× above to 10× below the
//! solver's default 0.02); the absolute ε of each solve and the share of energy gathered through
//! cluster links are recorded so the series can be checked against the paper's 30–100% range.

use super::plot::{strategy_color, BarPlot, LinePlot, Series};
use super::records::{ClusterRecord, RayRecord, ReferenceRecord, RunMeta, RunRecord, SolveRecord};
use super::report::{self, ReportData, VolumeRow};
use super::store::Store;
use hirad_accel::cluster::{stats::ClusterStats, ClusterConfig, ClusterTree, Prims, Strategy};
use hirad_accel::ray::{sample::sample_segments, Boxes, RayCaster};
use hirad_core::progress::Progress;
use hirad_core::{Error, Result};
use hirad_radiosity::{self as radiosity, SolverConfig, VisibilityMode};
use hirad_render::{self as render, CameraOverrides, CameraView, Image, RasterOptions};
use hirad_scene::{Scene, SceneOptions};
use serde::{Deserialize, Serialize};
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

/// Everything a study needs; serde-able so a study directory records how it was made.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(default)]
pub struct StudyConfig {
    /// Scene path or built-in name.
    pub scene: String,
    pub strategies: Vec<Strategy>,
    pub cluster: ClusterConfig,
    /// Base solver configuration (refinement oracle, visibility, two-sided, ...).
    pub solver: SolverConfig,
    /// Number of ε values of the sweep (0: no sweep).
    pub tolerances: usize,
    /// Explicit `eps_rel` values (override `tolerances`).
    pub eps_list: Vec<f64>,
    pub eps_hi: f64,
    pub eps_lo: f64,
    /// Choose `eps_hi`/`eps_lo` by probe solves so that 30–100% of the gathered energy goes
    /// through cluster links (the paper's range); see [`Study::calibrate`].
    pub eps_auto: bool,
    /// Viewpoints by camera name (empty: every camera of the scene).
    pub viewpoints: Vec<String>,
    /// Image size of the study's renders.
    pub size: (u32, u32),
    pub supersample: u32,
    /// Path-tracer samples per pixel of the references.
    pub reference_spp: u32,
    /// Ray-casting test pairs and seed.
    pub ray_pairs: usize,
    /// Boxes the ray-casting test traverses (`cluster`: the strategies' own, as in the paper).
    pub ray_boxes: Boxes,
    pub seed: u64,
    /// Timed builds per strategy (median reported).
    pub build_repeats: usize,
    /// Run the volumetric-visibility experiment (§5).
    pub volume: bool,
    pub out: PathBuf,
    /// Run only the units whose key starts with one of these (empty: all).
    pub only: Vec<String>,
}

impl Default for StudyConfig {
    fn default() -> Self {
        StudyConfig {
            scene: "office".into(),
            strategies: Strategy::ALL.to_vec(),
            cluster: ClusterConfig::default(),
            // The paper's cluster model: the study reproduces its experiments.
            solver: SolverConfig {
                cluster_emission: radiosity::ClusterEmission::Isotropic,
                ..SolverConfig::default()
            },
            tolerances: 8,
            eps_list: Vec::new(),
            eps_hi: 0.2,
            eps_lo: 0.002,
            eps_auto: true,
            viewpoints: Vec::new(),
            size: (320, 240),
            supersample: 2,
            reference_spp: 256,
            ray_pairs: 100_000,
            ray_boxes: Boxes::Tight,
            seed: 1,
            build_repeats: 5,
            volume: false,
            out: PathBuf::from("hirad-out/study"),
            only: Vec::new(),
        }
    }
}

/// One unit of work.
#[derive(Clone, Debug, PartialEq)]
pub enum Job {
    Clusters(Strategy),
    Raybench(Strategy),
    Reference(String),
    Solve(Strategy, f64),
    Volume(Strategy),
}

/// Format an ε so that it is a stable key.
pub fn eps_key(eps: f64) -> String {
    format!("eps-{eps:.4e}")
}

impl Job {
    /// The unit's key in the store.
    pub fn key(&self) -> String {
        match self {
            Job::Clusters(s) => format!("clusters/{s}"),
            Job::Raybench(s) => format!("raybench/{s}"),
            Job::Reference(v) => format!("reference/{v}"),
            Job::Solve(s, e) => format!("solve/{s}/{}", eps_key(*e)),
            Job::Volume(s) => format!("volume/{s}"),
        }
    }
}

impl StudyConfig {
    /// The `eps_rel` values of the sweep, largest first.
    pub fn eps_values(&self) -> Vec<f64> {
        let mut v = if !self.eps_list.is_empty() {
            self.eps_list.clone()
        } else if self.tolerances == 0 {
            Vec::new()
        } else if self.tolerances == 1 {
            vec![self.eps_hi]
        } else {
            let n = self.tolerances;
            let r = (self.eps_lo / self.eps_hi).powf(1.0 / (n - 1) as f64);
            (0..n).map(|i| self.eps_hi * r.powi(i as i32)).collect()
        };
        v.sort_by(|a, b| b.total_cmp(a));
        v
    }

    fn selected(&self, key: &str) -> bool {
        self.only.is_empty() || self.only.iter().any(|p| key.starts_with(p.as_str()))
    }
}

/// Viewpoints of the study (name, view): the named cameras, or every camera of the scene, at
/// the study's image size.
pub fn viewpoints(scene: &Scene, cfg: &StudyConfig) -> Result<Vec<(String, CameraView)>> {
    let cams: Vec<_> = if cfg.viewpoints.is_empty() {
        scene.cameras.clone()
    } else {
        cfg.viewpoints
            .iter()
            .map(|n| {
                scene
                    .cameras
                    .iter()
                    .find(|c| &c.name == n)
                    .cloned()
                    .ok_or_else(|| {
                        Error::Config(format!(
                            "scene has no viewpoint '{n}' (has: {})",
                            scene
                                .cameras
                                .iter()
                                .map(|c| c.name.as_str())
                                .collect::<Vec<_>>()
                                .join(", ")
                        ))
                    })
            })
            .collect::<Result<_>>()?
    };
    let cams = if cams.is_empty() {
        vec![scene.default_camera()]
    } else {
        cams
    };
    let o = CameraOverrides {
        size: Some(cfg.size),
        ..Default::default()
    };
    cams.iter()
        .map(|c| Ok((c.name.clone(), CameraView::with_overrides(c, &o)?)))
        .collect()
}

/// Result of the ε calibration.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Calibration {
    pub strategy: Strategy,
    /// Probes: (relative ε, % cluster energy, solve seconds).
    pub probes: Vec<(f64, f64, f64)>,
    pub eps_hi: f64,
    pub eps_lo: f64,
}

/// Pick the sweep's ends from probes `(ε, %cluster, s)` sorted by decreasing ε, so that the
/// sweep spans the paper's 30–100% of energy through cluster links: `eps_hi` is the smallest
/// probed ε that still sends ≥ 95% through clusters (the first probe when none does), `eps_lo`
/// the smallest probed ε below it with ≥ 30%. When the share drops from ≥ 95% to < 30% between
/// two probes (an abrupt transition, as under a sun), `eps_lo` is the first probe below 30%, so
/// the sweep crosses the whole band; when no probe goes below 30%, `eps_lo` = `eps_hi` / 8.
pub fn pick_range(probes: &[(f64, f64, f64)]) -> (f64, f64) {
    let hi = probes
        .iter()
        .filter(|p| p.1 >= 95.0)
        .map(|p| p.0)
        .fold(f64::NAN, f64::min);
    let hi = if hi.is_finite() {
        hi
    } else {
        probes.first().map(|p| p.0).unwrap_or(0.2)
    };
    let lo = probes
        .iter()
        .filter(|p| p.1 >= 30.0 && p.0 < hi)
        .map(|p| p.0)
        .fold(f64::NAN, f64::min);
    let lo = if lo.is_finite() {
        lo
    } else if let Some(p) = probes.iter().find(|p| p.0 < hi && p.1 < 30.0) {
        p.0
    } else {
        hi / 8.0
    };
    (hi, lo)
}

/// The units of a study, in the order they run; `eps` are the sweep's relative ε.
pub fn plan(scene: &Scene, cfg: &StudyConfig, eps: &[f64]) -> Result<Vec<Job>> {
    let mut jobs = Vec::new();
    for &s in &cfg.strategies {
        jobs.push(Job::Clusters(s));
    }
    if cfg.ray_pairs > 0 {
        for &s in &cfg.strategies {
            jobs.push(Job::Raybench(s));
        }
    }
    if !eps.is_empty() {
        for (name, _) in viewpoints(scene, cfg)? {
            jobs.push(Job::Reference(name));
        }
        for &s in &cfg.strategies {
            for &e in eps {
                jobs.push(Job::Solve(s, e));
            }
        }
    }
    if cfg.volume {
        for &s in &cfg.strategies {
            jobs.push(Job::Volume(s));
        }
    }
    Ok(jobs
        .into_iter()
        .filter(|j| cfg.selected(&j.key()))
        .collect())
}

/// A study in progress: the scene, its prepared inputs and the store.
pub struct Study<'a> {
    pub cfg: StudyConfig,
    pub scene: Scene,
    pub prims: Prims,
    pub views: Vec<(String, CameraView)>,
    pub store: Store,
    pub meta: RunMeta,
    /// Temporary files left by an earlier, killed invocation and removed by [`Study::new`].
    pub removed_temp: usize,
    progress: &'a dyn Progress,
    cancel: &'a AtomicBool,
    /// `<out>/.lock`, locked while the study lives ([`lock_dir`]).
    _lock: std::fs::File,
}

/// Take the study directory `dir` (created if needed) for this process: an exclusive lock on
/// `dir/.lock`, which the system releases when the process ends however it ends. A second
/// study in the same directory gets an error instead of interleaving its writes.
pub fn lock_dir(dir: &std::path::Path) -> Result<std::fs::File> {
    std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    let p = dir.join(".lock");
    let f = std::fs::OpenOptions::new()
        .create(true)
        .truncate(false)
        .write(true)
        .open(&p)
        .map_err(|e| Error::io(&p, e))?;
    match f.try_lock() {
        Ok(()) => Ok(f),
        Err(std::fs::TryLockError::WouldBlock) => Err(Error::Config(format!(
            "{}: another `hirad study` is running in this directory (it holds {})",
            dir.display(),
            p.display()
        ))),
        Err(std::fs::TryLockError::Error(e)) => Err(Error::io(&p, e)),
    }
}

/// Remove the temporary files (`.hirad-*.tmp`, see [`hirad_core::io::write_atomic`]) that a killed
/// invocation can leave below `dir`; returns how many. Only one study runs in a directory at a
/// time, so none of them belongs to a live writer.
pub fn remove_stale_temp(dir: &std::path::Path) -> Result<usize> {
    let mut n = 0;
    for p in super::store::walk_files(dir, &[]) {
        let name = p
            .file_name()
            .map(|n| n.to_string_lossy().to_string())
            .unwrap_or_default();
        if name.starts_with(".hirad-") && name.ends_with(".tmp") {
            std::fs::remove_file(&p).map_err(|e| Error::io(&p, e))?;
            tracing::info!("removed {} left by an interrupted run", p.display());
            n += 1;
        }
    }
    Ok(n)
}

/// PNG exposure (stops) that maps the image's white (99th-percentile luminance, as the CIELUV
/// metric takes it) to 1, so that indoor scenes and sunlit ones are both readable. Errors are
/// always computed on the linear images, never on the PNGs.
pub fn auto_exposure(img: &Image) -> f32 {
    let yn = hirad_render::metrics::white_luminance(img);
    if yn.is_finite() && yn > 0.0 {
        (-yn.log2()).clamp(-30.0, 30.0) as f32
    } else {
        0.0
    }
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    if v.is_empty() {
        return f64::NAN;
    }
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

fn ms(t: Instant) -> f64 {
    t.elapsed().as_secs_f64() * 1e3
}

impl<'a> Study<'a> {
    /// Load the scene and prepare a study.
    pub fn new(
        mut cfg: StudyConfig,
        progress: &'a dyn Progress,
        cancel: &'a AtomicBool,
    ) -> Result<Self> {
        let scene = Scene::load(&cfg.scene, &SceneOptions::default())?;
        // A file whose surfaces all have back faces (MGF `sides 2`) is solved two-sided.
        cfg.solver.two_sided |= scene.two_sided;
        let prims = Prims::from_scene(&scene);
        let views = viewpoints(&scene, &cfg)?;
        let lock = lock_dir(&cfg.out)?;
        let removed_temp = remove_stale_temp(&cfg.out)?;
        let store = Store::new(&cfg.out);
        let meta = RunMeta {
            scene_objects: scene.objects.len(),
            ..RunMeta::current(&cfg.scene)
        };
        store.put("config", &cfg)?;
        Ok(Study {
            cfg,
            scene,
            prims,
            views,
            store,
            meta,
            removed_temp,
            progress,
            cancel,
            _lock: lock,
        })
    }

    /// Store the record of one invocation (key `runs/<start ms>-<pid>`); returns the key.
    pub fn record_run(&self, rec: &RunRecord) -> Result<String> {
        let key = format!("runs/{:.0}-{}", rec.started_unix * 1e3, std::process::id());
        self.store.put(&key, rec)?;
        Ok(key)
    }

    /// Probe solves choosing the sweep's ε range (stored as unit `calibrate`).
    pub fn calibrate(&self) -> Result<Calibration> {
        if let Some(c) = self.store.get::<Calibration>("calibrate") {
            return Ok(c);
        }
        let strategy = if self.cfg.strategies.contains(&Strategy::OkdtP) {
            Strategy::OkdtP
        } else {
            self.cfg
                .strategies
                .first()
                .copied()
                .unwrap_or(Strategy::OkdtP)
        };
        self.progress.message("calibrating ε");
        let tree = self.tree(strategy);
        let mut probes = Vec::new();
        let mut spent = 0.0;
        for k in 0..20 {
            self.check_cancel()?;
            let e = 0.5f64.powi(k);
            let solver = SolverConfig {
                eps_rel: e,
                eps: None,
                ..self.cfg.solver.clone()
            };
            let (sol, secs) = self.solve_with(&tree, &solver)?;
            let pct = sol.stats.cluster_energy_percent;
            tracing::info!("calibration ε={e:.3e}: {pct:.1}% through clusters, {secs:.2} s");
            probes.push((e, pct, secs));
            spent += secs;
            // Stop below the paper's range, or before the probes cost more than a few solves.
            if pct < 30.0 || spent > 60.0 {
                break;
            }
        }
        let (eps_hi, eps_lo) = pick_range(&probes);
        let c = Calibration {
            strategy,
            probes,
            eps_hi,
            eps_lo,
        };
        self.store.put("calibrate", &c)?;
        Ok(c)
    }

    /// The sweep's relative ε values, largest first (calibrating first when asked).
    pub fn eps(&self) -> Result<Vec<f64>> {
        if self.cfg.eps_list.is_empty() && self.cfg.tolerances > 0 && self.cfg.eps_auto {
            let c = self.calibrate()?;
            let cfg = StudyConfig {
                eps_hi: c.eps_hi,
                eps_lo: c.eps_lo,
                ..self.cfg.clone()
            };
            return Ok(cfg.eps_values());
        }
        Ok(self.cfg.eps_values())
    }

    /// Every unit of this study.
    pub fn plan(&self) -> Result<Vec<Job>> {
        plan(&self.scene, &self.cfg, &self.eps()?)
    }

    fn check_cancel(&self) -> Result<()> {
        if self.cancel.load(Ordering::Relaxed) {
            Err(Error::Interrupted)
        } else {
            Ok(())
        }
    }

    fn tree(&self, s: Strategy) -> ClusterTree {
        ClusterTree::build_prims(&self.prims, s, &self.cfg.cluster)
    }

    /// Run one unit unless it is on disk; true when it was computed, false when skipped.
    pub fn run_job(&self, job: &Job) -> Result<bool> {
        self.check_cancel()?;
        let key = job.key();
        if self.store.has(&key) {
            tracing::info!("{key}: done earlier, skipped");
            return Ok(false);
        }
        self.progress.message(&key);
        self.compute(job, &key)?;
        tracing::info!("{key}: done");
        Ok(true)
    }

    fn compute(&self, job: &Job, key: &str) -> Result<()> {
        let key = key.to_string();
        match job {
            Job::Clusters(s) => {
                let r = self.cluster_record(*s)?;
                self.store.put(&key, &r)
            }
            Job::Raybench(s) => {
                let r = self.ray_record(*s)?;
                self.store.put(&key, &r)
            }
            Job::Reference(v) => {
                let r = self.reference(v)?;
                self.store.put(&key, &r)
            }
            Job::Solve(s, e) => {
                let r = self.solve_record(*s, *e)?;
                self.store.put(&key, &r)
            }
            Job::Volume(s) => {
                let r = self.volume_row(*s)?;
                self.store.put(&key, &r)
            }
        }
    }

    fn cluster_record(&self, s: Strategy) -> Result<ClusterRecord> {
        let mut times = Vec::new();
        let mut tree = None;
        for _ in 0..self.cfg.build_repeats.max(1) {
            let t = Instant::now();
            let tr = self.tree(s);
            times.push(ms(t));
            tree = Some(tr);
        }
        let tree = tree.expect("at least one build");
        let st = ClusterStats::compute(&tree, &self.prims);
        Ok(ClusterRecord {
            meta: self.meta.clone(),
            strategy: s,
            clusters: st.clusters,
            depth_max: st.depth_max as usize,
            depth_mean: st.depth_mean,
            avg_surfaces: st.surfaces_per_cluster_avg,
            avg_children: st.children_per_cluster_avg,
            branching: st.branching_factor,
            overlap: st.overlap,
            empty_space: st.empty_space_ratio,
            tree_bytes: tree.memory_bytes(),
            build_ms: median(times),
        })
    }

    fn ray_record(&self, s: Strategy) -> Result<RayRecord> {
        let segs = sample_segments(&self.scene, self.cfg.ray_pairs, self.cfg.seed);
        let t = Instant::now();
        let tree = self.tree(s);
        let caster = RayCaster::with_boxes(&self.scene, &tree, self.cfg.ray_boxes);
        let build_ms = ms(t);
        let t = Instant::now();
        let occluded = caster.count_occluded(&segs);
        let query_ms = ms(t);
        let (_, stats) = caster.occluded_batch_stats(&segs);
        Ok(RayRecord {
            meta: self.meta.clone(),
            strategy: s,
            pairs: segs.len(),
            seed: self.cfg.seed,
            boxes: self.cfg.ray_boxes,
            build_ms,
            query_ms,
            mrays_per_s: segs.len() as f64 / (query_ms * 1e3).max(1e-12),
            occluded: occluded as usize,
            nodes_per_ray: stats.nodes_per_ray(),
            tris_per_ray: stats.tris_per_ray(),
        })
    }

    fn view(&self, name: &str) -> Result<&CameraView> {
        self.views
            .iter()
            .find(|(n, _)| n == name)
            .map(|(_, v)| v)
            .ok_or_else(|| Error::Config(format!("no viewpoint '{name}'")))
    }

    fn reference_path(&self, name: &str) -> PathBuf {
        self.cfg.out.join("reference").join(format!("{name}.exr"))
    }

    fn reference(&self, name: &str) -> Result<ReferenceRecord> {
        let view = self.view(name)?;
        let tree = self.tree(Strategy::Sah);
        let caster = RayCaster::new(&self.scene, &tree);
        let t = Instant::now();
        let opts = render::pathtrace::ReferenceOptions {
            spp: self.cfg.reference_spp,
            seed: self.cfg.seed,
            two_sided: self.cfg.solver.two_sided,
            ..Default::default()
        };
        let (img, _) =
            render::pathtrace::render_reference(&self.scene, &caster, view, &opts, self.progress)?;
        let seconds = t.elapsed().as_secs_f64();
        let path = self.reference_path(name);
        img.write_exr(&path)?;
        img.write_png(&path.with_extension("png"), auto_exposure(&img))?;
        Ok(ReferenceRecord {
            meta: self.meta.clone(),
            viewpoint: name.to_string(),
            method: format!("path tracer, {} spp", self.cfg.reference_spp),
            seconds,
            image: format!("reference/{name}.png"),
        })
    }

    fn render_views(&self, sol: &radiosity::Solution, dir: &str) -> Result<Vec<(String, Image)>> {
        let mesh = radiosity::output::radiosity_mesh(sol, &self.scene, false);
        let opts = RasterOptions {
            supersample: self.cfg.supersample,
            ..Default::default()
        };
        let mut out = Vec::new();
        for (name, view) in &self.views {
            let img = render::render_solution(&mesh, view, &opts)?;
            let rel = format!("{dir}/{name}.png");
            img.write_png(&self.cfg.out.join(&rel), auto_exposure(&img))?;
            out.push((rel, img));
        }
        Ok(out)
    }

    /// Solve with `tree` (built once by the caller, so repeated solves of one strategy share
    /// it); the time is the solve's alone, as in the paper.
    fn solve_with(
        &self,
        tree: &ClusterTree,
        solver: &SolverConfig,
    ) -> Result<(radiosity::Solution, f64)> {
        let t = Instant::now();
        let sol =
            radiosity::solve_cancellable(&self.scene, tree, solver, self.progress, self.cancel)?;
        Ok((sol, t.elapsed().as_secs_f64()))
    }

    fn solve_record(&self, s: Strategy, eps_rel: f64) -> Result<SolveRecord> {
        let solver = SolverConfig {
            eps_rel,
            eps: None,
            ..self.cfg.solver.clone()
        };
        let (sol, solve_s) = self.solve_with(&self.tree(s), &solver)?;
        let dir = format!("solve/{s}/{}", eps_key(eps_rel));
        let imgs = self.render_views(&sol, &dir)?;
        let mut errors = Vec::new();
        for ((name, _), (_, img)) in self.views.iter().zip(&imgs) {
            // A job run alone (`--jobs`, `--only`) makes the reference it needs; the path
            // tracer is deterministic, so every machine makes the same one.
            let job = Job::Reference(name.clone());
            if !self.store.has(&job.key()) {
                self.run_job(&job)?;
            }
            let reference = Image::read(&self.reference_path(name))?;
            errors.push(hirad_render::metrics::compare(img, &reference)?.rms_delta_e);
        }
        let st = &sol.stats;
        Ok(SolveRecord {
            meta: self.meta.clone(),
            strategy: s,
            refine: solver.refine.name().to_string(),
            visibility: solver.visibility.name().to_string(),
            eps: eps_rel,
            solve_s,
            elements: st.elements,
            links: st.links,
            cluster_energy_pct: st.cluster_energy_percent,
            errors,
            images: imgs.into_iter().map(|(r, _)| r).collect(),
        })
    }

    fn volume_row(&self, s: Strategy) -> Result<VolumeRow> {
        let exact_cfg = SolverConfig {
            visibility: VisibilityMode::Rays,
            ..self.cfg.solver.clone()
        };
        let vol_cfg = SolverConfig {
            visibility: VisibilityMode::Volume,
            ..self.cfg.solver.clone()
        };
        let tree = self.tree(s);
        let (exact, exact_s) = self.solve_with(&tree, &exact_cfg)?;
        let exact_imgs = self.render_views(&exact, &format!("volume/{s}/exact"))?;
        let (vol, volume_s) = self.solve_with(&tree, &vol_cfg)?;
        let vol_imgs = self.render_views(&vol, &format!("volume/{s}/volume"))?;
        let mut err = 0.0;
        for ((_, a), (_, b)) in vol_imgs.iter().zip(&exact_imgs) {
            err += hirad_render::metrics::compare(a, b)?.rms_delta_e;
        }
        Ok(VolumeRow {
            strategy: s,
            volume_s,
            exact_s,
            error: err / vol_imgs.len().max(1) as f64,
            image: vol_imgs.first().map(|(r, _)| r.clone()).unwrap_or_default(),
        })
    }

    /// Run every planned unit that is not done yet, references first (solves compare against
    /// them), and store the invocation's [`RunRecord`], also when it was interrupted or failed.
    /// `on_unit(job, i, n)` is called before unit `i` of `n` (for an overall progress bar).
    pub fn run_all(&self, on_unit: &mut dyn FnMut(&Job, usize, usize)) -> Result<RunRecord> {
        let started = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map(|d| d.as_secs_f64())
            .unwrap_or(0.0);
        let t0 = Instant::now();
        let mut rec = RunRecord {
            meta: self.meta.clone(),
            started_unix: started,
            removed_temp: self.removed_temp,
            ..Default::default()
        };
        let r = self.plan().and_then(|jobs| {
            let (refs, rest): (Vec<Job>, Vec<Job>) = jobs
                .into_iter()
                .partition(|j| matches!(j, Job::Reference(_)));
            let n = refs.len() + rest.len();
            for (i, j) in refs.iter().chain(rest.iter()).enumerate() {
                on_unit(j, i, n);
                if self.run_job(j)? {
                    rec.computed.push(j.key());
                } else {
                    rec.skipped.push(j.key());
                }
            }
            Ok(())
        });
        rec.wall_s = t0.elapsed().as_secs_f64();
        rec.outcome = match &r {
            Ok(()) => "finished".into(),
            Err(Error::Interrupted) => "interrupted".into(),
            Err(e) => format!("failed: {e}"),
        };
        self.record_run(&rec)?;
        r.map(|()| rec)
    }
}

/// Collect every record in a study directory into the report's data.
pub fn collect(out: &std::path::Path) -> Result<ReportData> {
    let store = Store::new(out);
    let cfg: StudyConfig = store.get("config").unwrap_or_default();
    let mut d = ReportData {
        meta: RunMeta::current(&cfg.scene),
        only: cfg.only.clone(),
        ..Default::default()
    };
    let order = |s: Strategy| Strategy::ALL.iter().position(|&x| x == s).unwrap_or(99);
    for k in store.keys("clusters") {
        if let Some(r) = store.get::<ClusterRecord>(&k) {
            d.meta = r.meta.clone();
            d.clusters.push(r);
        }
    }
    d.clusters.sort_by_key(|r| order(r.strategy));
    for k in store.keys("raybench") {
        if let Some(r) = store.get::<RayRecord>(&k) {
            d.rays.push(r);
        }
    }
    d.rays.sort_by_key(|r| order(r.strategy));
    for k in store.keys("solve") {
        if let Some(r) = store.get::<SolveRecord>(&k) {
            d.solves.push(r);
        }
    }
    for k in store.keys("volume") {
        if let Some(r) = store.get::<VolumeRow>(&k) {
            d.volume.push(r);
        }
    }
    d.volume.sort_by_key(|r| order(r.strategy));
    for k in store.keys("runs") {
        if let Some(r) = store.get::<RunRecord>(&k) {
            d.runs.push(r);
        }
    }
    d.runs
        .sort_by(|a, b| a.started_unix.total_cmp(&b.started_unix));
    Ok(d)
}

/// Write CSV tables, plots, `report.md` and `report.html` for a study directory.
pub fn write_outputs(out: &std::path::Path, d: &mut ReportData) -> Result<Vec<PathBuf>> {
    let mut files = Vec::new();
    let plots = out.join("plots");
    // Fig. 6: clusters, children per cluster, ray-casting time per strategy.
    if !d.clusters.is_empty() {
        let bars = |title: &str, y: &str, f: &dyn Fn(&ClusterRecord) -> f64| BarPlot {
            title: title.into(),
            y_label: y.into(),
            log_y: false,
            bars: d
                .clusters
                .iter()
                .map(|r| (r.strategy.to_string(), strategy_color(r.strategy), f(r)))
                .collect(),
        };
        let scene = &d.meta.scene;
        let f1 = bars(
            &format!("Clusters per strategy ({scene})"),
            "clusters",
            &|r| r.clusters as f64,
        )
        .write(&plots.join("clusters"))?;
        let f2 = bars(
            &format!("Children per cluster ({scene})"),
            "children / cluster (mean over clusters)",
            &|r| r.avg_children,
        )
        .write(&plots.join("children"))?;
        d.figures.insert("clusters".into(), rel(out, &f1));
        d.figures.insert("children".into(), rel(out, &f2));
        files.extend(f1);
        files.extend(f2);
    }
    if !d.rays.is_empty() {
        // Log scale when the strategies differ by orders of magnitude (kdt on large scenes).
        let q: Vec<f64> = d
            .rays
            .iter()
            .map(|r| r.query_ms)
            .filter(|v| *v > 0.0)
            .collect();
        let spread =
            q.iter().cloned().fold(0.0, f64::max) / q.iter().cloned().fold(f64::INFINITY, f64::min);
        let f = BarPlot {
            title: format!(
                "Ray-casting test: {} segments ({})",
                d.rays[0].pairs, d.meta.scene
            ),
            y_label: "query time (ms)".into(),
            log_y: spread > 30.0,
            bars: d
                .rays
                .iter()
                .map(|r| {
                    (
                        r.strategy.to_string(),
                        strategy_color(r.strategy),
                        r.query_ms,
                    )
                })
                .collect(),
        }
        .write(&plots.join("raytime"))?;
        d.figures.insert("raytime".into(), rel(out, &f));
        files.extend(f);
    }
    if !d.solves.is_empty() {
        let curves = report::curves(&d.solves);
        let series = |f: &dyn Fn(&SolveRecord) -> (f64, f64)| -> Vec<Series> {
            curves
                .iter()
                .map(|(s, v)| Series {
                    name: s.to_string(),
                    color: strategy_color(*s),
                    points: v.iter().map(|r| f(r)).collect(),
                })
                .collect()
        };
        let f2 = LinePlot {
            title: format!("Time vs error ({})", d.meta.scene),
            x_label: "solve time (s)".into(),
            y_label: "RMS ΔE*uv".into(),
            log_x: true,
            log_y: true,
            series: series(&|r| (r.solve_s, r.error())),
        }
        .write(&plots.join("time_error"))?;
        let f3 = LinePlot {
            title: format!("Error vs ε ({})", d.meta.scene),
            x_label: "ε (relative)".into(),
            y_label: "RMS ΔE*uv".into(),
            log_x: true,
            log_y: false,
            series: series(&|r| (r.eps, r.error())),
        }
        .write(&plots.join("error_eps"))?;
        d.figures.insert("time_error".into(), rel(out, &f2));
        d.figures.insert("error_eps".into(), rel(out, &f3));
        files.extend(f2);
        files.extend(f3);
    }
    // CSV tables.
    let scene = &d.meta.scene;
    files.push(write_csv(
        &out.join("sweep.csv"),
        "scene,strategy,refine,visibility,eps_rel,solve_s,elements,links,cluster_energy_pct,rms_delta_e",
        d.solves.iter().map(|r| {
            format!(
                "{scene},{},{},{},{:e},{:.6},{},{},{:.3},{:.6}",
                r.strategy, r.refine, r.visibility, r.eps, r.solve_s, r.elements, r.links,
                r.cluster_energy_pct, r.error()
            )
        }),
    )?);
    files.push(write_csv(
        &out.join("clusters.csv"),
        "scene,strategy,clusters,depth_max,depth_mean,avg_surfaces,avg_children,branching,overlap,empty_space,tree_bytes,build_ms",
        d.clusters.iter().map(|r| {
            format!(
                "{scene},{},{},{},{:.4},{:.4},{:.4},{:.4},{:.6},{:.6},{},{:.4}",
                r.strategy, r.clusters, r.depth_max, r.depth_mean, r.avg_surfaces,
                r.avg_children, r.branching, r.overlap, r.empty_space, r.tree_bytes, r.build_ms
            )
        }),
    )?);
    files.push(write_csv(
        &out.join("raybench.csv"),
        "scene,strategy,pairs,seed,boxes,build_ms,query_ms,mrays_per_s,occluded,nodes_per_ray,tris_per_ray",
        d.rays.iter().map(|r| {
            format!(
                "{scene},{},{},{},{},{:.4},{:.4},{:.6},{},{:.3},{:.3}",
                r.strategy,
                r.pairs,
                r.seed,
                r.boxes.name(),
                r.build_ms,
                r.query_ms,
                r.mrays_per_s,
                r.occluded,
                r.nodes_per_ray,
                r.tris_per_ray
            )
        }),
    )?);
    let md = report::markdown(d);
    let p = out.join("report.md");
    hirad_core::io::write_bytes_atomic(&p, md.as_bytes())?;
    files.push(p);
    let p = out.join("report.html");
    hirad_core::io::write_bytes_atomic(
        &p,
        report::html(&md, &format!("hirad study: {}", d.meta.scene)).as_bytes(),
    )?;
    files.push(p);
    let p = out.join("results.json");
    hirad_core::io::write_json_atomic(
        &p,
        &serde_json::json!({
            "meta": d.meta, "clusters": d.clusters, "raybench": d.rays, "solves": d.solves,
            "volume": d.volume, "findings": report::findings(d),
            "wall_s": d.total_wall_s(), "runs": d.runs,
            "monotonicity": report::monotonicity(&d.solves).into_iter().map(|(s, m)| (s.to_string(), m)).collect::<std::collections::BTreeMap<_, _>>(),
        }),
    )?;
    files.push(p);
    Ok(files)
}

/// Write a CSV file atomically: the header line, then one line per row.
fn write_csv(
    path: &std::path::Path,
    header: &str,
    rows: impl Iterator<Item = String>,
) -> Result<PathBuf> {
    let mut csv = format!("{header}\n");
    for r in rows {
        csv.push_str(&r);
        csv.push('\n');
    }
    hirad_core::io::write_bytes_atomic(path, csv.as_bytes())?;
    Ok(path.to_path_buf())
}

fn rel(base: &std::path::Path, files: &[PathBuf]) -> Vec<String> {
    files
        .iter()
        .map(|f| {
            f.strip_prefix(base)
                .unwrap_or(f)
                .to_string_lossy()
                .replace('\\', "/")
        })
        .collect()
}

/// Merge the stores of several study directories into `into` (files already there are kept).
pub fn merge(into: &std::path::Path, dirs: &[PathBuf]) -> Result<usize> {
    let mut copied = 0;
    for d in dirs {
        let src = Store::new(d);
        for prefix in [
            "clusters",
            "raybench",
            "reference",
            "solve",
            "volume",
            "runs",
        ] {
            for k in src.keys(prefix) {
                let from = src.path(&k);
                let to = Store::new(into).path(&k);
                if to.exists() {
                    continue;
                }
                let bytes = std::fs::read(&from).map_err(|e| Error::io(&from, e))?;
                hirad_core::io::write_bytes_atomic(&to, &bytes)?;
                copied += 1;
            }
        }
        // Images and references next to the records.
        copy_tree(d, into, &["png", "exr", "svg"])?;
        if !into.join("config.json").exists() {
            // A job's configuration, without the job's `--only`: the merge holds every unit.
            if let Some(mut cfg) = src.get::<StudyConfig>("config") {
                cfg.only.clear();
                cfg.out = into.to_path_buf();
                Store::new(into).put("config", &cfg)?;
            }
        }
    }
    Ok(copied)
}

fn copy_tree(from: &std::path::Path, to: &std::path::Path, exts: &[&str]) -> Result<()> {
    for p in super::store::walk_files(from, &["plots"]) {
        if !p.extension().is_some_and(|x| exts.iter().any(|e| x == *e)) {
            continue;
        }
        let Ok(r) = p.strip_prefix(from) else {
            continue;
        };
        let dst = to.join(r);
        if !dst.exists() {
            let bytes = std::fs::read(&p).map_err(|e| Error::io(&p, e))?;
            hirad_core::io::write_bytes_atomic(&dst, &bytes)?;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_study_directory_takes_one_study_at_a_time() {
        let d = tempfile::tempdir().unwrap();
        let dir = d.path().join("study");
        let first = lock_dir(&dir).unwrap();
        let err = lock_dir(&dir).unwrap_err().to_string();
        assert!(err.contains("another `hirad study` is running"), "{err}");
        drop(first);
        lock_dir(&dir).unwrap();
    }

    #[test]
    fn eps_series_is_geometric_and_sorted() {
        let c = StudyConfig {
            tolerances: 5,
            eps_hi: 0.16,
            eps_lo: 0.01,
            ..Default::default()
        };
        let v = c.eps_values();
        assert_eq!(v.len(), 5);
        for (a, b) in v.iter().zip([0.16, 0.08, 0.04, 0.02, 0.01]) {
            assert!((a - b).abs() < 1e-12, "{v:?}");
        }
        let c = StudyConfig {
            eps_list: vec![0.01, 0.3, 0.1],
            ..Default::default()
        };
        assert_eq!(c.eps_values(), vec![0.3, 0.1, 0.01]);
        assert_eq!(eps_key(0.1), "eps-1.0000e-1");
        assert_eq!(
            Job::Solve(Strategy::OkdtP, 0.25).key(),
            "solve/okdt-p/eps-2.5000e-1"
        );
    }

    #[test]
    fn calibration_range_follows_cluster_energy() {
        // ε: 1, .5, .25, .125, .0625 with % cluster energy 100, 97, 80, 45, 20.
        let probes = [
            (1.0, 100.0, 0.1),
            (0.5, 97.0, 0.1),
            (0.25, 80.0, 0.2),
            (0.125, 45.0, 0.4),
            (0.0625, 20.0, 0.9),
        ];
        assert_eq!(pick_range(&probes), (0.5, 0.125));
        // Never below 30%: the last probe becomes eps_hi and the range spans 8×.
        let probes = [(1.0, 100.0, 0.1), (0.5, 99.0, 0.1)];
        assert_eq!(pick_range(&probes), (0.5, 0.0625));
        // An abrupt drop (the copper beech under a sun: 99.9% at 0.25, 20% at 0.125): the sweep
        // runs from the last probe above 95% to the first below 30%, across the band.
        let probes = [
            (1.0, 99.9, 6.8),
            (0.5, 99.9, 8.2),
            (0.25, 99.9, 9.6),
            (0.125, 20.2, 38.3),
        ];
        assert_eq!(pick_range(&probes), (0.25, 0.125));
        // Never above 95%: the sweep starts at the first probe.
        let probes = [(1.0, 80.0, 0.1), (0.5, 50.0, 0.1), (0.25, 10.0, 0.1)];
        assert_eq!(pick_range(&probes), (1.0, 0.5));
    }
}
