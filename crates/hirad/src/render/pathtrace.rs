//! Path-traced reference images with the solver's conventions (`radiosity.md`,
//! `experiments.md` §3).
//!
//! - Diffuse surfaces only: reflectance ρ per material, BRDF ρ/π.
//! - One-sided surfaces by default: a ray that reaches the back of a triangle (the side opposite
//!   its counter-clockwise normal) is absorbed, so back faces look black and block light, as
//!   surfaces without a back face do in the solver. With `two_sided`, the back is a diffuse
//!   surface with the same ρ (but it does not emit).
//! - Emitters emit radiance L_e from the front face only.
//! - Next-event estimation on emitting triangles: a triangle is chosen with probability
//!   proportional to its power `A · mean(L_e)`, a point uniformly on it; the light sample and
//!   the cosine-weighted BRDF sample are combined with multiple importance sampling (power
//!   heuristic, β = 2), so emission is never counted twice. Emission seen directly by a camera
//!   ray has weight 1.
//! - Sun: a directional light of irradiance E (on a surface facing it), direction `s` towards the
//!   sun: a shadow ray per shading point, contribution `ρ/π · E · max(0, n·s)`.
//! - Sky: uniform radiance over the upper hemisphere (directions with a positive component
//!   along the scene's up axis), collected by BRDF-sampled rays that leave the scene.
//! - Camera rays that leave the scene give the background 0 (the rasteriser's background), even
//!   with a sky.
//! - Russian roulette after `rr_depth` bounces with survival probability
//!   `min(0.95, max channel of the path throughput)`; `max_depth` bounces at most.
//! - Each pixel draws from its own generator `SplitMix64::for_item(seed, y·width + x)`; samples
//!   are uniformly jittered in the pixel. Rows are rendered in parallel; the image does not
//!   depend on the number of threads.

use super::camera::CameraView;
use super::image::Image;
use crate::progress::Progress;
use crate::ray::RayCaster;
use crate::rng::SplitMix64;
use crate::scene::Scene;
use crate::{Error, Result};
use glam::Vec3;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::f32::consts::PI;
use std::sync::atomic::{AtomicBool, Ordering};

/// Settings of the path tracer.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ReferenceOptions {
    /// Samples (paths) per pixel.
    pub spp: u32,
    /// Seed of the per-pixel generators.
    pub seed: u64,
    /// Give every surface a diffuse back face (default: back faces absorb).
    pub two_sided: bool,
    /// Bounces after which Russian roulette starts.
    pub rr_depth: u32,
    /// Hard limit on bounces.
    pub max_depth: u32,
}

impl Default for ReferenceOptions {
    fn default() -> Self {
        Self {
            spp: 64,
            seed: 1,
            two_sided: false,
            rr_depth: 3,
            max_depth: 1000,
        }
    }
}

/// Counts and time of a reference render.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ReferenceStats {
    /// Paths traced (pixels × spp).
    pub paths: u64,
    /// Path segments: closest-hit rays (camera rays and bounces).
    pub segments: u64,
    /// Shadow (occlusion) rays of next-event estimation.
    pub shadow_rays: u64,
    /// Wall time, seconds.
    pub seconds: f64,
}

impl ReferenceStats {
    /// Path segments per second.
    pub fn segments_per_second(&self) -> f64 {
        self.segments as f64 / self.seconds.max(1e-12)
    }

    /// All rays (segments and shadow rays) per second.
    pub fn rays_per_second(&self) -> f64 {
        (self.segments + self.shadow_rays) as f64 / self.seconds.max(1e-12)
    }
}

/// Emitting triangles and the power distribution over them.
struct Lights {
    tris: Vec<u32>,
    /// Cumulative power, last entry = total.
    cdf: Vec<f64>,
    /// Probability density per unit area of choosing a point on each scene triangle
    /// (0 for non-emitters): `mean(L_e) / Σ A·mean(L_e)`.
    pdf_area: Vec<f32>,
}

