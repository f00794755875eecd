//! Final gather: images of a radiosity solution as sharp as a path tracer's, without its noise
//! in indirect light (the two-pass method of RenderPark and its kind).
//!
//! Per pixel sample: a camera ray to the first hit in the scene, direct light by the path
//! tracer's emitter sampling and the sun, and one cosine-weighted gather ray whose hit reads the
//! solution's reflected radiosity (B minus the emitted exitance there, so that direct light is
//! not counted twice); [`Gatherer`] gives the details. The solution is the mesh `solve` writes
//! (`solution.glb`), matched to the scene's surfaces by [`SolutionLookup`]: a `.glb` and the
//! scene are enough, nothing is solved again. Bright solution triangles are also sampled by area
//! ([`GatherOptions::bright`]), gather hits near the shading point get one more bounce
//! ([`GatherOptions::near`]), an irradiance cache can stand for the gather rays where the
//! indirect light is smooth ([`GatherOptions::cache`]), and a second pass adds samples where
//! the first pass's pixels spread most ([`GatherOptions::adaptive`]).
//!
//! Each pixel draws from its own generator `SplitMix64::for_item(seed, y·width + x)` (its
//! extra samples from one with a tagged seed), each cache point from one of its own; rows are
//! rendered in parallel and the image does not depend on the number of threads.

mod adaptive;
mod bright;
mod cache;
mod lookup;

pub use lookup::{Lookup, SolutionLookup};

use super::camera::{CameraFrame, CameraView};
use super::image::{render_rows, Image};
use crate::facing::Facing;
use crate::sample::{cosine_sample, power_heuristic, surface_eps, Lights};
use adaptive::Spread;
use bright::Bright;
use cache::Cache;
use glam::{DVec3, Vec3};
use hirad_accel::ray::{Hit, RayCaster};
use hirad_core::progress::Progress;
use hirad_core::rng::SplitMix64;
use hirad_core::{Error, Result};
use hirad_scene::export::ColoredMesh;
use hirad_scene::Scene;
use lookup::SPLIT;
use serde::{Deserialize, Serialize};
use sobol_burley::parts::{hash_int4, owen_scramble_int4_rev, sobol_int4_rev, Int4};
use std::f32::consts::PI;
use std::sync::atomic::AtomicBool;

/// Settings of the final gather.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct GatherOptions {
    /// Samples per pixel before adaptive sampling: camera rays, light samples and gather rays
    /// (one each per sample; a sample that takes its indirect light from the irradiance cache
    /// casts no gather ray and two light samples).
    pub rays: u32,
    /// Seed of the per-pixel generators.
    pub seed: u64,
    /// Surfaces have a diffuse back face (the solution's back-face copies are read there).
    pub two_sided: bool,
    /// How a gather ray reads the solution.
    pub lookup: Lookup,
    /// Importance to bright elements: solution triangles whose reflected radiosity B − E is
    /// above this multiple of the area-weighted mean are also sampled by area (one more shadow
    /// ray per sample), combined with the gather rays by multiple importance sampling; 0: off.
    pub bright: f32,
    /// One more bounce near the shading point: a gather ray whose hit lies closer than this
    /// multiple of the square root of the hit element's area is shaded there (an emitter
    /// sample, a gather ray reading the solution, a bright-element sample) instead of reading
    /// the element's radiosity, which stands for the element as seen from afar (corners,
    /// contact); 0: off.
    pub near: f32,
    /// Irradiance cache: the indirect light of one point per block of this many pixels
    /// squared, gathered with the block's rays and interpolated where valid (`gather/cache.rs`);
    /// 0: every sample gathers its own (and what a record written before the cache reads).
    #[serde(default)]
    pub cache: u32,
    /// Adaptive sampling: after every pixel's `rays` samples, about this many times `rays`
    /// more per pixel on average, given to the pixels whose neighbours' samples spread most in
    /// lightness (`gather/adaptive.rs`); 0: every pixel takes `rays` (and what a record
    /// written before it reads).
    #[serde(default)]
    pub adaptive: f32,
}

