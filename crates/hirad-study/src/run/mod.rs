//! The study driver (`experiments.md` §1–6): plans the units of work of a study, runs the ones
//! that are not on disk yet, and writes tables, plots and the report.
//!
//! Units of work and their keys in the [`Store`] ([`Job::key`]): `clusters/<strategy>` (§1),
//! `raybench/<strategy>` (§2), `reference/<viewpoint>` (§3), `noise/<viewpoint>` (the
//! references' own noise: a second reference of another seed against the first),
//! `solve/<strategy>/<eps>` (§4) and `volume/<strategy>` (§5). Every unit is written atomically when it completes, so a study that
//! is stopped and started again skips finished units. [`plan()`] lists the units so that
//! `hirad study --jobs` can print one command per unit; [`merge()`] merges output directories;
//! [`slurm`] runs the units as a Slurm job array.
//!
//! Files: `config` ([`StudyConfig`], viewpoints), `plan` (units and their keys), `calibrate`
//! (the ε range of the sweep), `units` (computing each unit), `outputs` (tables, plots, report),
//! `merge` and `slurm`.

mod calibrate;
mod config;
mod merge;
mod outputs;
mod plan;
pub mod slurm;
mod units;

pub use calibrate::{pick_range, Calibration};
pub use config::{viewpoints, StudyConfig};
pub use merge::merge;
pub use outputs::{collect, write_outputs};
pub use plan::{eps_key, plan, Job};
pub use units::auto_exposure;

use super::records::{RunMeta, RunRecord};
use super::store::Store;
use hirad_accel::cluster::{ClusterTree, Prims, Strategy};
use hirad_core::progress::Progress;
use hirad_core::{Error, Result};
use hirad_render::CameraView;
use hirad_scene::{Scene, SceneOptions};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

/// A study in progress: the scene, its prepared inputs and the store.
pub struct Study<'a> {
    /// What the study is asked to do.
    pub cfg: StudyConfig,
    /// The scene.
    pub scene: Scene,
    /// The scene's primitives, input of the cluster trees.
    pub prims: Prims,
    /// Viewpoints (name, view) at the study's image size.
    pub views: Vec<(String, CameraView)>,
    /// The records on disk.
    pub store: Store,
    /// Metadata of this process, copied into every record.
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
/// time, so none of them belongs to a live writer; the Slurm tasks' own directories
/// (`slurm/`) are left alone, as they may be running.
pub fn remove_stale_temp(dir: &std::path::Path) -> Result<usize> {
    let mut n = 0;
    for p in super::store::walk_files(dir, &["slurm"]) {
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
}
