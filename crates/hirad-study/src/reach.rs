//! Time to an error: how long each strategy's sweep takes to reach a given RMS ΔE*uv, the
//! comparison of a time–error plot read at fixed errors (`experiments.md` §4).
//!
//! A sweep is a list of `(solve seconds, error)` points. [`time_to`] walks it in order of solve
//! time and interpolates in log time between the two solves around the error, so that a
//! strategy is not charged a whole ε step for an error it reaches part way. [`levels`] picks the
//! errors to read at from the sweeps themselves: from the lowest error any sweep starts at down
//! to the lowest error any sweep reaches, so that every level is reached by some strategy and a
//! strategy that never gets there shows as such.

/// Seconds a sweep needs to reach error `e`: the points in order of solve time, the first at or
/// below `e`, its time interpolated in log time from the point before it (the first point's
/// time when it is already there); `None` when no point reaches `e`.
pub fn time_to(points: &[(f64, f64)], e: f64) -> Option<f64> {
    let mut p: Vec<(f64, f64)> = points
        .iter()
        .copied()
        .filter(|(t, err)| t.is_finite() && *t > 0.0 && err.is_finite())
        .collect();
    p.sort_by(|a, b| a.0.total_cmp(&b.0));
    let i = p.iter().position(|&(_, err)| err <= e)?;
    if i == 0 || p[i].1 == e {
        return Some(p[i].0);
    }
    let ((t0, e0), (t1, e1)) = (p[i - 1], p[i]);
    let f = (e0 - e) / (e0 - e1);
    Some((t0.ln() + f * (t1.ln() - t0.ln())).exp())
}

/// `n` error levels spaced geometrically from the lowest first error of the sweeps (the error
/// of each sweep's quickest solve) down to the lowest error any sweep reaches; one level when
/// those meet, none without points.
pub fn levels<'a>(sweeps: impl IntoIterator<Item = &'a [(f64, f64)]>, n: usize) -> Vec<f64> {
    let (mut hi, mut lo) = (f64::INFINITY, f64::INFINITY);
    for s in sweeps {
        let first = s
            .iter()
            .filter(|(t, e)| t.is_finite() && e.is_finite())
            .min_by(|a, b| a.0.total_cmp(&b.0));
        if let Some(&(_, e)) = first {
            hi = hi.min(e);
        }
        for &(_, e) in s.iter().filter(|(_, e)| e.is_finite()) {
            lo = lo.min(e);
        }
    }
    if !lo.is_finite() || n == 0 {
        return Vec::new();
    }
    if hi <= lo || n == 1 || lo <= 0.0 {
        return vec![lo];
    }
    // The ends exactly (not through exp and ln), so that the lowest is reached.
    (0..n)
        .map(|k| match k {
            0 => hi,
            k if k == n - 1 => lo,
            k => (hi.ln() + k as f64 / (n - 1) as f64 * (lo.ln() - hi.ln())).exp(),
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn time_interpolates_in_log_time_between_the_solves_around_the_error() {
        let s = [(1.0, 8.0), (4.0, 4.0), (16.0, 2.0)];
        // Already there at the first solve.
        assert_eq!(time_to(&s, 9.0), Some(1.0));
        assert_eq!(time_to(&s, 8.0), Some(1.0));
        // Half way from 8 to 4 in error: half way from 1 to 4 in log time, 2 s.
        assert!((time_to(&s, 6.0).unwrap() - 2.0).abs() < 1e-12);
        assert_eq!(time_to(&s, 2.0), Some(16.0));
        assert_eq!(time_to(&s, 1.9), None);
        // Order of the points does not matter; a rise is crossed at its first reach.
        let r = [(16.0, 2.0), (1.0, 8.0), (8.0, 5.0), (4.0, 3.0)];
        // 5 is first reached at (4 s, 3): 3/5 of the way from (1 s, 8) in error.
        assert!((time_to(&r, 5.0).unwrap() - 4.0f64.powf(0.6)).abs() < 1e-9);
        assert_eq!(time_to(&[], 1.0), None);
    }

    #[test]
    fn levels_span_the_lowest_start_to_the_lowest_end() {
        let a: &[(f64, f64)] = &[(1.0, 16.0), (2.0, 8.0)];
        let b: &[(f64, f64)] = &[(0.5, 4.0), (3.0, 1.0)];
        let l = levels([a, b], 3);
        assert_eq!(l.len(), 3);
        assert!((l[0] - 4.0).abs() < 1e-12 && (l[1] - 2.0).abs() < 1e-12);
        assert_eq!(l[2], 1.0);
        // The lowest level is reached, whatever the rounding of the spacing.
        let d: &[(f64, f64)] = &[(1.0, 7.37), (2.0, 2.9181)];
        assert!(levels([d], 4).iter().all(|&e| time_to(d, e).is_some()));
        // Every level is reached by some sweep.
        assert!(l.iter().all(|&e| time_to(a, e).or(time_to(b, e)).is_some()));
        // A sweep that starts below where another ends: one level, the lowest error.
        let c: &[(f64, f64)] = &[(1.0, 0.5)];
        assert_eq!(levels([a, c], 4), vec![0.5]);
        assert!(levels(std::iter::empty::<&[(f64, f64)]>(), 3).is_empty());
    }
}
