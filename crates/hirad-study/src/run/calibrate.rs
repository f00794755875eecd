//! The ε range of the sweep: probe solves at halving ε until less than 30% of the energy goes
//! through cluster links (the paper's range is 30–100%), then [`pick_range`].

use super::{Study, StudyConfig};
use hirad_accel::cluster::Strategy;
use hirad_core::Result;
use hirad_radiosity::SolverConfig;
use serde::{Deserialize, Serialize};

/// Result of the ε calibration.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Calibration {
    /// Strategy of the probe solves.
    pub strategy: Strategy,
    /// Probes: (relative ε, % cluster energy, solve seconds).
    pub probes: Vec<(f64, f64, f64)>,
    /// Largest relative ε of the sweep.
    pub eps_hi: f64,
    /// Smallest relative ε of the sweep.
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

impl Study<'_> {
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
}

#[cfg(test)]
mod tests {
    use super::*;

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