impl Default for GatherOptions {
    fn default() -> Self {
        Self {
            rays: 64,
            seed: 1,
            two_sided: false,
            lookup: Lookup::Element,
            bright: 16.0,
            near: 8.0,
            cache: 2,
            adaptive: 1.0,
        }
    }
}

/// Counts and time of a gather.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct GatherStats {
    /// Camera rays.
    pub camera_rays: u64,
    /// Gather rays (closest-hit queries from shading points).
    pub gather_rays: u64,
    /// Shadow rays (emitter samples and the sun).
    pub shadow_rays: u64,
    /// Solution look-ups (short rays into the solution mesh).
    pub lookups: u64,
    /// Look-ups that found no element (read as black).
    pub lookup_misses: u64,
    /// Gather hits shaded by one more bounce ([`GatherOptions::near`]).
    #[serde(default)]
    pub near: u64,
    /// Solution triangles sampled as bright elements ([`GatherOptions::bright`]).
    pub bright_triangles: u64,
    /// Points of the irradiance cache ([`GatherOptions::cache`]).
    #[serde(default)]
    pub cache_points: u64,
    /// Pixel samples whose indirect light came from the cache.
    #[serde(default)]
    pub cached: u64,
    /// Extra samples of adaptive sampling ([`GatherOptions::adaptive`]), in all.
    #[serde(default)]
    pub adaptive_samples: u64,
    /// Pixels that took extra samples.
    #[serde(default)]
    pub adaptive_pixels: u64,
    /// Wall time of the image, seconds (without preparing the solution).
    pub seconds: f64,
}

/// The final gather over a scene, its ray caster and a solution.
///
/// Per pixel, `rays` samples, each: a camera ray jittered in the pixel to the first hit in the
/// scene; the emitted radiance there when the camera sees an emitter's front; direct light by
/// the path tracer's emitter sampling (a triangle chosen by power, a point on it) with an exact
/// shadow ray, and the sun's shadow ray; indirect light from one cosine-weighted ray whose hit
/// reads the solution's radiosity minus the emitted exitance there (direct light is not
/// counted twice), times ρ/π. The camera position, gather direction, emitter and bright
/// samples take their numbers from Owen-scrambled Sobol sets (`PixelSamples`). Emission that a
/// gather ray hits is combined with the emitter sample by multiple importance sampling (power
/// heuristic, as the path tracer), which keeps emitters close to the shading point (corners)
/// from spiking. A gather ray whose hit lies within
/// [`GatherOptions::near`] element sizes is shaded there by one more such bounce instead. Rays
/// that leave the scene upwards see the sky. One-sided surfaces absorb at their back (the path
/// tracer's convention) unless the solution is two-sided.
pub struct Gatherer<'a> {
    scene: &'a Scene,
    caster: &'a RayCaster<'a>,
    sol: &'a SolutionLookup,
    half_casters: [Option<RayCaster<'a>>; 2],
    opts: GatherOptions,
    lights: Lights,
    facing: Facing,
    bright: Option<Bright>,
    eps: f32,
    up: Vec3,
    /// `GatherOptions::near` squared.
    near2: f32,
    /// Luminance Y of linear sRGB (white Y = 1).
    lum: glam::DVec3,
}

#[derive(Clone, Copy, Default)]
struct Counts {
    camera: u64,
    gather: u64,
    shadow: u64,
    lookups: u64,
    misses: u64,
    near: u64,
    cached: u64,
}

impl Counts {
    fn add(&mut self, o: &Counts) {
        self.camera += o.camera;
        self.gather += o.gather;
        self.shadow += o.shadow;
        self.lookups += o.lookups;
        self.misses += o.misses;
        self.near += o.near;
        self.cached += o.cached;
    }
}

/// The random numbers of the samples of one pixel: three Owen-scrambled Sobol point sets
/// (the first `n` points of the 4D sequence, their values scrambled by a hash per pixel and
/// set: Burley 2020, `sobol_burley`), each spread over the dimensions of one integrand
/// together (nets of the sizes the test checks): the position in the pixel with the gather
/// ray's direction, the emitter's choice with the point on it, the bright element's choice
/// with the point on it. The second and third sets are visited in random orders, which
/// decorrelates the sets. Uniform numbers beyond 2¹⁶ samples (the sequences' length).
struct PixelSamples {
    /// Sequence index of sample `k` in the second and third sets.
    order: [Vec<u32>; 2],
    /// Per set, the four lanes' scramble keys.
    scramble: [Int4; 3],
    /// Whether the third set (bright elements) is drawn (its numbers are not used otherwise).
    bright: bool,
    /// Whether the sets are Sobol points (at most 2¹⁶ samples).
    sobol: bool,
}

