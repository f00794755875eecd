//! What a study is asked to do ([`StudyConfig`]) and the viewpoints it renders.
//!
//! The ε sweep: `tolerances` values of the solver's relative threshold `eps_rel`, a geometric
//! series from `eps_hi` down to `eps_lo`, calibrated by default (see `calibrate`); the absolute
//! ε of each solve and the share of energy gathered through cluster links are recorded so the
//! series can be checked against the paper's 30–100% range.

use hirad_accel::cluster::{ClusterConfig, Strategy};
use hirad_accel::ray::Boxes;
use hirad_core::{Error, Result};
use hirad_radiosity::{self as radiosity, SolverConfig};
use hirad_render::{CameraOverrides, CameraView};
use hirad_scene::Scene;
use serde::{Deserialize, Serialize};
use std::path::PathBuf;

/// Everything a study needs; serde-able so a study directory records how it was made.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(default)]
pub struct StudyConfig {
    /// Scene path or built-in name.
    pub scene: String,
    /// Clustering strategies compared.
    pub strategies: Vec<Strategy>,
    /// Settings of the cluster trees.
    pub cluster: ClusterConfig,
    /// Base solver configuration (refinement oracle, visibility, two-sided, ...).
    pub solver: SolverConfig,
    /// Number of ε values of the sweep (0: no sweep).
    pub tolerances: usize,
    /// Explicit `eps_rel` values (override `tolerances`).
    pub eps_list: Vec<f64>,
    /// Largest relative ε of the series (when not calibrated).
    pub eps_hi: f64,
    /// Smallest relative ε of the series (when not calibrated).
    pub eps_lo: f64,
    /// Choose `eps_hi`/`eps_lo` by probe solves so that 30–100% of the gathered energy goes
    /// through cluster links (the paper's range); see [`Study::calibrate`](super::Study::calibrate).
    pub eps_auto: bool,
    /// Viewpoints by camera name (empty: every camera of the scene).
    pub viewpoints: Vec<String>,
    /// Image size of the study's renders.
    pub size: (u32, u32),
    /// Supersampling of the rasterised images (N×N samples per pixel).
    pub supersample: u32,
    /// Path-tracer samples per pixel of the references.
    pub reference_spp: u32,
    /// Also render each reference again with another seed, to measure the references' own
    /// noise (the scale of error differences the study can resolve).
    pub reference_noise: bool,
    /// Ray-casting test pairs and seed.
    pub ray_pairs: usize,
    /// Boxes the ray-casting test traverses (`cluster`: the strategies' own, as in the paper).
    pub ray_boxes: Boxes,
    /// Seed of the ray-casting test and of the references.
    pub seed: u64,
    /// Timed builds per strategy (median reported).
    pub build_repeats: usize,
    /// Run the volumetric-visibility experiment (§5).
    pub volume: bool,
    /// Output directory.
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
            reference_noise: true,
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

    pub(super) fn selected(&self, key: &str) -> bool {
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
