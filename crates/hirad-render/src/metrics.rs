//! Image error: linear sRGB → XYZ → CIELUV, RMS ΔE*uv against a reference (`experiments.md` §3).
//!
//! Pixels are linear RGB with sRGB primaries and a D65 white ([`srgb_to_xyz_matrix`]); the
//! white's luminance `Yn` is taken from the reference ([`white_luminance`]); CIELUV as in CIE 15
//! ([`xyz_to_luv`]). [`compare`] gives the RMS, largest and mean ΔE*uv and the relative RMSE
//! ([`ImageError`] has the definitions). All arithmetic is in f64.
//!
//! Because `Yn` comes from the reference, `diff(a, r)` and `diff(r, a)` differ in general; for a
//! fixed white ([`compare_with_white`]) ΔE is symmetric.

use crate::Image;
use glam::{DMat3, DVec3, Vec3};
use hirad_core::{Error, Result};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// CIE XYZ of the D65 white point with Y = 1 (as in `palette`).
pub const D65: DVec3 = DVec3::new(0.95047, 1.0, 1.08883);

/// The linear sRGB → XYZ matrix (Y of white = 1), derived from the sRGB primaries and D65.
///
/// Pixels are linear RGB with sRGB primaries (x,y) = R (0.64, 0.33),
/// G (0.30, 0.60), B (0.15, 0.06) and white D65 with XYZ (0.95047, 1, 1.08883); the RGB → XYZ
/// matrix is derived from those primaries (the same derivation as the `palette` crate).
/// Negative channel values are clamped to 0 before the conversion; non-finite pixels are an
/// error.
pub fn srgb_to_xyz_matrix() -> DMat3 {
    let xyz_of = |x: f64, y: f64| DVec3::new(x / y, 1.0, (1.0 - x - y) / y);
    let m = DMat3::from_cols(xyz_of(0.64, 0.33), xyz_of(0.30, 0.60), xyz_of(0.15, 0.06));
    let s = m.inverse() * D65;
    DMat3::from_cols(m.x_axis * s.x, m.y_axis * s.y, m.z_axis * s.z)
}

/// Linear sRGB → XYZ (white (1,1,1) → D65 with Y = 1).
#[inline]
pub fn linear_srgb_to_xyz(m: &DMat3, rgb: DVec3) -> DVec3 {
    *m * rgb
}

/// CIE lightness L* of a luminance `yr` relative to the white's.
pub fn lightness(yr: f64) -> f64 {
    const EPS: f64 = 216.0 / 24389.0; // (6/29)^3
    const KAPPA: f64 = 24389.0 / 27.0; // (29/3)^3
    if yr > EPS {
        116.0 * yr.cbrt() - 16.0
    } else {
        KAPPA * yr
    }
}

/// XYZ → CIELUV relative to the white `white` (XYZ of the reference white).
///
/// CIE 15: `L* = 116 (Y/Yn)^⅓ − 16` for `Y/Yn > (6/29)³`, else `(29/3)³ Y/Yn`;
/// `u* = 13 L* (u′ − u′n)`, `v* = 13 L* (v′ − v′n)`, `u′ = 4X/(X+15Y+3Z)`,
/// `v′ = 9Y/(X+15Y+3Z)`; black (X+15Y+3Z = 0) is (0, 0, 0).
pub fn xyz_to_luv(xyz: DVec3, white: DVec3) -> DVec3 {
    let den = xyz.x + 15.0 * xyz.y + 3.0 * xyz.z;
    if den <= 0.0 {
        return DVec3::ZERO;
    }
    let wden = white.x + 15.0 * white.y + 3.0 * white.z;
    let (un, vn) = (4.0 * white.x / wden, 9.0 * white.y / wden);
    let (u, v) = (4.0 * xyz.x / den, 9.0 * xyz.y / den);
    let l = lightness(xyz.y / white.y);
    DVec3::new(l, 13.0 * l * (u - un), 13.0 * l * (v - vn))
}