impl Lights {
    fn new(scene: &Scene) -> Lights {
        let tris = scene.emitters();
        let mut cdf = Vec::with_capacity(tris.len());
        let mut total = 0.0f64;
        for &t in &tris {
            let le = scene.material_of(t as usize).emission;
            total += scene.areas[t as usize] as f64 * mean(le) as f64;
            cdf.push(total);
        }
        let mut pdf_area = vec![0.0f32; scene.num_triangles()];
        if total > 0.0 {
            for &t in &tris {
                pdf_area[t as usize] =
                    (mean(scene.material_of(t as usize).emission) as f64 / total) as f32;
            }
        }
        Lights {
            tris,
            cdf,
            pdf_area,
        }
    }

    fn is_empty(&self) -> bool {
        self.tris.is_empty() || *self.cdf.last().unwrap() <= 0.0
    }

    /// Choose an emitting triangle from a uniform `u`.
    fn pick(&self, u: f64) -> u32 {
        let target = u * self.cdf.last().unwrap();
        let i = self.cdf.partition_point(|&c| c <= target);
        self.tris[i.min(self.tris.len() - 1)]
    }
}

#[inline]
fn mean(v: Vec3) -> f32 {
    (v.x + v.y + v.z) / 3.0
}

/// Power heuristic (β = 2) weight of a sample of density `a` against one of density `b`.
#[inline]
fn power_heuristic(a: f32, b: f32) -> f32 {
    let (a2, b2) = (a * a, b * b);
    if a2 + b2 > 0.0 {
        a2 / (a2 + b2)
    } else {
        0.0
    }
}

/// Orthonormal basis around unit `n` (Duff et al. 2017).
#[inline]
fn basis(n: Vec3) -> (Vec3, Vec3) {
    let sign = 1.0f32.copysign(n.z);
    let a = -1.0 / (sign + n.z);
    let b = n.x * n.y * a;
    (
        Vec3::new(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x),
        Vec3::new(b, sign + n.y * n.y * a, -n.y),
    )
}

/// Cosine-weighted direction around unit `n`; returns (direction, cos θ).
#[inline]
fn cosine_sample(n: Vec3, u1: f32, u2: f32) -> (Vec3, f32) {
    let r = u1.sqrt();
    let phi = 2.0 * PI * u2;
    let (t, b) = basis(n);
    let cos = (1.0 - u1).max(0.0).sqrt();
    (
        (t * (r * phi.cos()) + b * (r * phi.sin()) + n * cos).normalize(),
        cos,
    )
}

/// The path tracer over a scene and a ray caster.
pub struct PathTracer<'a> {
    scene: &'a Scene,
    caster: &'a RayCaster<'a>,
    opts: ReferenceOptions,
    lights: Lights,
    /// Offset of secondary ray origins along the normal (scene units).
    eps: f32,
    up: Vec3,
}

#[derive(Default, Clone, Copy)]
struct Counts {
    segments: u64,
    shadow: u64,
}

impl<'a> PathTracer<'a> {
    /// Prepare the light distribution.
    pub fn new(scene: &'a Scene, caster: &'a RayCaster<'a>, opts: &ReferenceOptions) -> Self {
        let diag = scene.bbox.extent().length();
        let scale = diag
            .max(scene.bbox.min.abs().max_element())
            .max(scene.bbox.max.abs().max_element());
        PathTracer {
            scene,
            caster,
            opts: opts.clone(),
            lights: Lights::new(scene),
            eps: (scale * 2e-6).max(1e-7),
            up: scene.up.vector(),
        }
    }

    /// Radiance arriving at `origin` from direction `dir` (unit), estimated by one path.
    pub fn radiance(&self, origin: Vec3, dir: Vec3, rng: &mut SplitMix64) -> Vec3 {
        let mut c = Counts::default();
        self.trace(origin, dir, rng, &mut c)
    }

