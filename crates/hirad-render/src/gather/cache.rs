//! Irradiance cache of the final gather ([`super::GatherOptions::cache`]): the indirect light
//! of a grid of points, at the corners of `S × S` blocks of pixels, each gathered with the rays
//! of a whole block, then interpolated where the pixels' samples land close to them (after
//! Ward, Rubinstein and Clear 1988). A gather ray's noise is large on smooth walls and the
//! indirect light there varies slowly, so one well-sampled point serves its neighbours; near
//! corners, contacts and silhouettes no point is valid and the sample gathers on its own as
//! before. The points do not count the emission their rays hit: a sample that takes them has
//! its direct light from emitter samples alone, two of them (multiple importance weights hold
//! only at one point; the gather ray it does not cast pays for the second), and the sun.
//!
//! A point's validity radius R is the harmonic mean distance of its gather rays' hits (rays
//! that leave the scene say nothing about it), capped so that no sample farther than [`REACH`]
//! blocks (their world size at the point) is served by it. A sample at `x` of normal `n` takes
//! the corners of its block whose Ward error `|x − p|/R + √(1 − n·nₚ)` is below [`ACCURACY`]
//! and that `x` does not lie behind, with bilinear weights in the image renormalised over the
//! valid corners: exact where the light varies linearly across a block whose corners are all
//! valid, which Ward's inverse-error weights are not.

use super::{shuffle, stratum, Counts, Gatherer};
use crate::camera::CameraFrame;
use glam::{DVec3, Vec3};
use hirad_core::progress::Progress;
use hirad_core::rng::SplitMix64;
use hirad_core::{Error, Result};
use rayon::prelude::*;
use std::sync::atomic::{AtomicBool, Ordering};

/// Largest Ward error of a point used for a sample (pbrt-v2's irradiance cache uses 0.2).
pub(super) const ACCURACY: f32 = 0.2;
/// A point serves no sample farther than the world size of this many blocks at the point.
pub(super) const REACH: f32 = 2.0;
/// Mixed into the seed of the points' generators (the pixels' generators use the seed alone).
const SEED_TAG: u64 = 0x4952_5241_4443_4143;
/// Most gather rays of one point (`rays × S²`): a point's ray strata are held in memory.
pub(super) const MAX_POINT_RAYS: u64 = 1 << 22;

/// One point of the cache: where it lies, its normal, the mean incident radiance of its
/// gather rays (ρ times it is the reflected indirect radiance) and its validity radius.
#[derive(Clone, Copy, Debug)]
pub(super) struct Point {
    p: Vec3,
    n: Vec3,
    l: Vec3,
    r: f32,
}

/// The points of a view at pixel positions `(c·S, r·S)`, in rows of `cols`; `None` where the
/// point sees nothing to shade.
pub(super) struct Cache {
    spacing: u32,
    cols: usize,
    rows: usize,
    points: Vec<Option<Point>>,
}

