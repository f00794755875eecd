//! Direct sun and sky light, computed once per surface element when it is created and added
//! to the irradiance of the leaves in push-pull.
//!
//! The sun's direct irradiance on a surface element is `E_sun·max(0, n·s)` times the fraction
//! of `shadow_rays` jittered points from which a ray towards the sun escapes; the sky (uniform
//! radiance `L_sky` over the directions above the horizon of the up axis) is gathered as
//! ambient occlusion: `π·L_sky` times the fraction of `sky_rays` cosine-weighted directions
//! that are above the horizon and escape.

use super::Solver;
use crate::element::Kind;
use crate::formfactor::sample_triangle_inset;
use glam::DVec3;
use hirad_core::rng::SplitMix64;
use rayon::prelude::*;

impl Solver<'_> {
    /// Direct sun and sky irradiance of surface elements `lo..hi`.
    pub(super) fn compute_direct(&mut self, lo: u32, hi: u32) {
        let scene = self.scene;
        let vis = self.vis;
        let el = &self.el;
        let n_sun = self.cfg.shadow_rays as usize;
        let n_sky = self.cfg.sky_rays as usize;
        let seed = self.cfg.seed ^ 0x5u64.wrapping_mul(0x9E37_79B9);
        let up = scene.up.vector();
        let margin = vis.margin();
        let covers = &self.covers;
        let vals: Vec<(DVec3, u64)> = (lo..hi)
            .into_par_iter()
            .map(|id| {
                let e = &el.elems[id as usize];
                if e.kind != Kind::Surface || el.is_dead(id) {
                    return (DVec3::ZERO, 0);
                }
                let mut rng = SplitMix64::for_item(seed, id as u64);
                let mut h = DVec3::ZERO;
                let mut rays = 0u64;
                let n = e.normal;
                if let Some(sun) = scene.sun {
                    let c = n.dot(sun.direction);
                    if c > 0.0 {
                        let mut pts = Vec::new();
                        crate::formfactor::stratified_2d(n_sun, &mut rng, &mut pts);
                        let (mut open, mut n_open) = (0.0, 0usize);
                        for p in &pts {
                            let x = sample_triangle_inset(&e.verts, p[0], p[1], margin);
                            // Irradiance is the mean over the element's open points.
                            if covers.covered(e.tri, e.normal, x) {
                                continue;
                            }
                            n_open += 1;
                            rays += 1;
                            open += vis.open_to_infinity(x, sun.direction, e.tri);
                        }
                        h += sun.irradiance.as_dvec3() * (c as f64 * open / n_open.max(1) as f64);
                    }
                }
                if let Some(sky) = scene.sky {
                    let mut dirs = Vec::new();
                    crate::formfactor::stratified_2d(n_sky, &mut rng, &mut dirs);
                    let mut pts = Vec::new();
                    crate::formfactor::stratified_2d(n_sky, &mut rng, &mut pts);
                    let (t, b) = n.any_orthonormal_pair();
                    let (mut open, mut n_open) = (0.0, 0usize);
                    for (d, p) in dirs.iter().zip(&pts) {
                        let x = sample_triangle_inset(&e.verts, p[0], p[1], margin);
                        if covers.covered(e.tri, e.normal, x) {
                            continue;
                        }
                        n_open += 1;
                        // Cosine-weighted direction about n.
                        let r = d[0].sqrt();
                        let phi = std::f32::consts::TAU * d[1];
                        let w = (t * (r * phi.cos())
                            + b * (r * phi.sin())
                            + n * (1.0 - d[0]).max(0.0).sqrt())
                        .normalize_or_zero();
                        if w.dot(up) <= 0.0 {
                            continue;
                        }
                        rays += 1;
                        open += vis.open_to_infinity(x, w, e.tri);
                    }
                    h += sky.as_dvec3() * (std::f64::consts::PI * open / n_open.max(1) as f64);
                }
                (h, rays)
            })
            .collect();
        for (k, (h, r)) in vals.into_iter().enumerate() {
            self.el.direct[lo as usize + k] = h;
            self.rays += r;
        }
    }
}