    fn trace(&self, origin: Vec3, dir: Vec3, rng: &mut SplitMix64, cnt: &mut Counts) -> Vec3 {
        let scene = self.scene;
        let mut l = Vec3::ZERO;
        let mut beta = Vec3::ONE;
        let (mut o, mut d) = (origin, dir);
        // Density (solid angle) of the BRDF sample that produced `d`; 0 for camera rays.
        let mut pdf_bsdf = 0.0f32;
        let mut depth = 0u32;
        loop {
            cnt.segments += 1;
            let hit = match self.caster.closest(o, d, 0.0, f32::INFINITY) {
                Some(h) => h,
                None => {
                    if depth > 0 {
                        if let Some(sky) = scene.sky {
                            if d.dot(self.up) > 0.0 {
                                l += beta * sky;
                            }
                        }
                    }
                    break;
                }
            };
            let tri = hit.tri as usize;
            let ng = scene.normals[tri];
            let front = ng.dot(d) < 0.0;
            let mat = scene.material_of(tri);
            let p = o + d * hit.t;
            if front && mat.is_emitter() {
                let w = if depth == 0 {
                    1.0
                } else {
                    let cos_l = -ng.dot(d);
                    let pdf_light = self.lights.pdf_area[tri] * hit.t * hit.t / cos_l;
                    power_heuristic(pdf_bsdf, pdf_light)
                };
                l += beta * mat.emission * w;
            }
            if !front && !self.opts.two_sided {
                break; // one-sided: the back of a surface absorbs
            }
            let n = if front { ng } else { -ng };
            let rho = mat.rho;
            if rho.max_element() <= 0.0 || depth >= self.opts.max_depth {
                break;
            }
            let x = p + n * self.eps;
            // Next-event estimation: emitting triangles.
            if !self.lights.is_empty() {
                let lt = self.lights.pick(rng.next_f64()) as usize;
                let [a, b, c] = scene.tri_vertices(lt);
                let s = rng.next_f32().sqrt();
                let u2 = rng.next_f32();
                let y = a * (1.0 - s) + b * (s * (1.0 - u2)) + c * (s * u2);
                let to = y - x;
                let dist2 = to.length_squared();
                if dist2 > 0.0 {
                    let dist = dist2.sqrt();
                    let w = to / dist;
                    let cos_x = n.dot(w);
                    let nl = scene.normals[lt];
                    let cos_y = -nl.dot(w);
                    if cos_x > 0.0 && cos_y > 0.0 {
                        cnt.shadow += 1;
                        // The segment stops just short of the light's surface.
                        if !self.caster.occluded(x, to, 0.0, 1.0 - 1e-4) {
                            let pdf_a = self.lights.pdf_area[lt];
                            let pdf_light = pdf_a * dist2 / cos_y;
                            let wmis = power_heuristic(pdf_light, cos_x / PI);
                            let le = scene.material_of(lt).emission;
                            l += beta * rho * le * (cos_x * cos_y / (PI * dist2 * pdf_a) * wmis);
                        }
                    }
                }
            }
            // Sun: a delta light, shadow ray towards it.
            if let Some(sun) = scene.sun {
                let cos = n.dot(sun.direction);
                if cos > 0.0 {
                    cnt.shadow += 1;
                    if !self.caster.occluded(x, sun.direction, 0.0, f32::INFINITY) {
                        l += beta * rho * sun.irradiance * (cos / PI);
                    }
                }
            }
            // Continue the path: cosine-weighted sample, throughput × ρ.
            let (nd, cos) = cosine_sample(n, rng.next_f32(), rng.next_f32());
            if cos <= 0.0 {
                break;
            }
            beta *= rho;
            depth += 1;
            if depth >= self.opts.rr_depth {
                let q = beta.max_element().min(0.95);
                if rng.next_f32() >= q {
                    break;
                }
                beta /= q;
            }
            pdf_bsdf = cos / PI;
            o = x;
            d = nd;
        }
        l
    }