/// One sample of [`PixelSamples`].
struct PixelSample {
    jx: f32,
    jy: f32,
    ud: (f32, f32),
    upick: f64,
    ul: (f32, f32),
    ub: (f64, (f32, f32)),
}

impl PixelSamples {
    /// The point sets of `n` samples, drawn from `rng`.
    fn new(n: u32, bright: bool, rng: &mut SplitMix64) -> Self {
        let sobol = n <= 1 << 16;
        let order = [true, bright].map(|drawn| {
            let mut p: Vec<u32> = Vec::new();
            if drawn && sobol {
                p.extend(0..n);
                shuffle(&mut p, rng);
            }
            p
        });
        let scramble = [(); 3].map(|_| {
            let s = rng.next_u64() as u32;
            // Per-lane keys as `sobol_burley::sample_4d` forms them from a seed.
            let key = [0x912f_69ba, 0x174f_18ab, 0x691e_72ca, 0xb40c_c1b8].map(|d: u32| d ^ s);
            hash_int4(key.into())
        });
        PixelSamples {
            order,
            scramble,
            bright,
            sobol,
        }
    }

    /// Sample `k` (< `n`).
    #[inline]
    fn get(&self, k: u32, rng: &mut SplitMix64) -> PixelSample {
        let point = |s: usize, i: u32| -> [u32; 4] {
            owen_scramble_int4_rev(sobol_int4_rev(i.reverse_bits(), 0), self.scramble[s])
                .reverse_bits()
                .into()
        };
        let [a, b, c] = if self.sobol {
            let c = if self.bright {
                point(2, self.order[1][k as usize])
            } else {
                [0; 4]
            };
            [point(0, k), point(1, self.order[0][k as usize]), c]
        } else {
            [(); 3].map(|_| [(); 4].map(|_| rng.next_u64() as u32))
        };
        // Coordinates from the top 24 bits (exact in f32, below 1); the choices take all 32,
        // since they split their number among many triangles.
        let f = |x: u32| (x >> 8) as f32 * (1.0 / 16_777_216.0);
        let pick = |x: u32| x as f64 * (1.0 / 4_294_967_296.0);
        PixelSample {
            jx: f(a[0]),
            jy: f(a[1]),
            ud: (f(a[2]), f(a[3])),
            upick: pick(b[2]),
            ul: (f(b[0]), f(b[1])),
            ub: (pick(c[2]), (f(c[0]), f(c[1]))),
        }
    }
}

/// Shuffle `p` in place (Fisher–Yates, from the last entry down).
fn shuffle(p: &mut [u32], rng: &mut SplitMix64) {
    for i in (1..p.len()).rev() {
        // Multiply-shift (Lemire): a bias below 2⁻³² · len, without a division.
        let j = (((rng.next_u64() >> 32) * (i as u64 + 1)) >> 32) as usize;
        p.swap(i, j);
    }
}

/// `(i + jitter) / n` strata of a `a × b` grid for sample `k` (samples beyond the grid are
/// uniform).
#[inline]
fn stratum(k: u32, a: u32, b: u32, rng: &mut SplitMix64) -> (f32, f32) {
    let (r1, r2) = (rng.next_f32(), rng.next_f32());
    if k < a * b {
        (
            ((k % a) as f32 + r1) / a as f32,
            ((k / a) as f32 + r2) / b as f32,
        )
    } else {
        (r1, r2)
    }
}