impl Cache {
    /// Gather the points of a `width × height` view, `rays × spacing²` gather rays each (at
    /// most [`MAX_POINT_RAYS`]), one row of points per progress step.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn build(
        g: &Gatherer,
        frame: &CameraFrame,
        width: u32,
        height: u32,
        spacing: u32,
        progress: &dyn Progress,
        cancel: Option<&AtomicBool>,
        cnt: &mut Counts,
    ) -> Result<Cache> {
        let s = spacing.max(1);
        let m = g.opts.rays as u64 * s as u64 * s as u64;
        if m > MAX_POINT_RAYS {
            return Err(Error::Config(format!(
                "gather cache: {} rays × {s}² = {m} gather rays per point, at most {MAX_POINT_RAYS}",
                g.opts.rays
            )));
        }
        let m = m.max(1) as u32;
        let cols = width.div_ceil(s) as usize + 1;
        let rows = height.div_ceil(s) as usize + 1;
        let stopped = || cancel.is_some_and(|c| c.load(Ordering::Relaxed));
        progress.start("gather cache", rows as u64);
        let out: Vec<Vec<(Option<Point>, Counts)>> = (0..rows)
            .into_par_iter()
            .map(|r| {
                let row = (0..cols)
                    .map(|c| {
                        let mut n = Counts::default();
                        if stopped() {
                            return (None, n);
                        }
                        let (sx, sy) = ((c as u32 * s) as f32, (r as u32 * s) as f32);
                        let seed = g.opts.seed ^ SEED_TAG;
                        let i = (r * cols + c) as u64;
                        (point(g, frame, sx, sy, s, m, seed, i, &mut n), n)
                    })
                    .collect();
                progress.inc(1);
                row
            })
            .collect();
        progress.finish();
        if stopped() {
            return Err(Error::Interrupted);
        }
        let out = out.into_iter().flatten();
        let mut points = Vec::with_capacity(cols * rows);
        for (p, c) in out {
            cnt.add(&c);
            points.push(p);
        }
        Ok(Cache {
            spacing: s,
            cols,
            rows,
            points,
        })
    }

    /// Number of points gathered.
    pub(super) fn len(&self) -> usize {
        self.points.iter().filter(|p| p.is_some()).count()
    }

    /// The incident indirect radiance (as [`Gatherer::incident`]) at `x` of normal `n`, seen
    /// at image position `(sx, sy)` (pixels), from the corners of its block; `None` when none
    /// is valid there.
    pub(super) fn lookup(&self, x: Vec3, n: Vec3, sx: f32, sy: f32) -> Option<Vec3> {
        let s = self.spacing as f32;
        let (fx, fy) = (sx / s, sy / s);
        let c0 = (fx.floor().max(0.0) as usize).min(self.cols - 2);
        let r0 = (fy.floor().max(0.0) as usize).min(self.rows - 2);
        let (tx, ty) = (
            (fx - c0 as f32).clamp(0.0, 1.0),
            (fy - r0 as f32).clamp(0.0, 1.0),
        );
        let (mut sum, mut wsum) = (DVec3::ZERO, 0.0f64);
        for (r, wy) in [(r0, 1.0 - ty), (r0 + 1, ty)] {
            for (c, wx) in [(c0, 1.0 - tx), (c0 + 1, tx)] {
                let w = (wx * wy) as f64;
                let Some(pt) = &self.points[r * self.cols + c] else {
                    continue;
                };
                if w <= 0.0 {
                    continue;
                }
                let d = x - pt.p;
                let dist = d.length();
                // `x` behind the point's surface (beyond a grazing tolerance).
                if d.dot(n + pt.n) < -0.1 * dist {
                    continue;
                }
                let err = dist / pt.r + (1.0 - n.dot(pt.n)).max(0.0).sqrt();
                if err >= ACCURACY {
                    continue;
                }
                sum += pt.l.as_dvec3() * w;
                wsum += w;
            }
        }
        (wsum > 0.0).then(|| (sum / wsum).as_vec3())
    }
}

/// The point at image position `(sx, sy)`, a corner of the blocks around it: `m` stratified
/// samples of [`Gatherer::incident`] at the camera ray's hit.
#[allow(clippy::too_many_arguments)]
fn point(
    g: &Gatherer,
    frame: &CameraFrame,
    sx: f32,
    sy: f32,
    spacing: u32,
    m: u32,
    seed: u64,
    index: u64,
    cnt: &mut Counts,
) -> Option<Point> {
    let scene = g.scene;
    let d = frame.direction(sx, sy).normalize();
    cnt.camera += 1;
    let h = g.closest(frame.eye, d, f32::INFINITY)?;
    let tri = h.tri as usize;
    let ng = scene.normals[tri];
    let front = ng.dot(d) < 0.0;
    let mat = scene.material_of(tri);
    if (!front && !scene.has_back(tri, g.opts.two_sided)) || mat.rho.max_element() <= 0.0 {
        return None;
    }
    let n = if front { ng } else { -ng };
    let p = frame.eye + d * h.t;
    let x = p + n * g.eps;
    let mut rng = SplitMix64::for_item(seed, index);
    let a = ((m as f64).sqrt() as u32).max(1);
    let b = m / a;
    let mut perm_bpick: Vec<u32> = (0..m).collect();
    let mut perm_b: Vec<u32> = (0..m).collect();
    for q in [&mut perm_bpick, &mut perm_b] {
        shuffle(q, &mut rng);
    }
    let (mut sum, mut inv_t, mut hits) = (DVec3::ZERO, 0.0f64, 0u32);
    for k in 0..m {
        let ud = stratum(k, a, b, &mut rng);
        let ub = (
            (perm_bpick[k as usize] as f64 + rng.next_f64()) / m as f64,
            stratum(perm_b[k as usize], a, b, &mut rng),
        );
        let (l, br, t) = g.incident(x, n, ud, ub, 0, false, &mut rng, cnt);
        sum += (l + br).as_dvec3();
        if t.is_finite() && t > 0.0 {
            inv_t += 1.0 / t as f64;
            hits += 1;
        }
    }
    // World size of a pixel at the point, and the validity radius.
    let pixel = 2.0 * frame.tan_half_y * h.t * d.dot(frame.forward) / frame.height as f32;
    let reach = REACH * spacing as f32 * pixel / ACCURACY;
    let harmonic = if inv_t > 0.0 {
        (hits as f64 / inv_t) as f32
    } else {
        f32::INFINITY
    };
    Some(Point {
        p,
        n,
        l: (sum / m as f64).as_vec3(),
        r: harmonic.min(reach).max(1e-12),
    })
}