    /// Render an image: `spp` jittered paths per pixel, averaged.
    pub fn render(
        &self,
        view: &CameraView,
        progress: &dyn Progress,
        cancel: Option<&AtomicBool>,
    ) -> Result<(Image, ReferenceStats)> {
        view.validate()?;
        if self.opts.spp == 0 {
            return Err(Error::Config("spp must be at least 1".into()));
        }
        let t0 = std::time::Instant::now();
        let frame = view.frame();
        let w = view.width as usize;
        let mut img = Image::new(view.width, view.height, Vec3::ZERO);
        progress.start("reference", view.height as u64);
        let spp = self.opts.spp;
        let inv = 1.0 / spp as f64;
        let counts: Vec<Counts> = img
            .pixels
            .par_chunks_mut(w)
            .enumerate()
            .map(|(y, row)| {
                let mut cnt = Counts::default();
                if cancel.is_some_and(|c| c.load(Ordering::Relaxed)) {
                    return cnt;
                }
                for (x, px) in row.iter_mut().enumerate() {
                    let mut rng = SplitMix64::for_item(self.opts.seed, (y * w + x) as u64);
                    let mut sum = glam::DVec3::ZERO;
                    for _ in 0..spp {
                        let sx = x as f32 + rng.next_f32();
                        let sy = y as f32 + rng.next_f32();
                        let d = frame.direction(sx, sy).normalize();
                        sum += self.trace(frame.eye, d, &mut rng, &mut cnt).as_dvec3();
                    }
                    *px = (sum * inv).as_vec3();
                }
                progress.inc(1);
                cnt
            })
            .collect();
        progress.finish();
        if cancel.is_some_and(|c| c.load(Ordering::Relaxed)) {
            return Err(Error::Interrupted);
        }
        let stats = ReferenceStats {
            paths: view.width as u64 * view.height as u64 * spp as u64,
            segments: counts.iter().map(|c| c.segments).sum(),
            shadow_rays: counts.iter().map(|c| c.shadow).sum(),
            seconds: t0.elapsed().as_secs_f64(),
        };
        tracing::info!(
            "reference: {} paths, {} segments, {} shadow rays in {:.2} s ({:.2} M segments/s)",
            stats.paths,
            stats.segments,
            stats.shadow_rays,
            stats.seconds,
            stats.segments_per_second() * 1e-6
        );
        Ok((img, stats))
    }
}

/// Render a path-traced reference of `scene` seen from `view`.
pub fn render_reference(
    scene: &Scene,
    caster: &RayCaster,
    view: &CameraView,
    opts: &ReferenceOptions,
    progress: &dyn Progress,
) -> Result<(Image, ReferenceStats)> {
    PathTracer::new(scene, caster, opts).render(view, progress, None)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cosine_samples_are_on_the_hemisphere() {
        let mut rng = SplitMix64::new(3);
        for n in [Vec3::Z, Vec3::NEG_Z, Vec3::new(0.3, -0.5, 0.8).normalize()] {
            let mut mean_cos = 0.0f64;
            for _ in 0..20000 {
                let (d, c) = cosine_sample(n, rng.next_f32(), rng.next_f32());
                assert!((d.length() - 1.0).abs() < 1e-5);
                assert!((d.dot(n) - c).abs() < 1e-4);
                mean_cos += c as f64;
            }
            // E[cos θ] under the cosine density is 2/3.
            assert!((mean_cos / 20000.0 - 2.0 / 3.0).abs() < 0.01);
        }
    }

    #[test]
    fn power_heuristic_sums_to_one() {
        for (a, b) in [(1.0, 2.0), (0.3, 0.0), (5.0, 5.0)] {
            assert!((power_heuristic(a, b) + power_heuristic(b, a) - 1.0).abs() < 1e-6);
        }
        assert_eq!(power_heuristic(0.0, 0.0), 0.0);
    }
}