impl<'a> Gatherer<'a> {
    /// Prepare the light distribution and the solution's casters.
    pub fn new(
        scene: &'a Scene,
        caster: &'a RayCaster<'a>,
        sol: &'a SolutionLookup,
        opts: &GatherOptions,
    ) -> Self {
        let half_casters = [0, 1].map(|h| {
            sol.halves[h]
                .as_ref()
                .map(|m| RayCaster::new(&m.scene, &m.tree))
        });
        let facing = Facing::new(scene, caster.tree);
        let bright = if opts.bright > 0.0 {
            Bright::new(sol, scene, caster, &facing, opts.bright)
        } else {
            None
        };
        Gatherer {
            scene,
            caster,
            sol,
            half_casters,
            opts: opts.clone(),
            lights: Lights::new(scene),
            facing,
            bright,
            eps: surface_eps(scene),
            up: scene.up.vector(),
            near2: opts.near * opts.near,
            lum: crate::metrics::srgb_to_xyz_matrix().row(1),
        }
    }

    /// The closest hit in the scene for `t ∈ [0, tmax]`, the face of coincident ones that
    /// faces the ray ([`Facing`]).
    fn closest(&self, o: Vec3, d: Vec3, tmax: f32) -> Option<Hit> {
        let h = self.caster.closest(o, d, 0.0, tmax)?;
        Some(self.facing.resolve(self.scene, self.caster, (o, d), h))
    }

    /// Radiosity B (W/m²) of the solution at point `q` of a surface, on the side whose normal
    /// is `n`, the density per unit area of a bright sample there and the area of the element
    /// found; `None` when no element is there.
    fn radiosity(&self, q: Vec3, n: Vec3, cnt: &mut Counts) -> Option<(Vec3, f32, f32)> {
        cnt.lookups += 1;
        let h = if n.dot(SPLIT) > 0.0 { 0 } else { 1 };
        let (Some(c), Some(m)) = (&self.half_casters[h], &self.sol.halves[h]) else {
            cnt.misses += 1;
            return None;
        };
        let d = self.sol.delta;
        for k in [1.0f32, 20.0] {
            if let Some(hit) = c.closest(q + n * (d * k), -n, 0.0, 2.0 * d * k) {
                let col = &m.colors[hit.tri as usize];
                let pdf = self
                    .bright
                    .as_ref()
                    .map_or(0.0, |b| b.pdf_area[h][hit.tri as usize]);
                return Some((
                    col[0] * (1.0 - hit.u - hit.v) + col[1] * hit.u + col[2] * hit.v,
                    pdf,
                    m.scene.areas[hit.tri as usize],
                ));
            }
        }
        cnt.misses += 1;
        None
    }

    /// Radiance reflected at `x` (already offset off the surface) of normal `n` and
    /// reflectance `rho`: [`Self::direct`] + ρ × [`Self::incident`].
    #[allow(clippy::too_many_arguments)]
    fn reflected(
        &self,
        x: Vec3,
        n: Vec3,
        rho: Vec3,
        upick: f64,
        ul: (f32, f32),
        ud: (f32, f32),
        ub: (f64, (f32, f32)),
        depth: u32,
        rng: &mut SplitMix64,
        cnt: &mut Counts,
    ) -> Vec3 {
        let (l, b, _) = self.incident(x, n, ud, ub, depth, true, rng, cnt);
        self.direct(x, n, rho, &[(upick, ul)], true, cnt) + rho * l + rho * b
    }

