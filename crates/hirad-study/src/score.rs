//! Monotonicity scores of a time–error or error–tolerance curve (`experiments.md` §4).
//!
//! A curve is a list of `(ε, error)` points. The paper calls a curve *monotone* when the error
//! goes down as the tolerance ε goes down. Two scores:
//! - [`rises`]: with the points sorted by decreasing ε, the number of consecutive steps where
//!   the error goes up (0 for a perfectly monotone curve);
//! - [`kendall_tau`]: Kendall's τ-b rank correlation between ε and error (+1 when the error
//!   always decreases with ε, −1 when it always increases, ties handled by the τ-b correction).
//!
//! A rise can be smaller than anything the error can resolve (two solves that differ in a few
//! links); [`Monotonicity::max_rise`] and [`rises_above`] give its size, to be set against the
//! references' own noise (the study's `noise/<viewpoint>` units).

use serde::{Deserialize, Serialize};

/// Both scores of one curve.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Monotonicity {
    /// Steps (ε decreasing) where the error rises.
    pub rises: usize,
    /// Steps in all (points − 1).
    pub steps: usize,
    /// Largest rise of the error over one step (0 when it never rises).
    #[serde(default)]
    pub max_rise: f64,
    /// Kendall's τ-b between ε and error; `None` with fewer than two distinct values.
    pub kendall_tau: Option<f64>,
}

impl Monotonicity {
    /// Score a curve of `(eps, error)` points (any order).
    pub fn of(points: &[(f64, f64)]) -> Monotonicity {
        Monotonicity {
            rises: rises(points),
            max_rise: steps_by_eps(points).fold(0.0, f64::max),
            steps: points.len().saturating_sub(1),
            kendall_tau: kendall_tau(points),
        }
    }
}

/// Change of the error over each step, with the points sorted by decreasing ε (positive: a
/// rise).
fn steps_by_eps(points: &[(f64, f64)]) -> impl Iterator<Item = f64> {
    let mut p: Vec<(f64, f64)> = points.to_vec();
    p.sort_by(|a, b| b.0.total_cmp(&a.0));
    (1..p.len()).map(move |i| p[i].1 - p[i - 1].1)
}

/// Number of steps, with points sorted by decreasing ε, where the error goes up.
pub fn rises(points: &[(f64, f64)]) -> usize {
    rises_above(points, 0.0)
}

/// Number of steps, with points sorted by decreasing ε, where the error goes up by more than
/// `tol`.
pub fn rises_above(points: &[(f64, f64)], tol: f64) -> usize {
    steps_by_eps(points).filter(|&d| d > tol).count()
}

/// Kendall's τ-b between the two coordinates (O(n²), curves have tens of points).
pub fn kendall_tau(points: &[(f64, f64)]) -> Option<f64> {
    let n = points.len();
    let (mut conc, mut disc, mut tie_x, mut tie_y) = (0i64, 0i64, 0i64, 0i64);
    for i in 0..n {
        for j in i + 1..n {
            let dx = points[i].0 - points[j].0;
            let dy = points[i].1 - points[j].1;
            if dx == 0.0 && dy == 0.0 {
                continue;
            } else if dx == 0.0 {
                tie_x += 1;
            } else if dy == 0.0 {
                tie_y += 1;
            } else if (dx > 0.0) == (dy > 0.0) {
                conc += 1;
            } else {
                disc += 1;
            }
        }
    }
    let nx = (conc + disc + tie_y) as f64; // pairs not tied in x
    let ny = (conc + disc + tie_x) as f64; // pairs not tied in y
    if nx == 0.0 || ny == 0.0 {
        return None;
    }
    Some((conc - disc) as f64 / (nx * ny).sqrt())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn monotone_curve_scores_perfect() {
        let pts: Vec<(f64, f64)> = (0..10)
            .map(|i| (2f64.powi(-i), 1.0 / (i + 1) as f64))
            .collect();
        let m = Monotonicity::of(&pts);
        assert_eq!(m.rises, 0);
        assert_eq!(m.steps, 9);
        assert!((m.kendall_tau.unwrap() - 1.0).abs() < 1e-12);
    }

    #[test]
    fn reversed_curve_scores_minus_one() {
        let pts: Vec<(f64, f64)> = (0..6).map(|i| (i as f64, -(i as f64))).collect();
        let m = Monotonicity::of(&pts);
        assert_eq!(m.rises, 5);
        assert!((m.kendall_tau.unwrap() + 1.0).abs() < 1e-12);
    }

    #[test]
    fn hand_computed_tau() {
        // x: 1 2 3 4, y: 1 3 2 4 → 5 concordant, 1 discordant pair: τ = 4/6.
        let pts = [(1.0, 1.0), (2.0, 3.0), (3.0, 2.0), (4.0, 4.0)];
        assert!((kendall_tau(&pts).unwrap() - 4.0 / 6.0).abs() < 1e-12);
        // Sorted by decreasing ε the errors are 4, 2, 3, 1: one rise (2 → 3).
        assert_eq!(rises(&pts), 1);
        let m = Monotonicity::of(&pts);
        assert!((m.max_rise - 1.0).abs() < 1e-12);
        assert_eq!(rises_above(&pts, 0.5), 1);
        assert_eq!(rises_above(&pts, 1.0), 0);
    }

    #[test]
    fn rise_sizes() {
        // Sorted by decreasing ε: 10, 10.25, 6, 7.5, 7.5 → rises of 0.25 and 1.5.
        let pts = [
            (0.5, 7.5),
            (1.0, 10.0),
            (0.25, 7.5),
            (0.75, 10.25),
            (0.4, 6.0),
        ];
        let m = Monotonicity::of(&pts);
        assert_eq!(m.rises, 2);
        assert!((m.max_rise - 1.5).abs() < 1e-12);
        assert_eq!(rises_above(&pts, 0.2), 2);
        assert_eq!(rises_above(&pts, 0.3), 1);
        assert_eq!(rises_above(&pts, 1.5), 0);
        // A monotone curve rises by nothing.
        assert_eq!(Monotonicity::of(&[(1.0, 2.0), (0.5, 1.0)]).max_rise, 0.0);
    }

    #[test]
    fn ties_use_tau_b() {
        // x: 1 2 3, y: 1 1 2 → concordant 2, discordant 0, tie_y 1:
        // τ_b = 2 / sqrt(3 · 2).
        let pts = [(1.0, 1.0), (2.0, 1.0), (3.0, 2.0)];
        assert!((kendall_tau(&pts).unwrap() - 2.0 / 6f64.sqrt()).abs() < 1e-12);
        assert_eq!(kendall_tau(&[(1.0, 1.0)]), None);
        assert_eq!(kendall_tau(&[(1.0, 1.0), (1.0, 2.0)]), None);
    }
}
