//! The units of work of a study ([`Job`]), their keys in the store, and their order.

use super::config::{viewpoints, StudyConfig};
use hirad_accel::cluster::Strategy;
use hirad_core::Result;
use hirad_scene::Scene;

/// One unit of work.
#[derive(Clone, Debug, PartialEq)]
pub enum Job {
    /// Cluster statistics and build time of a strategy (§1).
    Clusters(Strategy),
    /// The ray-casting test of a strategy (§2).
    Raybench(Strategy),
    /// The reference image of a viewpoint (§3).
    Reference(String),
    /// The references' own noise at a viewpoint: a second reference of another seed against
    /// the first.
    Noise(String),
    /// One solve of the sweep: strategy and relative ε (§4).
    Solve(Strategy, f64),
    /// Volumetric against exact visibility for a strategy (§5).
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
            Job::Noise(v) => format!("noise/{v}"),
            Job::Solve(s, e) => format!("solve/{s}/{}", eps_key(*e)),
            Job::Volume(s) => format!("volume/{s}"),
        }
    }
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
        let views = viewpoints(scene, cfg)?;
        for (name, _) in &views {
            jobs.push(Job::Reference(name.clone()));
        }
        if cfg.reference_noise {
            for (name, _) in views {
                jobs.push(Job::Noise(name));
            }
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

#[cfg(test)]
mod tests {
    use super::*;

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
}
