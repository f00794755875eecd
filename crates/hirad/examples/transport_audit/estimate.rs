//! The Monte Carlo estimators the modes share: area sampling, cosine directions, direct light,
//! one path of indirect light, brute-force irradiance from a source element, visibility.
use glam::Vec3;
use hirad::radiosity::element::{Element, Elements};
use hirad::radiosity::formfactor::{point_to_polygon, sample_triangle, sample_triangle_above};
use hirad::radiosity::overlap::Covers;
use hirad::ray::RayCaster;
use hirad::render::PathTracer;
use hirad::rng::SplitMix64;
use hirad::scene::Scene;
use std::f64::consts::PI;

/// Ray origins leave their surface by this much (scene units) along the normal.
pub const OFF: f32 = 2e-6;

/// Triangles by area: draws one with probability proportional to its area.
pub struct ByArea {
    /// The triangles (or elements) to draw from.
    pub ids: Vec<u32>,
    /// Running sum of their areas.
    cdf: Vec<f64>,
}

impl ByArea {
    /// `ids` with their areas `area(id)`.
    pub fn new(ids: Vec<u32>, area: impl Fn(u32) -> f64) -> Self {
        let mut acc = 0.0;
        let cdf = ids
            .iter()
            .map(|&t| {
                acc += area(t);
                acc
            })
            .collect();
        ByArea { ids, cdf }
    }

    /// Scene triangles `ids` by their areas.
    pub fn triangles(scene: &Scene, ids: Vec<u32>) -> Self {
        ByArea::new(ids, |t| scene.areas[t as usize] as f64)
    }

    /// The scene's emitting triangles by their areas.
    pub fn emitters(scene: &Scene) -> Self {
        ByArea::triangles(scene, scene.emitters())
    }

    /// Total area.
    pub fn total(&self) -> f64 {
        self.cdf.last().copied().unwrap_or(0.0)
    }

    /// One id, with probability proportional to its area.
    pub fn pick(&self, rng: &mut SplitMix64) -> u32 {
        let x = rng.next_f64() * self.total();
        self.ids[self
            .cdf
            .partition_point(|&c| c <= x)
            .min(self.ids.len() - 1)]
    }
}

/// Cosine-distributed direction about unit normal `n` from two uniform numbers.
pub fn cosine_dir(n: Vec3, u: f32, v: f32) -> Vec3 {
    let (t, b) = n.any_orthonormal_pair();
    let (r, phi) = (u.sqrt(), 2.0 * std::f32::consts::PI * v);
    (t * (r * phi.cos()) + b * (r * phi.sin()) + n * (1.0 - u).max(0.0).sqrt()).normalize()
}

/// Irradiance (channel sum) at `p` (normal `n`) from the emitters' fronts, each emitter point
/// weighted by `radiance(triangle, point)`. With few emitting triangles (≤ 64), each one's
/// analytic point-to-polygon form factor times one shadow ray to a point of its part above
/// `p`'s plane (near lamps light sampling's 1/r² tail makes means unusable); else light sampling.
pub fn direct(
    scene: &Scene,
    caster: &RayCaster,
    ems: &ByArea,
    (p, n): (Vec3, Vec3),
    rng: &mut SplitMix64,
    radiance: impl Fn(u32, Vec3) -> f64,
) -> f64 {
    if ems.ids.is_empty() {
        return 0.0;
    }
    let o = p + n * OFF;
    if ems.ids.len() <= 64 {
        let mut sum = 0.0;
        for &t in &ems.ids {
            let v = scene.tri_vertices(t as usize);
            let (u1, u2) = (rng.next_f32(), rng.next_f32());
            let Some(y) = sample_triangle_above(p, n, &v, (u1, u2), 0.0) else {
                continue;
            };
            let d = y - o;
            let len = d.length();
            if len <= 0.0 || caster.occluded(o, d / len, 0.0, len * (1.0 - 1e-4)) {
                continue;
            }
            let poly = v.map(|a| a.as_dvec3());
            let f = point_to_polygon(
                p.as_dvec3(),
                n.as_dvec3(),
                &poly,
                scene.normals[t as usize].as_dvec3(),
            );
            sum += PI * f * radiance(t, y);
        }
        return sum;
    }
    let t = ems.pick(rng);
    let y = point_on(scene, t as usize, rng);
    let d = y - o;
    let r2 = d.length_squared();
    let len = r2.sqrt();
    let w = d / len;
    let (cx, cy) = (n.dot(w), -scene.normals[t as usize].dot(w));
    if cx <= 0.0 || cy <= 0.0 || caster.occluded(o, w, 0.0, len * (1.0 - 1e-4)) {
        return 0.0;
    }
    radiance(t, y) * (cx * cy) as f64 / r2 as f64 * ems.total()
}