    /// Direct light reflected at `x` of normal `n` and reflectance `rho`: ρ/π × the irradiance
    /// from the emitters (the mean of one emitter sample per `(pick, point)` of `samples`) and
    /// the sun. With `mis` an emitter sample is weighted against the gather rays' emission
    /// hits, without it the samples stand for all direct light.
    #[allow(clippy::too_many_arguments)]
    fn direct(
        &self,
        x: Vec3,
        n: Vec3,
        rho: Vec3,
        samples: &[(f64, (f32, f32))],
        mis: bool,
        cnt: &mut Counts,
    ) -> Vec3 {
        let scene = self.scene;
        let mut e = Vec3::ZERO; // irradiance estimate
        if !self.lights.is_empty() {
            for &(upick, ul) in samples {
                let lt = self.lights.pick(upick);
                let s = ul.0.sqrt();
                let u2 = ul.1;
                let y = lt.a * (1.0 - s) + lt.b * (s * (1.0 - u2)) + lt.c * (s * u2);
                let to = y - x;
                let dist2 = to.length_squared();
                if dist2 <= 0.0 {
                    continue;
                }
                let w = to / dist2.sqrt();
                let cos_x = n.dot(w);
                let cos_y = -lt.normal.dot(w);
                if cos_x > 0.0 && cos_y > 0.0 {
                    cnt.shadow += 1;
                    if !self.caster.occluded(x, to, 0.0, 1.0 - 1e-4)
                        && self.facing.sees(scene, self.caster, (x, to), lt.tri)
                    {
                        let pdf_light = lt.pdf_area * dist2 / cos_y;
                        let w = if mis {
                            power_heuristic(pdf_light, cos_x / PI)
                        } else {
                            1.0
                        };
                        e += lt.emission * (cos_x * cos_y / (dist2 * lt.pdf_area) * w);
                    }
                }
            }
            e /= samples.len().max(1) as f32;
        }
        if let Some(sun) = scene.sun {
            let cos = n.dot(sun.direction);
            if cos > 0.0 {
                cnt.shadow += 1;
                if !self.caster.occluded(x, sun.direction, 0.0, f32::INFINITY) {
                    e += sun.irradiance * cos;
                }
            }
        }
        rho * e / PI
    }

    /// One sample of the indirect light at `x` of normal `n`: the radiance of one
    /// cosine-weighted gather ray `ud` (the solution's reflected radiosity at its hit, emission
    /// hit weighted against the emitter sample) and one sample of the bright elements `ub`,
    /// whose sum times ρ estimates the reflected indirect radiance; and the gather ray's hit
    /// distance (infinite when it leaves the scene). Emission the gather ray hits counts only
    /// with `emission` (weighted against the emitter sample at `x`). At `depth` 0 a near hit
    /// ([`GatherOptions::near`]) is shaded by [`Self::reflected`] at depth 1, with samples
    /// drawn from `rng`.
    #[allow(clippy::too_many_arguments)]
    fn incident(
        &self,
        x: Vec3,
        n: Vec3,
        ud: (f32, f32),
        ub: (f64, (f32, f32)),
        depth: u32,
        emission: bool,
        rng: &mut SplitMix64,
        cnt: &mut Counts,
    ) -> (Vec3, Vec3, f32) {
        let Some((l, t)) = self.gather_ray(x, n, ud, depth, emission, rng, cnt) else {
            return (Vec3::ZERO, Vec3::ZERO, f32::INFINITY);
        };
        let bright = match &self.bright {
            Some(br) => self.bright_sample(x, n, br, ub, cnt),
            None => Vec3::ZERO,
        };
        (l, bright, t)
    }

    /// The gather ray of [`Self::incident`]: its radiance and hit distance; `None` for a
    /// direction in the surface's plane.
    #[allow(clippy::too_many_arguments)]
    fn gather_ray(
        &self,
        x: Vec3,
        n: Vec3,
        ud: (f32, f32),
        depth: u32,
        emission: bool,
        rng: &mut SplitMix64,
        cnt: &mut Counts,
    ) -> Option<(Vec3, f32)> {
        let scene = self.scene;
        let mut out = Vec3::ZERO;
        // Indirect: the cosine-weighted estimator of ρ/π ∫ L cos dω is ρ·L.
        let (d, cos) = cosine_sample(n, ud.0, ud.1);
        if cos <= 0.0 {
            return None;
        }
        cnt.gather += 1;
        let Some(h) = self.closest(x, d, f32::INFINITY) else {
            if let Some(sky) = scene.sky {
                if d.dot(self.up) > 0.0 {
                    out += sky;
                }
            }
            return Some((out, f32::INFINITY));
        };
        let tri = h.tri as usize;
        let ng = scene.normals[tri];
        let front = ng.dot(d) < 0.0;
        if !front && !scene.has_back(tri, self.opts.two_sided) {
            return Some((out, h.t));
        }
        let mat = scene.material_of(tri);
        let ns = if front { ng } else { -ng };
        let q = x + d * h.t;
        // Emission hit by the gather ray: its multiple-importance weight against the emitter
        // sample.
        if emission && front && mat.is_emitter() {
            let pdf_light = self.lights.pdf_area[tri] * h.t * h.t / -ng.dot(d);
            out += mat.emission * power_heuristic(cos / PI, pdf_light);
        }
        // The solution's reflected radiosity there, weighted against the bright elements'
        // sample when it is one of them.
        if let Some((b, pdf_b, area)) = self.radiosity(q, ns, cnt) {
            let emitted = if front { mat.emission * PI } else { Vec3::ZERO };
            let near = depth == 0 && h.t * h.t < self.near2 * area;
            let w = if pdf_b > 0.0 {
                let pdf_sa = pdf_b * h.t * h.t / ns.dot(d).abs().max(1e-12);
                power_heuristic(cos / PI, pdf_sa)
            } else {
                1.0
            };
            if near && mat.rho.max_element() > 0.0 {
                cnt.near += 1;
                let qo = q + ns * self.eps;
                let r2 = |rng: &mut SplitMix64| (rng.next_f32(), rng.next_f32());
                let (upick2, ul2, ud2) = (rng.next_f64(), r2(rng), r2(rng));
                let ub2 = (rng.next_f64(), r2(rng));
                out += self.reflected(qo, ns, mat.rho, upick2, ul2, ud2, ub2, 1, rng, cnt) * w;
            } else {
                out += (b - emitted).max(Vec3::ZERO) / PI * w;
            }
        }
        Some((out, h.t))
    }

