//! Adaptive sampling of the final gather: after every pixel's N samples, extra samples go where
//! a pixel's perceptual error is largest (emitter outlines, silhouettes, shadow edges), in
//! proportion to the spread of its samples' lightness L*. That is Neyman's allocation: for a
//! given number of samples, `n_p ∝ σ_p` minimises the sum of the pixels' squared errors
//! `σ_p² / n_p`, which is what RMS ΔE*uv measures (chromaticity is left out).
//!
//! A pixel's spread is judged from its eight neighbours' samples, never its own: the number of
//! extra samples a pixel takes does not depend on its first samples, so the weighted mean of
//! the two independent estimates stays unbiased. Edges are a pixel wide or more, so the
//! neighbours see them too.

use crate::metrics::lightness;

/// Seed tag of the extra samples' generators (the first pass uses the seed itself).
pub(super) const SEED_TAG: u64 = 0x4144_4150_5449_5645;

/// Mean luminance of a pixel's samples and their spread (standard deviation of one sample).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(super) struct Spread {
    pub(super) mean: f32,
    pub(super) std: f32,
}

/// Extra samples per pixel of a `width × height` image whose `n` first samples per pixel had
/// the luminance `spread` (row-major), about `extra × n` per pixel on average: pixel `p` takes
/// `⌊max(0, λ·s_p − n)⌋`, where `s_p` is the largest lightness spread of its neighbours
/// (`L*(Y + σ) − L*(Y)` with the white's luminance `white`) and `λ` makes the total at most
/// `extra × n × width × height`.
pub(super) fn allocate(
    width: usize,
    height: usize,
    n: u32,
    extra: f64,
    spread: &[Spread],
    white: f64,
) -> Vec<u32> {
    assert_eq!(spread.len(), width * height);
    let budget = extra * n as f64 * spread.len() as f64;
    if !(budget >= 1.0 && white > 0.0) {
        return vec![0; spread.len()];
    }
    let judged = judged(width, height, spread, white);
    let n = n as f64;
    let top = judged.iter().cloned().fold(0.0f64, f64::max);
    if top <= 0.0 {
        return vec![0; spread.len()]; // no spread anywhere: nothing to add
    }
    let total = |lambda: f64| -> f64 { judged.iter().map(|&s| (lambda * s - n).max(0.0)).sum() };
    // Bisect λ in [0, hi]: `total` is continuous and non-decreasing in λ, and at `hi` the
    // widest-spread pixel alone takes the whole budget.
    let (mut lo, mut hi) = (0.0f64, (n + budget) / top);
    for _ in 0..64 {
        let mid = 0.5 * (lo + hi);
        if total(mid) <= budget {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    judged
        .iter()
        .map(|&s| (lo * s - n).max(0.0).floor() as u32)
        .collect()
}

/// The lightness spread `L*(Y + σ) − L*(Y)` each pixel is judged by: the largest of its
/// neighbours' (not its own).
fn judged(width: usize, height: usize, spread: &[Spread], white: f64) -> Vec<f64> {
    let own: Vec<f64> = spread
        .iter()
        .map(|s| {
            let y = s.mean.max(0.0) as f64 / white;
            let d = lightness(y + s.std.max(0.0) as f64 / white) - lightness(y);
            if d.is_finite() {
                d
            } else {
                0.0 // a sample that is not a number says nothing of the pixel's spread
            }
        })
        .collect();
    let mut out = vec![0.0f64; spread.len()];
    for y in 0..height {
        for x in 0..width {
            let mut m = 0.0f64;
            for yy in y.saturating_sub(1)..(y + 2).min(height) {
                for xx in x.saturating_sub(1)..(x + 2).min(width) {
                    if (xx, yy) != (x, y) {
                        m = m.max(own[yy * width + xx]);
                    }
                }
            }
            out[y * width + x] = m;
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn flat(width: usize, height: usize) -> Vec<Spread> {
        vec![
            Spread {
                mean: 0.2,
                std: 0.01
            };
            width * height
        ]
    }

    #[test]
    fn extra_samples_follow_the_neighbours_spread_within_the_budget() {
        let (w, h, n) = (12, 9, 16);
        let mut s = flat(w, h);
        // An edge down column 5: its samples spread widely.
        for y in 0..h {
            s[y * w + 5].std = 0.5;
        }
        let m = allocate(w, h, n, 0.5, &s, 1.0);
        let sum: u64 = m.iter().map(|&k| k as u64).sum();
        let budget = (0.5 * n as f64 * (w * h) as f64) as u64;
        assert!(
            sum <= budget && sum + (w * h) as u64 >= budget,
            "{sum} of {budget}"
        );
        for y in 0..h {
            for x in 0..w {
                let k = m[y * w + x];
                // Columns 4 and 6 see the edge beside them, column 5 only along it.
                if (4..=6).contains(&x) {
                    assert!(k > 0, "({x}, {y})");
                } else {
                    assert_eq!(k, 0, "({x}, {y})");
                }
            }
        }
    }

    #[test]
    fn a_pixel_s_own_samples_do_not_decide_its_share() {
        let (w, h) = (7, 5);
        let mut base = flat(w, h);
        base[2 * w + 3].std = 0.3;
        base[w + 1].std = 0.2;
        let a = judged(w, h, &base, 1.0);
        for p in 0..w * h {
            let mut s = base.clone();
            s[p].std *= 3.0;
            s[p].mean *= 0.5;
            assert_eq!(judged(w, h, &s, 1.0)[p], a[p], "pixel {p}");
        }
        assert!(a[2 * w + 3] < a[2 * w + 2], "judged by the neighbours");
        // No budget or no spread: nothing to add.
        assert!(allocate(w, h, 8, 0.0, &base, 1.0).iter().all(|&k| k == 0));
        let zero = vec![Spread::default(); w * h];
        assert!(allocate(w, h, 8, 1.0, &zero, 1.0).iter().all(|&k| k == 0));
        // A pixel whose samples are not numbers neither takes nor blocks the others' share.
        let mut odd = base.clone();
        odd[0].std = f32::INFINITY;
        odd[w + 4].mean = f32::NAN;
        let b = allocate(w, h, 8, 1.0, &odd, 1.0);
        let sum: usize = b.iter().map(|&k| k as usize).sum();
        assert!(sum <= 8 * w * h && sum + w * h >= 8 * w * h, "{b:?}");
        assert!(b[2 * w + 2] > b[1], "{b:?}");
    }
}
