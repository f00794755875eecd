//! Path-traced reference images with the solver's conventions (`radiosity.md`,
//! `experiments.md` §3): diffuse surfaces only (BRDF ρ/π), one-sided by default (the back of a
//! triangle absorbs), emitters emit from their front only, a sun and a uniform sky as in the
//! solver. [`PathTracer`] lists the conventions in full; [`render_reference`] renders an image,
//! and [`PathTracer::record_rays`] with [`RayLog::replay`] measures the share of ray casting.
//!
//! Each pixel draws from its own generator `SplitMix64::for_item(seed, y·width + x)`; samples
//! are uniformly jittered in the pixel. Rows are rendered in parallel; the image does not
//! depend on the number of threads.

use super::camera::{CameraFrame, CameraView};
use super::image::{render_rows, Image};
use crate::facing::Facing;
use crate::sample::{cosine_sample, power_heuristic, surface_eps, Lights};
use glam::Vec3;
use hirad_accel::ray::{RayCaster, Segment};
use hirad_core::progress::Progress;
use hirad_core::rng::SplitMix64;
use hirad_core::{Error, Result};
use hirad_scene::Scene;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::f32::consts::PI;
use std::sync::atomic::AtomicBool;

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

/// Time of replaying a [`RayLog`] through a ray caster.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct RayReplay {
    /// Closest-hit queries replayed.
    pub closest_rays: u64,
    /// Wall time of the closest-hit queries, seconds.
    pub closest_seconds: f64,
    /// Occlusion queries replayed.
    pub shadow_rays: u64,
    /// Wall time of the occlusion queries, seconds.
    pub shadow_seconds: f64,
}

impl RayReplay {
    /// Closest-hit queries per second.
    pub fn closest_per_second(&self) -> f64 {
        self.closest_rays as f64 / self.closest_seconds.max(1e-12)
    }

    /// Occlusion queries per second.
    pub fn shadow_per_second(&self) -> f64 {
        self.shadow_rays as f64 / self.shadow_seconds.max(1e-12)
    }

    /// Seconds that ray casting alone would take for the counts of `stats`, at the replayed
    /// rates.
    pub fn ray_seconds_for(&self, stats: &ReferenceStats) -> f64 {
        let c = if self.closest_rays > 0 {
            stats.segments as f64 / self.closest_per_second()
        } else {
            0.0
        };
        let s = if self.shadow_rays > 0 {
            stats.shadow_rays as f64 / self.shadow_per_second()
        } else {
            0.0
        };
        c + s
    }
}

impl RayLog {
    /// Cast the logged rays again, in parallel (closest-hit queries, then occlusion queries),
    /// and time each kind. Returns the times and the number of hits and of occluded rays.
    pub fn replay(&self, caster: &RayCaster) -> (RayReplay, u64, u64) {
        let t0 = std::time::Instant::now();
        let hits = caster
            .closest_batch(&self.closest)
            .iter()
            .filter(|h| h.is_some())
            .count() as u64;
        let closest_seconds = t0.elapsed().as_secs_f64();
        let t1 = std::time::Instant::now();
        let occluded = caster.count_occluded(&self.shadow);
        let shadow_seconds = t1.elapsed().as_secs_f64();
        (
            RayReplay {
                closest_rays: self.closest.len() as u64,
                closest_seconds,
                shadow_rays: self.shadow.len() as u64,
                shadow_seconds,
            },
            hits,
            occluded,
        )
    }
}