/// Brute-force irradiance over receiver element `re` (open points) from the leaves of `src`
/// (analytic form factor to each leaf times one shadow ray, the leaf's own B).
pub fn brute_irradiance(
    el: &Elements,
    covers: &Covers,
    caster: &RayCaster,
    re: &Element,
    src: u32,
    m: usize,
    rng: &mut SplitMix64,
) -> f64 {
    let mut leaves = Vec::new();
    el.leaves_of(src, &mut leaves);
    let (mut sum, mut open) = (0.0, 0usize);
    for _ in 0..m {
        let x = sample_triangle(&re.verts, rng.next_f32(), rng.next_f32());
        if covers.covered(re.tri, re.normal, x) {
            continue;
        }
        open += 1;
        for &s in &leaves {
            let es = &el.elems[s as usize];
            let b = el.b[s as usize].element_sum();
            if b <= 0.0 {
                continue;
            }
            let poly = es.verts.map(|p| p.as_dvec3());
            let f = point_to_polygon(
                x.as_dvec3(),
                re.normal.as_dvec3(),
                &poly,
                es.normal.as_dvec3(),
            );
            if f <= 0.0 {
                continue;
            }
            let Some(y) = sample_triangle_above(
                x,
                re.normal,
                &es.verts,
                (rng.next_f32(), rng.next_f32()),
                0.0,
            ) else {
                continue;
            };
            if covers.covered(es.tri, es.normal, y) {
                continue;
            }
            if visible(caster, (x, re.normal), (y, es.normal)) {
                sum += f * b;
            }
        }
    }
    sum / open.max(1) as f64
}

/// `direct` with each emitter's own emission (channel sum) as its radiance.
pub fn direct_emitted(
    scene: &Scene,
    caster: &RayCaster,
    ems: &ByArea,
    (p, n): (Vec3, Vec3),
    rng: &mut SplitMix64,
) -> f64 {
    direct(scene, caster, ems, (p, n), rng, |t, _| {
        scene.material_of(t as usize).emission.element_sum() as f64
    })
}

/// One path-traced radiance sample along a cosine ray from `p` (normal `n`), less the
/// emission of an emitter front the ray hits directly (`direct` counts that light).
pub fn indirect_radiance(
    scene: &Scene,
    caster: &RayCaster,
    pt: &PathTracer,
    (p, n): (Vec3, Vec3),
    rng: &mut SplitMix64,
) -> Vec3 {
    let d = cosine_dir(n, rng.next_f32(), rng.next_f32());
    let org = p + n * OFF;
    let mut l = pt.radiance(org, d, rng);
    if let Some(h) = caster.closest(org, d, 0.0, f32::INFINITY) {
        if scene.normals[h.tri as usize].dot(d) < 0.0 {
            l -= scene.material_of(h.tri as usize).emission;
        }
    }
    l
}

/// Uniform random point of scene triangle `t`.
pub fn point_on(scene: &Scene, t: usize, rng: &mut SplitMix64) -> Vec3 {
    sample_triangle(&scene.tri_vertices(t), rng.next_f32(), rng.next_f32())
}

/// Whether surface points `x` and `y` (with their normals) see each other: the segment between
/// them, each lifted by `OFF` along its normal, meets nothing.
pub fn visible(caster: &RayCaster, (x, nx): (Vec3, Vec3), (y, ny): (Vec3, Vec3)) -> bool {
    let (a, b) = (x + nx * OFF, y + ny * OFF);
    let t = b - a;
    let tl = t.length();
    !caster.occluded(a, t / tl, 0.0, tl * (1.0 - 1e-5))
}