    /// `n` samples of pixel `(x, y)` drawn from `rng`: their mean and the spread of their
    /// luminance.
    #[allow(clippy::too_many_arguments)]
    fn pixel(
        &self,
        frame: &CameraFrame,
        cache: Option<&Cache>,
        x: usize,
        y: usize,
        n: u32,
        mut rng: SplitMix64,
        cnt: &mut Counts,
    ) -> (Vec3, Spread) {
        let scene = self.scene;
        let samples = PixelSamples::new(n, self.bright.is_some(), &mut rng);
        let (mut sum, mut sum_y, mut sum_y2) = (DVec3::ZERO, 0.0f64, 0.0f64);
        for k in 0..n {
            let PixelSample {
                jx,
                jy,
                ud,
                upick,
                ul,
                ub,
            } = samples.get(k, &mut rng);
            let d = frame.direction(x as f32 + jx, y as f32 + jy).normalize();
            cnt.camera += 1;
            let Some(h) = self.closest(frame.eye, d, f32::INFINITY) else {
                continue;
            };
            let tri = h.tri as usize;
            let ng = scene.normals[tri];
            let front = ng.dot(d) < 0.0;
            let mat = scene.material_of(tri);
            let mut l = Vec3::ZERO;
            if front {
                l += mat.emission;
            } else if !scene.has_back(tri, self.opts.two_sided) {
                continue;
            }
            if mat.rho.max_element() > 0.0 {
                let ns = if front { ng } else { -ng };
                let q = frame.eye + d * h.t;
                let p = q + ns * self.eps;
                let (sx, sy) = (x as f32 + jx, y as f32 + jy);
                l += match cache.and_then(|c| c.lookup(q, ns, sx, sy)) {
                    Some(li) => {
                        cnt.cached += 1;
                        // The gather ray it does not cast pays for a second emitter sample,
                        // the first one's strata shifted by half.
                        let half = |u: f32| (u + 0.5).fract();
                        let second = ((upick + 0.5).fract(), (half(ul.0), half(ul.1)));
                        let emitters = [(upick, ul), second];
                        self.direct(p, ns, mat.rho, &emitters, false, cnt) + mat.rho * li
                    }
                    None => self.reflected(p, ns, mat.rho, upick, ul, ud, ub, 0, &mut rng, cnt),
                };
            }
            let l = l.as_dvec3();
            let lum = self.lum.dot(l.max(DVec3::ZERO));
            sum += l;
            sum_y += lum;
            sum_y2 += lum * lum;
        }
        let mean_y = sum_y / n as f64;
        let spread = Spread {
            mean: mean_y as f32,
            std: (sum_y2 / n as f64 - mean_y * mean_y).max(0.0).sqrt() as f32,
        };
        ((sum / n as f64).as_vec3(), spread)
    }