/// Converts linear sRGB pixels to CIELUV for a white of luminance `yn`.
#[derive(Clone, Copy, Debug)]
pub struct LuvConverter {
    m: DMat3,
    white: DVec3,
}

impl LuvConverter {
    /// Converter with the D65 white scaled to luminance `yn` (> 0).
    pub fn new(yn: f64) -> Self {
        Self {
            m: srgb_to_xyz_matrix(),
            white: D65 * yn,
        }
    }

    /// L*u*v* of a linear sRGB value (negative channels clamped to 0).
    #[inline]
    pub fn luv(&self, rgb: Vec3) -> DVec3 {
        xyz_to_luv(self.m * rgb.max(Vec3::ZERO).as_dvec3(), self.white)
    }
}

/// Luminance Y (white = 1) of a linear sRGB value, negative channels clamped to 0.
#[inline]
pub fn luminance(rgb: Vec3) -> f64 {
    let m = srgb_to_xyz_matrix();
    m.row(1).dot(rgb.max(Vec3::ZERO).as_dvec3())
}

/// Nearest-rank percentile `p` (0 < p ≤ 100, integer) of `values`: the `⌈p·N/100⌉`-th smallest.
/// `None` for an empty slice.
pub fn percentile_nearest_rank(values: &[f64], p: u32) -> Option<f64> {
    if values.is_empty() || p == 0 || p > 100 {
        return None;
    }
    let n = values.len();
    let rank = (p as usize * n).div_ceil(100).max(1);
    let mut v = values.to_vec();
    let (_, kth, _) = v.select_nth_unstable_by(rank - 1, |a, b| a.total_cmp(b));
    Some(*kth)
}

/// The white luminance Yn of a reference image.
///
/// The white is D65 scaled so that `Yn` is the 99th percentile of the reference's Y, by the
/// nearest-rank method: with the N values of Y sorted ascending (`v[0] ≤ … ≤ v[N−1]`),
/// `Yn = v[⌈0.99·N⌉ − 1]` (`⌈0.99·N⌉` computed exactly in integers as `(99·N + 99) / 100`).
/// If that is 0 the largest Y is used, and if the reference is entirely black, `Yn = 1`.
/// Pixels brighter than Yn are not clipped (their L* exceeds 100).
pub fn white_luminance(reference: &Image) -> f64 {
    let m = srgb_to_xyz_matrix();
    let row = m.row(1);
    let ys: Vec<f64> = reference
        .pixels
        .par_iter()
        .map(|p| row.dot(p.max(Vec3::ZERO).as_dvec3()))
        .collect();
    let p99 = percentile_nearest_rank(&ys, 99).unwrap_or(0.0);
    if p99 > 0.0 {
        return p99;
    }
    let max = ys.iter().cloned().fold(0.0, f64::max);
    if max > 0.0 {
        max
    } else {
        1.0
    }
}

/// Error of an image against a reference.
///
/// ΔE*uv per pixel: Euclidean distance of (L*, u*, v*). The image error is the RMS over
/// pixels, `√(Σ ΔE² / N)` (the L2 norm of the difference image over √N, independent of the
/// resolution); also the maximum and the mean ΔE.
///
/// Relative RMSE in linear RGB: `√(Σ_pixels Σ_channels (a − r)²) / √(Σ r²)` (0 when both are
/// black, infinite when only the reference is black).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ImageError {
    /// RMS over pixels of ΔE*uv.
    pub rms_delta_e: f64,
    /// Largest per-pixel ΔE*uv.
    pub max_delta_e: f64,
    /// Mean per-pixel ΔE*uv.
    pub mean_delta_e: f64,
    /// Relative RMSE in linear RGB (see [`ImageError`]).
    pub rel_rmse: f64,
    /// Mean luminance of the image over that of the reference (energy agreement).
    #[serde(default)]
    pub mean_luminance_ratio: f64,
    /// White luminance Yn used for CIELUV.
    pub white_y: f64,
    /// Width of the images, pixels.
    pub width: u32,
    /// Height of the images, pixels.
    pub height: u32,
}

