//! Final gather: images of a radiosity solution as sharp as a path tracer's, without its noise
//! in indirect light (the two-pass method of RenderPark and its kind).
//!
//! Per pixel, `rays` samples, each: a camera ray jittered in the pixel (stratified) to the first
//! hit in the scene; the emitted radiance there when the camera sees an emitter's front; direct
//! light by the path tracer's emitter sampling (a triangle chosen by power, a point on it, both
//! stratified) with an exact shadow ray, and the sun's shadow ray; indirect light from one
//! cosine-weighted ray (the samples' directions stratified over the hemisphere) whose hit reads
//! the solution's radiosity minus the emitted exitance there (direct light is not counted
//! twice), times ρ/π. Emission that a gather ray hits is combined with the emitter sample by
//! multiple importance sampling (power heuristic, as the path tracer), which keeps emitters
//! close to the shading point (corners) from spiking. Rays that leave the scene upwards see the
//! sky. One-sided surfaces absorb at their back (the path tracer's convention) unless the
//! solution is two-sided.
//!
//! The solution is the mesh `solve` writes (`solution.glb`: leaf elements with per-vertex
//! radiosity B). [`SolutionLookup`] checks that its triangles lie on the scene's surfaces (one
//! short ray per triangle, which also tells a two-sided solution by its back-face copies) and
//! builds a ray accelerator over each half of it (split by the sign of the normal along a
//! generic direction, so that coinciding triangles facing opposite ways never share one). A
//! gather ray is cast against the scene (exact geometry and materials, as the path tracer's);
//! its hit point then finds its element by a short ray along the normal of the side it was hit
//! on, into the half of the mesh facing that way, and reads B
//! interpolated from the vertices (what the per-vertex image shows) or the triangle's mean
//! ([`Lookup`]). So a `.glb` and the scene are enough: nothing is solved again.
//!
//! Importance to bright elements ([`GatherOptions::bright`], on by default): solution triangles
//! far brighter than the mean (lamp housings, lit patches next to a lamp) are also sampled by
//! area (stratified as the emitter samples) with a shadow ray, combined with the gather rays by multiple importance sampling; on
//! graz_office it halves the gather's noise at the same time. Measured and left out: shading
//! close hits by one more bounce instead of the solution (no gain on office or graz_office,
//! `docs/perf-log.md` 2026-12-03 (6)).
//!
//! Each pixel draws from its own generator `SplitMix64::for_item(seed, y·width + x)`; rows are
//! rendered in parallel and the image does not depend on the number of threads.

use super::camera::{CameraFrame, CameraView};
use super::image::{render_rows, Image};
use super::pathtrace::{alias_table, cosine_sample, power_heuristic, surface_eps, Lights};
use glam::{DVec3, Vec3};
use hirad_accel::cluster::{ClusterConfig, ClusterTree, Strategy};
use hirad_accel::ray::RayCaster;
use hirad_core::progress::Progress;
use hirad_core::rng::SplitMix64;
use hirad_core::{Error, Result};
use hirad_scene::export::ColoredMesh;
use hirad_scene::{Material, RawScene, Scene, SceneOptions};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::f32::consts::PI;
use std::sync::atomic::AtomicBool;

/// How a gather ray reads the solution at its hit.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub enum Lookup {
    /// Radiosity interpolated from the mesh's vertex values (as the per-vertex image).
    Vertex,
    /// The mean of the hit triangle's vertex values (the element constant; the default: as
    /// good on office, closer to the path tracer on graz_office).
    #[default]
    Element,
}

impl Lookup {
    /// Parse `vertex` or `element`.
    pub fn parse(s: &str) -> Result<Lookup> {
        match s.trim().to_ascii_lowercase().as_str() {
            "vertex" => Ok(Lookup::Vertex),
            "element" => Ok(Lookup::Element),
            _ => Err(Error::Config(format!(
                "gather lookup: vertex or element, got '{s}'"
            ))),
        }
    }
}

/// Settings of the final gather.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct GatherOptions {
    /// Samples per pixel: camera rays, light samples and gather rays (one each per sample).
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
}

