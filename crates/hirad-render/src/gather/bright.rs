//! Importance to bright elements ([`super::GatherOptions::bright`], on by default): solution
//! triangles far brighter than the mean (lamp housings, lit patches next to a lamp) are also
//! sampled by area (stratified as the emitter samples) with a shadow ray, and combined with the
//! gather rays by multiple importance sampling.

use super::lookup::SolutionLookup;
use super::{Counts, Gatherer};
use crate::facing::Facing;
use crate::sample::{alias_pick, alias_table, power_heuristic};
use glam::Vec3;
use hirad_accel::ray::RayCaster;
use hirad_scene::Scene;
use rayon::prelude::*;
use std::f32::consts::PI;

/// Bright solution triangles, sampled by area with probability proportional to their
/// reflected power `A · mean(B − E)`.
pub(super) struct Bright {
    pub(super) tris: Vec<BrightTri>,
    prob: Vec<f64>,
    alias: Vec<u32>,
    /// Per half of the solution mesh, per triangle: density per unit area of a bright sample
    /// on it (0 when not bright).
    pub(super) pdf_area: [Vec<f32>; 2],
}

#[derive(Clone, Copy)]
pub(super) struct BrightTri {
    p: [Vec3; 3],
    normal: Vec3,
    colors: [Vec3; 3],
    pdf_area: f32,
}

impl Bright {
    /// The bright triangles of `sol`: reflected radiosity above `factor` × the area-weighted
    /// mean; `None` when there are none.
    pub(super) fn new(
        sol: &SolutionLookup,
        scene: &Scene,
        caster: &RayCaster,
        facing: &Facing,
        factor: f32,
    ) -> Option<Bright> {
        // Per half, per triangle: (area, mean reflected radiosity B − E).
        let per: Vec<Vec<(f32, f32)>> = sol
            .halves
            .iter()
            .map(|half| {
                let Some(m) = half else { return Vec::new() };
                (0..m.scene.num_triangles())
                    .into_par_iter()
                    .map(|t| {
                        let n = m.scene.normals[t];
                        let c = m.scene.tri_centroid(t);
                        let o = c + n * sol.delta;
                        let hit = caster.closest(o, -n, 0.0, 2.0 * sol.delta);
                        let hit = hit.map(|h| facing.resolve(scene, caster, (o, -n), h));
                        let emitted = match hit {
                            Some(h) if scene.normals[h.tri as usize].dot(n) > 0.0 => {
                                scene.material_of(h.tri as usize).emission * PI
                            }
                            _ => Vec3::ZERO,
                        };
                        let b = m.colors[t].iter().sum::<Vec3>() / 3.0;
                        let r = (b - emitted).max(Vec3::ZERO);
                        (m.scene.areas[t], (r.x + r.y + r.z) / 3.0)
                    })
                    .collect()
            })
            .collect();
        let (mut sa, mut sr) = (0.0f64, 0.0f64);
        for v in &per {
            for &(a, r) in v {
                sa += a as f64;
                sr += (a * r) as f64;
            }
        }
        let threshold = (factor as f64 * sr / sa.max(1e-300)) as f32;
        let mut ids = Vec::new();
        let mut power = Vec::new();
        for (h, v) in per.iter().enumerate() {
            for (t, &(a, r)) in v.iter().enumerate() {
                if r > threshold && r > 0.0 {
                    ids.push((h, t));
                    power.push(a as f64 * r as f64);
                }
            }
        }
        let total: f64 = power.iter().sum();
        if ids.is_empty() || total.is_nan() || total <= 0.0 {
            return None;
        }
        let mut pdf_area = [vec![0.0f32; per[0].len()], vec![0.0f32; per[1].len()]];
        let tris = ids
            .iter()
            .map(|&(h, t)| {
                let m = sol.halves[h].as_ref().unwrap();
                let pdf = (per[h][t].1 as f64 / total) as f32;
                pdf_area[h][t] = pdf;
                BrightTri {
                    p: m.scene.tri_vertices(t),
                    normal: m.scene.normals[t],
                    colors: m.colors[t],
                    pdf_area: pdf,
                }
            })
            .collect();
        let (prob, alias) = alias_table(&power, total);
        Some(Bright {
            tris,
            prob,
            alias,
            pdf_area,
        })
    }

    #[inline]
    pub(super) fn pick(&self, u: f64) -> &BrightTri {
        &self.tris[alias_pick(&self.prob, &self.alias, u)]
    }
}

impl Gatherer<'_> {
    /// Radiance (before × ρ) reflected at `x` from one area sample of the bright elements,
    /// weighted against the gather ray by multiple importance sampling.
    pub(super) fn bright_sample(
        &self,
        x: Vec3,
        n: Vec3,
        br: &Bright,
        (upick, (u1, u2)): (f64, (f32, f32)),
        cnt: &mut Counts,
    ) -> Vec3 {
        let bt = br.pick(upick);
        let s = u1.sqrt();
        let (w0, w1, w2) = (1.0 - s, s * (1.0 - u2), s * u2);
        let y = bt.p[0] * w0 + bt.p[1] * w1 + bt.p[2] * w2;
        let to = y - x;
        let dist2 = to.length_squared();
        if dist2 <= 0.0 {
            return Vec3::ZERO;
        }
        let w = to / dist2.sqrt();
        let cos_x = n.dot(w);
        let cos_y = -bt.normal.dot(w);
        if cos_x <= 0.0 || cos_y <= 0.0 {
            return Vec3::ZERO;
        }
        // The first surface towards the sample must be the sample's own (its side, emission).
        cnt.shadow += 1;
        let Some(h) = self.closest(x, to, 1.0 + 1e-3) else {
            return Vec3::ZERO;
        };
        if h.t < 1.0 - 1e-3 {
            return Vec3::ZERO;
        }
        let tri = h.tri as usize;
        let ng = self.scene.normals[tri];
        let front = ng.dot(to) < 0.0;
        if !front && !self.scene.has_back(tri, self.opts.two_sided) {
            return Vec3::ZERO;
        }
        let mat = self.scene.material_of(tri);
        let emitted = if front { mat.emission * PI } else { Vec3::ZERO };
        let b = bt.colors[0] * w0 + bt.colors[1] * w1 + bt.colors[2] * w2;
        let l = (b - emitted).max(Vec3::ZERO) / PI;
        let pdf_sa = bt.pdf_area * dist2 / cos_y;
        let wmis = power_heuristic(pdf_sa, cos_x / PI);
        l * (cos_x * cos_y / (PI * dist2 * bt.pdf_area) * wmis)
    }
}