    /// Render an image.
    pub fn render(
        &self,
        view: &CameraView,
        progress: &dyn Progress,
        cancel: Option<&AtomicBool>,
    ) -> Result<(Image, GatherStats)> {
        view.validate()?;
        if self.opts.rays == 0 {
            return Err(Error::Config("gather rays must be at least 1".into()));
        }
        if !(self.opts.near >= 0.0 && self.opts.near.is_finite()) {
            return Err(Error::Config(format!(
                "gather near factor {} must be a number >= 0",
                self.opts.near
            )));
        }
        if self.opts.bright.is_nan() || self.opts.bright < 0.0 {
            return Err(Error::Config(format!(
                "gather bright factor {} must be >= 0",
                self.opts.bright
            )));
        }
        if !(self.opts.adaptive >= 0.0 && self.opts.adaptive.is_finite()) {
            return Err(Error::Config(format!(
                "gather adaptive share {} must be a number >= 0",
                self.opts.adaptive
            )));
        }
        let t0 = std::time::Instant::now();
        let frame = view.frame();
        let w = view.width as usize;
        let mut img = Image::new(view.width, view.height, Vec3::ZERO);
        let mut pre = Counts::default();
        let cache = if self.opts.cache > 0 {
            Some(Cache::build(
                self,
                &frame,
                view.width,
                view.height,
                self.opts.cache,
                progress,
                cancel,
                &mut pre,
            )?)
        } else {
            None
        };
        let n = self.opts.rays;
        let mut first = vec![(Vec3::ZERO, Spread::default()); img.pixels.len()];
        let mut counts: Vec<Counts> =
            render_rows(&mut first, w, "gather", progress, cancel, |x, y, cnt| {
                let rng = SplitMix64::for_item(self.opts.seed, (y * w + x) as u64);
                self.pixel(&frame, cache.as_ref(), x, y, n, rng, cnt)
            })?;
        counts.push(pre);
        for (px, (c, _)) in img.pixels.iter_mut().zip(&first) {
            *px = *c;
        }
        let spread: Vec<Spread> = first.iter().map(|(_, s)| *s).collect();
        // Adaptive sampling: more samples where the neighbours' samples spread most, drawn
        // from generators of their own and averaged with the first by count.
        let extra = adaptive::allocate(
            w,
            view.height as usize,
            n,
            self.opts.adaptive as f64,
            &spread,
            crate::metrics::white_luminance(&img),
        );
        drop(spread);
        let (adaptive_samples, adaptive_pixels) = (
            extra.iter().map(|&m| m as u64).sum::<u64>(),
            extra.iter().filter(|&&m| m > 0).count() as u64,
        );
        if adaptive_pixels > 0 {
            counts.extend(render_rows(
                &mut img.pixels,
                w,
                "gather (adaptive)",
                progress,
                cancel,
                |x, y, cnt| {
                    let i = y * w + x;
                    let (m, c1) = (extra[i], first[i].0);
                    if m == 0 {
                        return c1;
                    }
                    let rng = SplitMix64::for_item(self.opts.seed ^ adaptive::SEED_TAG, i as u64);
                    let (c, _) = self.pixel(&frame, cache.as_ref(), x, y, m, rng, cnt);
                    (c1 * n as f32 + c * m as f32) / (n + m) as f32
                },
            )?);
        }
        let sum = |f: fn(&Counts) -> u64| counts.iter().map(f).sum::<u64>();
        let stats = GatherStats {
            camera_rays: sum(|c| c.camera),
            gather_rays: sum(|c| c.gather),
            shadow_rays: sum(|c| c.shadow),
            lookups: sum(|c| c.lookups),
            lookup_misses: sum(|c| c.misses),
            near: sum(|c| c.near),
            bright_triangles: self.bright.as_ref().map_or(0, |b| b.tris.len() as u64),
            cache_points: cache.as_ref().map_or(0, |c| c.len() as u64),
            cached: sum(|c| c.cached),
            adaptive_samples,
            adaptive_pixels,
            seconds: t0.elapsed().as_secs_f64(),
        };
        tracing::info!(
            "gather: {} camera rays, {} gather rays ({} near), {} cache points ({} samples cached), \
             {} adaptive samples in {} pixels, {} shadow rays, {} look-ups ({} missed) in {:.2} s",
            stats.camera_rays,
            stats.gather_rays,
            stats.near,
            stats.cache_points,
            stats.cached,
            stats.adaptive_samples,
            stats.adaptive_pixels,
            stats.shadow_rays,
            stats.lookups,
            stats.lookup_misses,
            stats.seconds
        );
        Ok((img, stats))
    }
}