impl Default for GatherOptions {
    fn default() -> Self {
        Self {
            rays: 64,
            seed: 1,
            two_sided: false,
            lookup: Lookup::Element,
            bright: 16.0,
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
    /// Solution triangles sampled as bright elements ([`GatherOptions::bright`]).
    pub bright_triangles: u64,
    /// Wall time of the image, seconds (without preparing the solution).
    pub seconds: f64,
}

/// Generic direction that splits the solution's triangles into two halves by the sign of
/// `normal · SPLIT`: two coinciding triangles facing opposite ways (the back-face copies of
/// two-sided solutions, or back-to-back surfaces) never share a half, so a look-up ray along a
/// normal finds the element facing it. No axis-aligned or common normal is perpendicular to it.
const SPLIT: Vec3 = Vec3::new(0.267_261_24, 0.534_522_5, 0.801_783_7);

/// One half of the solution mesh, as a scene of its own with an accelerator.
struct HalfMesh {
    scene: Scene,
    tree: ClusterTree,
    /// Per triangle: the radiosity at its three vertices.
    colors: Vec<[Vec3; 3]>,
}

/// A solution mesh (leaf elements with per-vertex radiosity B, W/m²) matched to its scene and
/// prepared for look-ups by point.
pub struct SolutionLookup {
    /// Triangles whose normal has a positive (index 0) or negative (1) component along
    /// [`SPLIT`].
    halves: [Option<HalfMesh>; 2],
    /// Half length of the look-up rays (scene units).
    delta: f32,
    /// Solution triangles on the front of a scene surface.
    pub front: usize,
    /// Solution triangles on the back of a scene surface only (back-face copies).
    pub back: usize,
    /// Solution triangles under which no scene surface was found.
    pub unmatched: usize,
    /// Solution triangles of zero area (left out).
    pub degenerate: usize,
}

impl SolutionLookup {
    /// Match the solution mesh `mesh` to `scene` (whose ray caster is `caster`) and build the
    /// look-up structures. Fails when most of the mesh lies on no surface of the scene (a
    /// solution of another scene).
    pub fn new(
        mesh: &ColoredMesh,
        scene: &Scene,
        caster: &RayCaster,
        lookup: Lookup,
    ) -> Result<Self> {
        let nv = mesh.positions.len();
        if mesh.colors.len() != nv {
            return Err(Error::Config(format!(
                "solution mesh has {} colours for {nv} vertices",
                mesh.colors.len()
            )));
        }
        if let Some(t) = mesh
            .triangles
            .iter()
            .find(|t| t.iter().any(|&v| v as usize >= nv))
        {
            return Err(Error::Config(format!(
                "solution triangle {t:?} uses a vertex out of range ({nv} vertices)"
            )));
        }
        let delta = 5.0 * surface_eps(scene);
        // Per triangle: 0 front of a scene surface, 1 back only, 2 degenerate, 3 on no surface.
        let class: Vec<u8> = mesh
            .triangles
            .par_iter()
            .map(|t| {
                let [a, b, c] = t.map(|v| mesh.positions[v as usize]);
                let cr = (b - a).cross(c - a);
                let area = 0.5 * cr.length();
                if area.is_nan() || area <= 0.0 || !cr.normalize_or_zero().is_normalized() {
                    return 2;
                }
                let n = cr.normalize();
                let centroid = (a + b + c) / 3.0;
                let facing_away = |tri: u32| scene.normals[tri as usize].dot(n) <= 0.0;
                for k in [1.0f32, 20.0] {
                    let o = centroid + n * (delta * k);
                    let span = (0.0, 2.0 * delta * k);
                    if caster.occluded_except(o, -n, span, &facing_away) {
                        return 0;
                    }
                    if caster.occluded(o, -n, span.0, span.1) {
                        return 1;
                    }
                }
                3
            })
            .collect();
        let count = |s: u8| class.iter().filter(|&&x| x == s).count();
        let (front, back, degenerate, unmatched) = (count(0), count(1), count(2), count(3));
        let good = mesh.triangles.len() - degenerate;
        if good == 0 || unmatched * 2 > good {
            return Err(Error::Config(format!(
                "the solution does not fit the scene: {unmatched} of {good} solution triangles \
                 lie on no surface of '{}'",
                scene.name
            )));
        }
        if unmatched > 0 {
            tracing::warn!(
                "gather: {unmatched} of {good} solution triangles lie on no surface of the scene"
            );
        }
        let mut halves: [Option<HalfMesh>; 2] = [None, None];
        for (h, slot) in halves.iter_mut().enumerate() {
            let triangles: Vec<[u32; 3]> = mesh
                .triangles
                .iter()
                .zip(&class)
                .filter(|&(t, &c)| {
                    if c == 2 {
                        return false;
                    }
                    let [a, b, c] = t.map(|v| mesh.positions[v as usize]);
                    ((b - a).cross(c - a).dot(SPLIT) > 0.0) == (h == 0)
                })
                .map(|(t, _)| *t)
                .collect();
            if triangles.is_empty() {
                continue;
            }
            let colors: Vec<[Vec3; 3]> = triangles
                .iter()
                .map(|t| {
                    let c = t.map(|v| mesh.colors[v as usize]);
                    match lookup {
                        Lookup::Vertex => c,
                        Lookup::Element => [(c[0] + c[1] + c[2]) / 3.0; 3],
                    }
                })
                .collect();
            let n = triangles.len();
            let raw = RawScene {
                name: format!("{} solution half {h}", scene.name),
                positions: mesh.positions.clone(),
                triangles,
                tri_material: vec![0; n],
                tri_object: vec![0; n],
                objects: Vec::new(),
                materials: vec![Material::diffuse("solution", Vec3::ZERO)],
                up: scene.up,
                ..Default::default()
            };
            let sub = Scene::from_raw(raw, &SceneOptions::default())?;
            if sub.num_triangles() != n {
                return Err(Error::Config(format!(
                    "solution half {h}: {} of {n} triangles kept",
                    sub.num_triangles()
                )));
            }
            let tree = ClusterTree::build(&sub, Strategy::Sah, &ClusterConfig::default());
            *slot = Some(HalfMesh {
                scene: sub,
                tree,
                colors,
            });
        }
        Ok(SolutionLookup {
            halves,
            delta,
            front,
            back,
            unmatched,
            degenerate,
        })
    }

    /// True when the solution has back-face elements (a two-sided solve): at least a quarter
    /// of its triangles lie on the back of a scene surface only. (A one-sided solve has such
    /// triangles only where the scene has back-to-back surfaces.)
    pub fn has_back_faces(&self) -> bool {
        self.back * 4 >= self.front + self.back
    }
}

/// The final gather over a scene, its ray caster and a solution.
pub struct Gatherer<'a> {
    scene: &'a Scene,
    caster: &'a RayCaster<'a>,
    sol: &'a SolutionLookup,
    half_casters: [Option<RayCaster<'a>>; 2],
    opts: GatherOptions,
    lights: Lights,
    bright: Option<Bright>,
    eps: f32,
    up: Vec3,
}

/// Bright solution triangles, sampled by area with probability proportional to their
/// reflected power `A · mean(B − E)`.
struct Bright {
    tris: Vec<BrightTri>,
    prob: Vec<f64>,
    alias: Vec<u32>,
    /// Per half of the solution mesh, per triangle: density per unit area of a bright sample
    /// on it (0 when not bright).
    pdf_area: [Vec<f32>; 2],
}

#[derive(Clone, Copy)]
struct BrightTri {
    p: [Vec3; 3],
    normal: Vec3,
    colors: [Vec3; 3],
    pdf_area: f32,
}

impl Bright {
    /// The bright triangles of `sol`: reflected radiosity above `factor` × the area-weighted
    /// mean; `None` when there are none.
    fn new(sol: &SolutionLookup, scene: &Scene, caster: &RayCaster, factor: f32) -> Option<Bright> {
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
                        let emitted = match caster.closest(o, -n, 0.0, 2.0 * sol.delta) {
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
    fn pick(&self, u: f64) -> &BrightTri {
        let n = self.tris.len();
        let x = u * n as f64;
        let i = (x as usize).min(n - 1);
        if x - (i as f64) < self.prob[i] {
            &self.tris[i]
        } else {
            &self.tris[self.alias[i] as usize]
        }
    }
}

#[derive(Clone, Copy, Default)]
struct Counts {
    camera: u64,
    gather: u64,
    shadow: u64,
    lookups: u64,
    misses: u64,
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
        let bright = if opts.bright > 0.0 {
            Bright::new(sol, scene, caster, opts.bright)
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
            bright,
            eps: surface_eps(scene),
            up: scene.up.vector(),
        }
    }

    /// Radiosity B (W/m²) of the solution at point `q` of a surface, on the side whose normal
    /// is `n`, and the density per unit area of a bright sample there; `None` when no element
    /// is there.
    fn radiosity(&self, q: Vec3, n: Vec3, cnt: &mut Counts) -> Option<(Vec3, f32)> {
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
                ));
            }
        }
        cnt.misses += 1;
        None
    }

    /// Radiance reflected at `x` (already offset off the surface) of normal `n` and
    /// reflectance `rho`: ρ/π × (direct irradiance from one emitter sample `ul` and the sun +
    /// indirect irradiance from one cosine-weighted gather ray `ud`, and one sample of the bright
    /// elements).
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
        cnt: &mut Counts,
    ) -> Vec3 {
        let scene = self.scene;
        let mut e = Vec3::ZERO; // irradiance estimate
        if !self.lights.is_empty() {
            let lt = self.lights.pick(upick);
            let s = ul.0.sqrt();
            let u2 = ul.1;
            let y = lt.a * (1.0 - s) + lt.b * (s * (1.0 - u2)) + lt.c * (s * u2);
            let to = y - x;
            let dist2 = to.length_squared();
            if dist2 > 0.0 {
                let w = to / dist2.sqrt();
                let cos_x = n.dot(w);
                let cos_y = -lt.normal.dot(w);
                if cos_x > 0.0 && cos_y > 0.0 {
                    cnt.shadow += 1;
                    if !self.caster.occluded(x, to, 0.0, 1.0 - 1e-4) {
                        let pdf_light = lt.pdf_area * dist2 / cos_y;
                        let w = power_heuristic(pdf_light, cos_x / PI);
                        e += lt.emission * (cos_x * cos_y / (dist2 * lt.pdf_area) * w);
                    }
                }
            }
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
        let mut out = rho * e / PI;
        // Indirect: the cosine-weighted estimator of ρ/π ∫ L cos dω is ρ·L.
        let (d, cos) = cosine_sample(n, ud.0, ud.1);
        if cos <= 0.0 {
            return out;
        }
        cnt.gather += 1;
        let l_in = match self.caster.closest(x, d, 0.0, f32::INFINITY) {
            None => match scene.sky {
                Some(sky) if d.dot(self.up) > 0.0 => sky,
                _ => Vec3::ZERO,
            },
            Some(h) => {
                let tri = h.tri as usize;
                let ng = scene.normals[tri];
                let front = ng.dot(d) < 0.0;
                if !front && !self.opts.two_sided {
                    Vec3::ZERO
                } else {
                    let mat = scene.material_of(tri);
                    let ns = if front { ng } else { -ng };
                    let q = x + d * h.t;
                    // Emission hit by the gather ray: its multiple-importance weight against
                    // the emitter sample.
                    let mut l = Vec3::ZERO;
                    if front && mat.is_emitter() {
                        let pdf_light = self.lights.pdf_area[tri] * h.t * h.t / -ng.dot(d);
                        l += mat.emission * power_heuristic(cos / PI, pdf_light);
                    }
                    // The solution's reflected radiosity there, weighted against the bright
                    // elements' sample when it is one of them.
                    if let Some((b, pdf_b)) = self.radiosity(q, ns, cnt) {
                        let emitted = if front { mat.emission * PI } else { Vec3::ZERO };
                        let w = if pdf_b > 0.0 {
                            let pdf_sa = pdf_b * h.t * h.t / ns.dot(d).abs().max(1e-12);
                            power_heuristic(cos / PI, pdf_sa)
                        } else {
                            1.0
                        };
                        l += (b - emitted).max(Vec3::ZERO) / PI * w;
                    }
                    l
                }
            }
        };
        out += rho * l_in;
        if let Some(br) = &self.bright {
            out += rho * self.bright_sample(x, n, br, ub, cnt);
        }
        out
    }

    /// Radiance (before × ρ) reflected at `x` from one area sample of the bright elements,
    /// weighted against the gather ray by multiple importance sampling.
    fn bright_sample(
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
        let Some(h) = self.caster.closest(x, to, 0.0, 1.0 + 1e-3) else {
            return Vec3::ZERO;
        };
        if h.t < 1.0 - 1e-3 {
            return Vec3::ZERO;
        }
        let tri = h.tri as usize;
        let ng = self.scene.normals[tri];
        let front = ng.dot(to) < 0.0;
        if !front && !self.opts.two_sided {
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

    /// Pixel `(x, y)` of an image `w` pixels wide.
    fn pixel(&self, frame: &CameraFrame, x: usize, y: usize, w: usize, cnt: &mut Counts) -> Vec3 {
        let scene = self.scene;
        let mut rng = SplitMix64::for_item(self.opts.seed, (y * w + x) as u64);
        let n = self.opts.rays;
        let a = ((n as f64).sqrt() as u32).max(1);
        let b = n / a;
        // Independent shuffles of the strata of the pixel jitter, of the emitter choice and of
        // the point on the emitter.
        let mut perm_px: Vec<u32> = (0..n).collect();
        let mut perm_l: Vec<u32> = (0..n).collect();
        let mut perm_pick: Vec<u32> = (0..n).collect();
        let mut perm_bpick: Vec<u32> = (0..n).collect();
        let mut perm_b: Vec<u32> = (0..n).collect();
        for p in [
            &mut perm_px,
            &mut perm_l,
            &mut perm_pick,
            &mut perm_bpick,
            &mut perm_b,
        ] {
            for i in (1..n as usize).rev() {
                let j = (rng.next_u64() % (i as u64 + 1)) as usize;
                p.swap(i, j);
            }
        }
        let mut sum = DVec3::ZERO;
        for k in 0..n {
            let (jx, jy) = stratum(perm_px[k as usize], a, b, &mut rng);
            let d = frame.direction(x as f32 + jx, y as f32 + jy).normalize();
            let ul = stratum(perm_l[k as usize], a, b, &mut rng);
            let upick = (perm_pick[k as usize] as f64 + rng.next_f64()) / n as f64;
            let ud = stratum(k, a, b, &mut rng);
            let ub = (
                (perm_bpick[k as usize] as f64 + rng.next_f64()) / n as f64,
                stratum(perm_b[k as usize], a, b, &mut rng),
            );
            cnt.camera += 1;
            let Some(h) = self.caster.closest(frame.eye, d, 0.0, f32::INFINITY) else {
                continue;
            };
            let tri = h.tri as usize;
            let ng = scene.normals[tri];
            let front = ng.dot(d) < 0.0;
            let mat = scene.material_of(tri);
            let mut l = Vec3::ZERO;
            if front {
                l += mat.emission;
            } else if !self.opts.two_sided {
                continue;
            }
            if mat.rho.max_element() > 0.0 {
                let ns = if front { ng } else { -ng };
                let p = frame.eye + d * h.t + ns * self.eps;
                l += self.reflected(p, ns, mat.rho, upick, ul, ud, ub, cnt);
            }
            sum += l.as_dvec3();
        }
        (sum / n as f64).as_vec3()
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
        if self.opts.bright.is_nan() || self.opts.bright < 0.0 {
            return Err(Error::Config(format!(
                "gather bright factor {} must be >= 0",
                self.opts.bright
            )));
        }
        let t0 = std::time::Instant::now();
        let frame = view.frame();
        let w = view.width as usize;
        let mut img = Image::new(view.width, view.height, Vec3::ZERO);
        let counts: Vec<Counts> =
            render_rows(&mut img, "gather", progress, cancel, |x, y, cnt| {
                self.pixel(&frame, x, y, w, cnt)
            })?;
        let sum = |f: fn(&Counts) -> u64| counts.iter().map(f).sum::<u64>();
        let stats = GatherStats {
            camera_rays: sum(|c| c.camera),
            gather_rays: sum(|c| c.gather),
            shadow_rays: sum(|c| c.shadow),
            lookups: sum(|c| c.lookups),
            lookup_misses: sum(|c| c.misses),
            bright_triangles: self.bright.as_ref().map_or(0, |b| b.tris.len() as u64),
            seconds: t0.elapsed().as_secs_f64(),
        };
        tracing::info!(
            "gather: {} camera rays, {} gather rays, {} shadow rays, {} look-ups ({} missed) in \
             {:.2} s",
            stats.camera_rays,
            stats.gather_rays,
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