/// The path tracer over a scene and a ray caster. Its conventions, the solver's:
///
/// - Diffuse surfaces only: reflectance ρ per material, BRDF ρ/π.
/// - One-sided surfaces by default: a ray that reaches the back of a triangle (the side opposite
///   its counter-clockwise normal) is absorbed, so back faces look black and block light, as
///   surfaces without a back face do in the solver. With `two_sided`, or for a material the
///   scene makes two-sided (`Scene::has_back`), the back is a diffuse surface with the same ρ
///   (but it does not emit).
/// - Emitters emit radiance L_e from the front face only.
/// - A ray that meets coincident faces facing opposite ways at once sees the one facing it
///   (`facing.rs`).
/// - Next-event estimation on emitting triangles: a triangle is chosen with probability
///   proportional to its power `A · mean(L_e)`, a point uniformly on it; the light sample and
///   the cosine-weighted BRDF sample are combined with multiple importance sampling (power
///   heuristic, β = 2), so emission is never counted twice. Emission seen directly by a camera
///   ray has weight 1.
/// - Sun: a directional light of irradiance E (on a surface facing it), direction `s` towards the
///   sun: a shadow ray per shading point, contribution `ρ/π · E · max(0, n·s)`.
/// - Sky: uniform radiance over the upper hemisphere (directions with a positive component
///   along the scene's up axis), collected by BRDF-sampled rays that leave the scene.
/// - Camera rays that leave the scene give the background 0 (the rasteriser's background), even
///   with a sky.
/// - Russian roulette after `rr_depth` bounces with survival probability
///   `min(0.95, max channel of the path throughput)`; `max_depth` bounces at most.
pub struct PathTracer<'a> {
    scene: &'a Scene,
    caster: &'a RayCaster<'a>,
    opts: ReferenceOptions,
    lights: Lights,
    facing: Facing,
    /// Offset of secondary ray origins along the normal (scene units).
    eps: f32,
    up: Vec3,
}

/// What the tracer reports about every ray it casts: plain counting while rendering, counting
/// and recording for [`PathTracer::record_rays`]. Generic, so the render loop carries no
/// recording cost.
trait RayTally {
    /// A closest-hit query (path segment).
    fn segment(&mut self, origin: Vec3, dir: Vec3, tmin: f32, tmax: f32);
    /// An occlusion query (shadow ray).
    fn shadow(&mut self, origin: Vec3, dir: Vec3, tmin: f32, tmax: f32);
}

#[derive(Default, Clone, Copy)]
struct Counts {
    segments: u64,
    shadow: u64,
}

impl RayTally for Counts {
    #[inline(always)]
    fn segment(&mut self, _: Vec3, _: Vec3, _: f32, _: f32) {
        self.segments += 1;
    }
    #[inline(always)]
    fn shadow(&mut self, _: Vec3, _: Vec3, _: f32, _: f32) {
        self.shadow += 1;
    }
}

/// The rays a render casts, in the order it casts them (see [`PathTracer::record_rays`]).
#[derive(Clone, Debug, Default)]
pub struct RayLog {
    /// Closest-hit queries: camera rays and bounces (path segments).
    pub closest: Vec<Segment>,
    /// Occlusion queries: shadow rays of next-event estimation and of the sun.
    pub shadow: Vec<Segment>,
}

impl RayTally for RayLog {
    #[inline]
    fn segment(&mut self, origin: Vec3, dir: Vec3, tmin: f32, tmax: f32) {
        self.closest.push(Segment {
            origin,
            dir,
            tmin,
            tmax,
        });
    }
    #[inline]
    fn shadow(&mut self, origin: Vec3, dir: Vec3, tmin: f32, tmax: f32) {
        self.shadow.push(Segment {
            origin,
            dir,
            tmin,
            tmax,
        });
    }
}

impl<'a> PathTracer<'a> {
    /// Prepare the light distribution.
    pub fn new(scene: &'a Scene, caster: &'a RayCaster<'a>, opts: &ReferenceOptions) -> Self {
        PathTracer {
            scene,
            caster,
            opts: opts.clone(),
            lights: Lights::new(scene),
            facing: Facing::new(scene, caster.tree),
            eps: surface_eps(scene),
            up: scene.up.vector(),
        }
    }

    /// Radiance arriving at `origin` from direction `dir` (unit), estimated by one path.
    pub fn radiance(&self, origin: Vec3, dir: Vec3, rng: &mut SplitMix64) -> Vec3 {
        let mut c = Counts::default();
        self.trace(origin, dir, rng, &mut c)
    }