/// Per-pixel ΔE*uv of `image` against `reference` with the white of luminance `yn`.
pub fn delta_e_map(image: &Image, reference: &Image, yn: f64) -> Result<Vec<f32>> {
    check_pair(image, reference)?;
    if !(yn > 0.0 && yn.is_finite()) {
        return Err(Error::Config(format!("white luminance {yn} must be > 0")));
    }
    let conv = LuvConverter::new(yn);
    Ok(image
        .pixels
        .par_iter()
        .zip(reference.pixels.par_iter())
        .map(|(&a, &r)| (conv.luv(a) - conv.luv(r)).length() as f32)
        .collect())
}

fn check_pair(image: &Image, reference: &Image) -> Result<()> {
    if image.width != reference.width || image.height != reference.height {
        return Err(Error::Config(format!(
            "image sizes differ: {}x{} vs reference {}x{}",
            image.width, image.height, reference.width, reference.height
        )));
    }
    if image.is_empty() {
        return Err(Error::Config("images have no pixels".into()));
    }
    for (what, img) in [("image", image), ("reference", reference)] {
        if let Some(i) = img.pixels.iter().position(|p| !p.is_finite()) {
            return Err(Error::Config(format!(
                "{what} pixel ({}, {}) is not finite: {}",
                i as u32 % img.width,
                i as u32 / img.width,
                img.pixels[i]
            )));
        }
    }
    Ok(())
}

/// Compare `image` with `reference`, white from the reference (`experiments.md` §3).
pub fn compare(image: &Image, reference: &Image) -> Result<ImageError> {
    check_pair(image, reference)?;
    compare_with_white(image, reference, white_luminance(reference))
}

/// Compare with an explicit white luminance `yn`.
pub fn compare_with_white(image: &Image, reference: &Image, yn: f64) -> Result<ImageError> {
    let de = delta_e_map(image, reference, yn)?;
    // Fixed-size chunks summed in order: the result does not depend on the thread count.
    const CHUNK: usize = 4096;
    let partial: Vec<(f64, f64, f64, f64, f64, f64, f64)> = de
        .par_chunks(CHUNK)
        .zip(image.pixels.par_chunks(CHUNK))
        .zip(reference.pixels.par_chunks(CHUNK))
        .map(|((d, a), r)| {
            let (mut s1, mut s2, mut mx, mut diff2, mut ref2) = (0.0, 0.0, 0.0f64, 0.0, 0.0);
            let (mut ya, mut yr) = (0.0, 0.0);
            for i in 0..d.len() {
                ya += luminance(a[i]);
                yr += luminance(r[i]);
                let e = d[i] as f64;
                s1 += e;
                s2 += e * e;
                mx = mx.max(e);
                diff2 += (a[i].as_dvec3() - r[i].as_dvec3()).length_squared();
                ref2 += r[i].as_dvec3().length_squared();
            }
            (s1, s2, mx, diff2, ref2, ya, yr)
        })
        .collect();
    let (mut s1, mut s2, mut mx, mut diff2, mut ref2) = (0.0, 0.0, 0.0f64, 0.0, 0.0);
    let (mut ya, mut yr) = (0.0, 0.0);
    for p in partial {
        ya += p.5;
        yr += p.6;
        s1 += p.0;
        s2 += p.1;
        mx = mx.max(p.2);
        diff2 += p.3;
        ref2 += p.4;
    }
    let n = de.len() as f64;
    let rel_rmse = if diff2 == 0.0 {
        0.0
    } else if ref2 == 0.0 {
        f64::INFINITY
    } else {
        (diff2 / ref2).sqrt()
    };
    Ok(ImageError {
        rms_delta_e: (s2 / n).sqrt(),
        max_delta_e: mx,
        mean_delta_e: s1 / n,
        rel_rmse,
        mean_luminance_ratio: if yr > 0.0 { ya / yr } else { f64::NAN },
        white_y: yn,
        width: image.width,
        height: image.height,
    })
}

