//! Computing one unit of work: cluster statistics, the ray-casting test, a reference image, a
//! solve of the sweep with its images and errors, the volumetric-visibility experiment.

use super::plan::{eps_key, Job};
use super::Study;
use crate::records::{ClusterRecord, NoiseRecord, RayRecord, ReferenceRecord, SolveRecord};
use crate::report::VolumeRow;
use hirad_accel::cluster::{stats::ClusterStats, ClusterTree, Strategy};
use hirad_accel::ray::{sample::sample_segments, turns, RayCaster};
use hirad_core::{Error, Result};
use hirad_radiosity::{self as radiosity, SolverConfig, VisibilityMode};
use hirad_render::{self as render, CameraView, Image, RasterOptions};
use std::path::PathBuf;
use std::time::Instant;

/// Timed passes of a ray-casting unit over its segments (as `raybench`'s default).
const RAY_PASSES: usize = 3;

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

impl Study<'_> {
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
            Job::Noise(v) => {
                let r = self.noise(v)?;
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
        // `sah` is timed beside the strategy, in turns, as the baseline of its rate.
        let sah_tree = (s != Strategy::Sah).then(|| self.tree(Strategy::Sah));
        let sah = sah_tree
            .as_ref()
            .map(|t| RayCaster::with_boxes(&self.scene, t, self.cfg.ray_boxes));
        let list: Vec<&dyn turns::TurnCaster> = std::iter::once(&caster)
            .chain(sah.as_ref())
            .map(|c| c as &dyn turns::TurnCaster)
            .collect();
        let times = turns::time_in_turns(&list, &segs, RAY_PASSES, false, || ());
        let occluded = times.batch_occluded[0];
        // As `raybench`: single queries and the batch must agree; a strategy that disagrees
        // with `sah` is reported, not fatal (the spec expects equal counts).
        if times.single_occluded != times.batch_occluded {
            return Err(Error::Config(format!(
                "{s}: single-ray occluded counts {:?} differ from the batch's {:?}",
                times.single_occluded, times.batch_occluded
            )));
        }
        if let Some(&o) = times.batch_occluded.get(1).filter(|&&o| o != occluded) {
            tracing::warn!("{s}: {occluded} segments occluded, sah {o}");
        }
        let rate = |secs: f64| (RAY_PASSES * segs.len()) as f64 / (secs * 1e6).max(1e-12);
        let query_ms = times.batch_s[0] * 1e3 / RAY_PASSES as f64;
        let (_, stats) = caster.occluded_batch_stats(&segs);
        Ok(RayRecord {
            meta: self.meta.clone(),
            strategy: s,
            pairs: segs.len(),
            seed: self.cfg.seed,
            boxes: self.cfg.ray_boxes,
            build_ms,
            query_ms,
            mrays_per_s: rate(times.batch_s[0]),
            sah_mrays_per_s: Some(rate(*times.batch_s.last().expect("one caster at least"))),
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

    /// Path-traced image of viewpoint `name` with the study's samples per pixel and `seed`,
    /// and its render time in seconds.
    fn path_trace(&self, name: &str, seed: u64) -> Result<(Image, f64)> {
        let view = self.view(name)?;
        let tree = self.tree(Strategy::Sah);
        let caster = RayCaster::new(&self.scene, &tree);
        let t = Instant::now();
        let opts = render::pathtrace::ReferenceOptions {
            spp: self.cfg.reference_spp,
            seed,
            two_sided: self.cfg.solver.two_sided,
            ..Default::default()
        };
        let (img, _) =
            render::pathtrace::render_reference(&self.scene, &caster, view, &opts, self.progress)?;
        Ok((img, t.elapsed().as_secs_f64()))
    }

    /// The reference of viewpoint `name`, made first if a unit run alone (`--jobs`,
    /// `--only`) needs it; the path tracer is deterministic, so every machine makes the same.
    fn reference_image(&self, name: &str) -> Result<Image> {
        let job = Job::Reference(name.to_string());
        if !self.store.has(&job.key()) {
            self.run_job(&job)?;
        }
        Image::read(&self.reference_path(name))
    }

    fn reference(&self, name: &str) -> Result<ReferenceRecord> {
        let (img, seconds) = self.path_trace(name, self.cfg.seed)?;
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

    fn noise(&self, name: &str) -> Result<NoiseRecord> {
        let seed = self.cfg.seed.wrapping_add(1);
        let (img, seconds) = self.path_trace(name, seed)?;
        let reference = self.reference_image(name)?;
        let delta_e = hirad_render::metrics::compare(&img, &reference)?.rms_delta_e;
        let rel = format!("noise/{name}.png");
        img.write_png(&self.cfg.out.join(&rel), auto_exposure(&img))?;
        Ok(NoiseRecord {
            meta: self.meta.clone(),
            viewpoint: name.to_string(),
            seed,
            delta_e,
            seconds,
            image: rel,
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
    pub(super) fn solve_with(
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
            let reference = self.reference_image(name)?;
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
}