    fn trace<T: RayTally>(
        &self,
        origin: Vec3,
        dir: Vec3,
        rng: &mut SplitMix64,
        cnt: &mut T,
    ) -> Vec3 {
        let scene = self.scene;
        let mut l = Vec3::ZERO;
        let mut beta = Vec3::ONE;
        let (mut o, mut d) = (origin, dir);
        // Density (solid angle) of the BRDF sample that produced `d`; 0 for camera rays.
        let mut pdf_bsdf = 0.0f32;
        let mut depth = 0u32;
        loop {
            cnt.segment(o, d, 0.0, f32::INFINITY);
            let hit = match self.caster.closest(o, d, 0.0, f32::INFINITY) {
                Some(h) => self.facing.resolve(scene, self.caster, (o, d), h),
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
            if !front && !scene.has_back(tri, self.opts.two_sided) {
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
                let lt = self.lights.pick(rng.next_f64());
                let (a, b, c) = (lt.a, lt.b, lt.c);
                let s = rng.next_f32().sqrt();
                let u2 = rng.next_f32();
                let y = a * (1.0 - s) + b * (s * (1.0 - u2)) + c * (s * u2);
                let to = y - x;
                let dist2 = to.length_squared();
                if dist2 > 0.0 {
                    let dist = dist2.sqrt();
                    let w = to / dist;
                    let cos_x = n.dot(w);
                    let cos_y = -lt.normal.dot(w);
                    if cos_x > 0.0 && cos_y > 0.0 {
                        cnt.shadow(x, to, 0.0, 1.0 - 1e-4);
                        // The segment stops just short of the light's surface.
                        if !self.caster.occluded(x, to, 0.0, 1.0 - 1e-4)
                            && self.facing.sees(scene, self.caster, (x, to), lt.tri)
                        {
                            let pdf_a = lt.pdf_area;
                            let pdf_light = pdf_a * dist2 / cos_y;
                            let wmis = power_heuristic(pdf_light, cos_x / PI);
                            l += beta
                                * rho
                                * lt.emission
                                * (cos_x * cos_y / (PI * dist2 * pdf_a) * wmis);
                        }
                    }
                }
            }
            // Sun: a delta light, shadow ray towards it.
            if let Some(sun) = scene.sun {
                let cos = n.dot(sun.direction);
                if cos > 0.0 {
                    cnt.shadow(x, sun.direction, 0.0, f32::INFINITY);
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

    /// Pixel `(x, y)` of an image `w` pixels wide: the mean of `spp` jittered paths drawn from
    /// the pixel's own generator.
    #[inline]
    fn pixel<T: RayTally>(
        &self,
        frame: &CameraFrame,
        x: usize,
        y: usize,
        w: usize,
        cnt: &mut T,
    ) -> Vec3 {
        let mut rng = SplitMix64::for_item(self.opts.seed, (y * w + x) as u64);
        let mut sum = glam::DVec3::ZERO;
        for _ in 0..self.opts.spp {
            let sx = x as f32 + rng.next_f32();
            let sy = y as f32 + rng.next_f32();
            let d = frame.direction(sx, sy).normalize();
            sum += self.trace(frame.eye, d, &mut rng, cnt).as_dvec3();
        }
        (sum / self.opts.spp as f64).as_vec3()
    }

    /// The rays that [`PathTracer::render`] casts for the rows `0, row_stride, 2·row_stride, …`
    /// of `view`, in the order it casts them (rows, then pixels, then paths). Replaying them
    /// through the ray caster ([`RayLog::replay`]) measures how much of a render is ray casting.
    pub fn record_rays(&self, view: &CameraView, row_stride: u32) -> Result<RayLog> {
        view.validate()?;
        if self.opts.spp == 0 || row_stride == 0 {
            return Err(Error::Config(
                "spp and the row stride must be at least 1".into(),
            ));
        }
        let frame = view.frame();
        let w = view.width as usize;
        let rows: Vec<usize> = (0..view.height as usize)
            .step_by(row_stride as usize)
            .collect();
        let logs: Vec<RayLog> = rows
            .par_iter()
            .map(|&y| {
                let mut log = RayLog::default();
                for x in 0..w {
                    self.pixel(&frame, x, y, w, &mut log);
                }
                log
            })
            .collect();
        let mut all = RayLog::default();
        for l in logs {
            all.closest.extend_from_slice(&l.closest);
            all.shadow.extend_from_slice(&l.shadow);
        }
        Ok(all)
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
        let spp = self.opts.spp;
        let counts: Vec<Counts> = render_rows(
            &mut img.pixels,
            w,
            "reference",
            progress,
            cancel,
            |x, y, cnt| self.pixel(&frame, x, y, w, cnt),
        )?;
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