/// Display colours (sRGB-encoded) of the heatmap colour scale at 0, ¼, ½, ¾ and 1 (matplotlib
/// "inferno"), interpolated linearly between stops.
const HEAT_STOPS: [[f32; 3]; 5] = [
    [0.0015, 0.0005, 0.0139],
    [0.3412, 0.0621, 0.4290],
    [0.7353, 0.2163, 0.3300],
    [0.9783, 0.5573, 0.0347],
    [0.9884, 0.9984, 0.6449],
];

/// Heatmap colour of `t` ∈ [0, 1] as a linear RGB value (so that the PNG writer's sRGB encoding
/// shows the scale's display colour).
pub fn heat_color(t: f32) -> Vec3 {
    let t = if t.is_nan() { 0.0 } else { t.clamp(0.0, 1.0) } * 4.0;
    let i = (t as usize).min(3);
    let f = t - i as f32;
    let a = Vec3::from(HEAT_STOPS[i]);
    let b = Vec3::from(HEAT_STOPS[i + 1]);
    let s = a + (b - a) * f;
    Vec3::new(
        crate::image::decode_srgb(s.x),
        crate::image::decode_srgb(s.y),
        crate::image::decode_srgb(s.z),
    )
}

/// False-colour image of a ΔE map: 0 black, `scale_max` and above pale yellow ("inferno").
pub fn heatmap(delta_e: &[f32], width: u32, height: u32, scale_max: f32) -> Result<Image> {
    if delta_e.len() != width as usize * height as usize {
        return Err(Error::Config(format!(
            "heatmap: {} values for {width}x{height} pixels",
            delta_e.len()
        )));
    }
    let k = if scale_max > 0.0 {
        1.0 / scale_max
    } else {
        0.0
    };
    Ok(Image {
        width,
        height,
        pixels: delta_e.par_iter().map(|&e| heat_color(e * k)).collect(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn matrix_maps_white_to_d65() {
        let m = srgb_to_xyz_matrix();
        let w = m * DVec3::ONE;
        assert!((w - D65).abs().max_element() < 1e-12, "{w}");
        // Lindbloom's published sRGB → XYZ matrix (same primaries and white), 7 decimals.
        let want = [
            [0.4124564, 0.3575761, 0.1804375],
            [0.2126729, 0.7151522, 0.0721750],
            [0.0193339, 0.1191920, 0.9503041],
        ];
        for (r, row) in want.iter().enumerate() {
            for (c, &v) in row.iter().enumerate() {
                assert!(
                    (m.row(r)[c] - v).abs() < 1e-6,
                    "({r}, {c}): {}",
                    m.row(r)[c]
                );
            }
        }
    }

    #[test]
    fn nearest_rank() {
        let v: Vec<f64> = (1..=100).map(|i| i as f64).collect();
        assert_eq!(percentile_nearest_rank(&v, 99), Some(99.0));
        assert_eq!(percentile_nearest_rank(&v, 100), Some(100.0));
        assert_eq!(percentile_nearest_rank(&v[..10], 99), Some(10.0));
        assert_eq!(percentile_nearest_rank(&v[..1], 99), Some(1.0));
        // 201 values: rank ⌈198.99⌉ = 199.
        let v: Vec<f64> = (0..201).rev().map(|i| i as f64).collect();
        assert_eq!(percentile_nearest_rank(&v, 99), Some(198.0));
        assert_eq!(percentile_nearest_rank(&[], 99), None);
    }

    #[test]
    fn heat_scale_ends() {
        let a = heat_color(0.0);
        let b = heat_color(1.0);
        assert!(a.max_element() < 0.01);
        assert!(b.min_element() > 0.3);
        assert_eq!(heat_color(2.0), b);
        assert_eq!(heat_color(f32::NAN), a);
    }
}