/// Match `mesh` to `scene`, then gather an image of it from `view`.
pub fn render_gather(
    scene: &Scene,
    caster: &RayCaster,
    mesh: &ColoredMesh,
    view: &CameraView,
    opts: &GatherOptions,
    progress: &dyn Progress,
    cancel: Option<&AtomicBool>,
) -> Result<(Image, GatherStats)> {
    let sol = SolutionLookup::new(mesh, scene, caster, opts.lookup)?;
    Gatherer::new(scene, caster, &sol, opts).render(view, progress, cancel)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Whether the points `p` (of a power-of-two count `n = 2^m`) form a (t, m, 2)-net: every
    /// box `[i/2^a, (i+1)/2^a) × [j/2^b, (j+1)/2^b)` with `a + b = m − t` holds exactly `2^t`.
    fn is_net(p: &[(f32, f32)], t: u32) -> bool {
        let m = p.len().trailing_zeros() - t;
        (0..=m).all(|a| {
            let b = m - a;
            let mut count = vec![0u32; 1 << m];
            for &(x, y) in p {
                let i = (x * (1u32 << a) as f32) as usize;
                let j = (y * (1u32 << b) as f32) as usize;
                count[(i << b) | j] += 1;
            }
            count.iter().all(|&c| c == 1 << t)
        })
    }

    #[test]
    fn pixel_samples_are_stratified_per_integrand() {
        let mut rng = SplitMix64::new(5);
        for n in [16u32, 64, 256] {
            let s = PixelSamples::new(n, true, &mut rng);
            let all: Vec<PixelSample> = (0..n).map(|k| s.get(k, &mut rng)).collect();
            let pixel: Vec<_> = all.iter().map(|p| (p.jx, p.jy)).collect();
            let gather: Vec<_> = all.iter().map(|p| p.ud).collect();
            let light: Vec<_> = all.iter().map(|p| p.ul).collect();
            let bright: Vec<_> = all.iter().map(|p| p.ub.1).collect();
            for (name, set, t) in [
                ("pixel", &pixel, 0),
                ("gather", &gather, 1),
                ("light", &light, 0),
                ("bright", &bright, 0),
            ] {
                assert!(
                    is_net(set, t),
                    "{name} points of {n} samples: not a ({t}, m, 2)-net"
                );
            }
            // The emitter's choice: one sample in each of the n strata alone, and stratified
            // jointly with the point on the emitter (a (1, m, 2)-net with its first coordinate).
            let mut strata: Vec<u32> = all.iter().map(|p| (p.upick * n as f64) as u32).collect();
            strata.sort_unstable();
            assert!(
                strata.iter().copied().eq(0..n),
                "light choice of {n} samples"
            );
            // (Rounded down to 24 bits, so that the f32 stays below 1.)
            let down = |u: f64| ((u * 16_777_216.0).floor() / 16_777_216.0) as f32;
            let pick: Vec<_> = all.iter().map(|p| (down(p.upick), p.ul.0)).collect();
            assert!(is_net(&pick, 1), "light choice and point of {n} samples");
            // The gather direction is not the pixel position again, and the second and third
            // sets are visited in random orders (permutations, not the sequence's).
            assert!(pixel.iter().zip(&gather).any(|(a, b)| a != b));
            for order in &s.order {
                let mut sorted = order.clone();
                sorted.sort_unstable();
                assert!(sorted.iter().copied().eq(0..n) && !order.iter().copied().eq(0..n));
            }
        }
        // Beyond the sequences' length: uniform numbers in [0, 1).
        let s = PixelSamples::new((1 << 16) + 1, false, &mut rng);
        let p = s.get(0, &mut rng);
        assert!((0.0..1.0).contains(&p.jx) && (0.0..1.0).contains(&p.upick));
    }
}
