//! Where a solution's light goes wrong, measured against brute force on the same scene.
//!
//! ```text
//! cargo run --release --example transport_audit -- SCENE [MODE] [options]
//!   MODE  irradiance  per object: solver irradiance against path-traced irradiance at random
//!                     points of the object (light sampling for the emitters, one path for the
//!                     rest); the path-traced values are cached in $TMPDIR/hirad-audit
//!         self        per object: solver irradiance against what cosine rays from the same
//!                     open points (those the solver does not leave out) gather from the
//!                     solution's own radiosity (exact visibility):
//!                     the transport error of one gather, without interreflection
//!         image       the scene camera's view at half its width and height: mean luminance of
//!                     the per-vertex (Gouraud) image `validate` draws, of the leaf elements'
//!                     own radiosity at each pixel's first hit, and of the path tracer (N/100
//!                     paths per pixel), with the visible objects that differ most
//!         leaves      per leaf of --object (front faces): the solver's irradiance against the
//!                     emitters' direct irradiance by light sampling (N/100 points per leaf),
//!                     for runs with --iters 1
//!         shut        per object: where the radiosity leaving its points lands (one cosine
//!                     ray per point, weighted by the leaf radiosity, 0 where the solver
//!                     leaves the point out): the share that goes into back faces
//!                     (emitted inside a solid) or into nothing
//!         links       per link: power delivered against Monte Carlo between the link's ends
//!                     (exact visibility), by link class (surface/cluster ends) and by centre
//!                     distance over the larger end's diameter
//!   --two-sided  --preset P  --clustering S  --visibility V  --refine O  --samples N (per object; per
//!   link N/100, at least 16)  --object NAME (links, irradiance, self: only that object)
//!   --source-mean (links: Monte Carlo with the source element's mean radiosity, as the link
//!   transfers it, instead of that of the leaf each sample lands on)
//!   --rays N  --eps-rel X  --min-area-rel X  --shadow-levels N  override the preset's solver settings;
//!   --iters N stops the solver after N iterations (1: direct light only)
//!   --depth N (image: the path tracer's bounces, 1: direct light only; irradiance: bounces
//!   after the receiver's hit, 0: direct light only, N matches --iters N+1)
//!   --fov DEGREES (image: the camera's vertical field of view)
//!   objlinks: every link into a surface element of --object, power delivered against brute
//!   force (as `leaf`, N/100 points per link), summed by source class and by source object
//!   --leaf ID (leaf: every link into the leaf and its surface ancestors, with the irradiance
//!   it delivers against brute force over the link's receiver from the source's leaves)
//!   --rows N (leaves: how many leaves to list, largest difference first; 30)
//!   leaves with --depth N: against the path tracer's irradiance (direct light as above plus
//!   one path of at most N bounces per point) instead of direct light only
//! ```
use glam::Vec3;
use hirad::cluster::{ClusterConfig, ClusterTree, Strategy};
use hirad::progress::NoProgress;
use hirad::radiosity::element::{facing_weight, Element, Elements, Kind};
use hirad::radiosity::formfactor::{point_to_polygon, sample_triangle, sample_triangle_above};
use hirad::radiosity::link::NO_SAMPLES;
use hirad::radiosity::overlap::Covers;
use hirad::radiosity::{solve, Oracle, Solution, SolverConfig, VisibilityMode};
use hirad::ray::RayCaster;
use hirad::render::{PathTracer, ReferenceOptions};
use hirad::rng::SplitMix64;
use hirad::scene::{Scene, SceneOptions};
use rayon::prelude::*;
use std::f64::consts::PI;

/// Ray origins leave their surface by this much (scene units) along the normal.
const OFF: f32 = 2e-6;

struct Opts {
    scene: String,
    mode: String,
    two_sided: bool,
    preset: String,
    clustering: String,
    visibility: Option<String>,
    refine: Option<String>,
    samples: usize,
    object: Option<String>,
    source_mean: bool,
    rays: Option<u32>,
    eps_rel: Option<f64>,
    min_area_rel: Option<f64>,
    iters: Option<u32>,
    depth: Option<u32>,
    rows: usize,
    leaf: Option<u32>,
    fov: Option<f32>,
    shadow_levels: Option<u32>,
}

fn parse() -> Opts {
    let mut a = std::env::args().skip(1);
    let mut o = Opts {
        scene: a
            .next()
            .expect("usage: transport_audit SCENE [MODE] [options]"),
        mode: "irradiance".into(),
        two_sided: false,
        preset: "default".into(),
        clustering: "proxi".into(),
        visibility: None,
        samples: 20_000,
        object: None,
        source_mean: false,
        rays: None,
        eps_rel: None,
        min_area_rel: None,
        iters: None,
        depth: None,
        rows: 30,
        leaf: None,
        fov: None,
        shadow_levels: None,
        refine: None,
    };
    while let Some(x) = a.next() {
        let mut val = || a.next().unwrap_or_else(|| panic!("{x} needs a value"));
        match x.as_str() {
            "--two-sided" => o.two_sided = true,
            "--preset" => o.preset = val(),
            "--clustering" => o.clustering = val(),
            "--visibility" => o.visibility = Some(val()),
            "--refine" => o.refine = Some(val()),
            "--samples" => o.samples = val().parse().expect("--samples N"),
            "--object" => o.object = Some(val()),
            "--source-mean" => o.source_mean = true,
            "--rays" => o.rays = Some(val().parse().expect("--rays N")),
            "--eps-rel" => o.eps_rel = Some(val().parse().expect("--eps-rel X")),
            "--min-area-rel" => o.min_area_rel = Some(val().parse().expect("--min-area-rel X")),
            "--iters" => o.iters = Some(val().parse().expect("--iters N")),
            "--depth" => o.depth = Some(val().parse().expect("--depth N")),
            "--rows" => o.rows = val().parse().expect("--rows N"),
            "--leaf" => o.leaf = Some(val().parse().expect("--leaf ID")),
            "--fov" => o.fov = Some(val().parse().expect("--fov DEGREES")),
            "--shadow-levels" => o.shadow_levels = Some(val().parse().expect("--shadow-levels N")),
            m if !m.starts_with("--") => o.mode = m.into(),
            _ => panic!("unknown option {x}"),
        }
    }
    o
}

/// Triangles by area: draws one with probability proportional to its area.
struct ByArea {
    ids: Vec<u32>,
    cdf: Vec<f64>,
}

impl ByArea {
    fn new(ids: Vec<u32>, area: impl Fn(u32) -> f64) -> Self {
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

    fn total(&self) -> f64 {
        self.cdf.last().copied().unwrap_or(0.0)
    }

    fn pick(&self, rng: &mut SplitMix64) -> u32 {
        let x = rng.next_f64() * self.total();
        self.ids[self
            .cdf
            .partition_point(|&c| c <= x)
            .min(self.ids.len() - 1)]
    }
}

fn cosine_dir(n: Vec3, u: f32, v: f32) -> Vec3 {
    let (t, b) = n.any_orthonormal_pair();
    let (r, phi) = (u.sqrt(), 2.0 * std::f32::consts::PI * v);
    (t * (r * phi.cos()) + b * (r * phi.sin()) + n * (1.0 - u).max(0.0).sqrt()).normalize()
}

/// Barycentric coordinates of `p` in triangle `v` (in its plane).
fn bary(v: &[Vec3; 3], p: Vec3) -> [f32; 3] {
    let (e1, e2, ep) = (v[1] - v[0], v[2] - v[0], p - v[0]);
    let (d11, d12, d22) = (e1.dot(e1), e1.dot(e2), e2.dot(e2));
    let (dp1, dp2) = (ep.dot(e1), ep.dot(e2));
    let den = d11 * d22 - d12 * d12;
    let b1 = (d22 * dp1 - d12 * dp2) / den;
    let b2 = (d11 * dp2 - d12 * dp1) / den;
    [1.0 - b1 - b2, b1, b2]
}

/// Root element of triangle `t` (its back face when `back` and two-sided).
fn root(sol: &Solution, t: u32, back: bool) -> u32 {
    let el = &sol.elements;
    el.first_root + t + if back && el.two_sided { el.num_tris } else { 0 }
}

/// Leaf element under `root` that contains point `p`.
fn leaf_at(sol: &Solution, root: u32, p: Vec3) -> u32 {
    let el = &sol.elements;
    let mut id = root;
    while el.elems[id as usize].num_children > 0 {
        id = el
            .children(id)
            .map(|c| {
                let b = bary(&el.elems[c as usize].verts, p);
                (b[0].min(b[1]).min(b[2]), c)
            })
            .fold((f32::MIN, id), |a, b| if b.0 > a.0 { b } else { a })
            .1;
    }
    id
}

/// Irradiance (channel sum) at `p` (normal `n`) from the emitters' fronts, each emitter point
/// weighted by `radiance(triangle, point)`. With few emitting triangles (≤ 64), each one's
/// analytic point-to-polygon form factor times one shadow ray to a point of its part above
/// `p`'s plane (near lamps light sampling's 1/r² tail makes means unusable); else light sampling.
fn direct(
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
            let Some(y) = sample_triangle_above(p, n, &v, u1, u2) else {
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
    let y = sample_triangle(
        &scene.tri_vertices(t as usize),
        rng.next_f32(),
        rng.next_f32(),
    );
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

/// One row of a per-object table.
struct Row {
    object: usize,
    back: bool,
    area: f64,
    solver: f64,
    other: f64,
    stderr: f64,
    direct: f64,
}

/// An object's irradiance by another method: mean, its standard error, the emitters' part,
/// and the solver's value at the same points when not the area average.
struct Estimate {
    value: f64,
    stderr: f64,
    direct: f64,
    solver: Option<f64>,
}

/// Irradiance (channel sum) of leaf `id` from its radiosity, `H = (B − E) / ρ` per channel of
/// non-zero reflectance.
fn leaf_irradiance(el: &Elements, id: u32) -> f64 {
    let e = &el.elems[id as usize];
    let (rho, b) = (e.rho.as_dvec3(), el.b[id as usize] - e.emission.as_dvec3());
    (0..3)
        .map(|c| if rho[c] > 0.0 { b[c] / rho[c] } else { 0.0 })
        .sum()
}

/// Per object (and side): the solver's mean irradiance over its open area (the parts no
/// coplanar triangle covers and no solid shuts, where the solver's H is defined), and `estimate`.
fn per_object(
    scene: &Scene,
    sol: &Solution,
    covers: &Covers,
    o: &Opts,
    estimate: impl Fn(usize, bool, &ByArea) -> Estimate + Sync,
) -> Vec<Row> {
    let (two_sided, only) = (o.two_sided, o.object.as_deref());
    let mut by: Vec<Vec<u32>> = vec![Vec::new(); scene.objects.len()];
    for t in 0..scene.num_triangles() {
        let o = scene.tri_object[t] as usize;
        if only.is_none_or(|n| scene.objects[o] == n) {
            by[o].push(t as u32);
        }
    }
    let sides: &[bool] = if two_sided { &[false, true] } else { &[false] };
    let mut rows = Vec::new();
    for &back in sides {
        let part: Vec<Row> = by
            .par_iter()
            .enumerate()
            .filter(|(_, ts)| !ts.is_empty())
            .map(|(o, ts)| {
                let tris = ByArea::new(ts.clone(), |t| scene.areas[t as usize] as f64);
                // Leaf by leaf: H over the leaf's open area (for ρ = 0, the triangle's H).
                let (mut area, mut sum, mut leaves) = (0.0f64, 0.0f64, Vec::new());
                for &t in ts {
                    leaves.clear();
                    sol.elements.leaves_of(root(sol, t, back), &mut leaves);
                    for &id in &leaves {
                        let e = &sol.elements.elems[id as usize];
                        let a = e.area as f64 * covers.open_fraction(t, e.normal, &e.verts);
                        let h = if e.rho.max_element() > 0.0 {
                            leaf_irradiance(&sol.elements, id)
                        } else {
                            sol.triangle_irradiance(t, back).element_sum()
                        };
                        area += a;
                        sum += a * h;
                    }
                }
                let area = area.max(1e-30);
                let solver = sum / area;
                let e = estimate(o, back, &tris);
                Row {
                    object: o,
                    back,
                    area,
                    solver: e.solver.unwrap_or(solver),
                    other: e.value,
                    stderr: e.stderr,
                    direct: e.direct,
                }
            })
            .collect();
        rows.extend(part);
    }
    rows
}

fn print_rows(scene: &Scene, mut rows: Vec<Row>, what: &str) {
    let (s, o) = rows
        .iter()
        .filter(|r| r.other > 0.0)
        .fold((0.0, 0.0), |a, r| {
            (a.0 + r.area * r.solver, a.1 + r.area * r.other)
        });
    println!("Σ A·H: solver {s:.3}, {what} {o:.3}, ratio {:.4}", s / o);
    rows.sort_by(|a, b| {
        let d = |r: &Row| (r.area * (r.solver - r.other)).abs();
        d(b).total_cmp(&d(a))
    });
    println!(
        "{:40} {:5} {:>9} {:>10} {:>10} {:>7} {:>10} {:>8} {:>9}",
        "object", "back", "area", "H solver", what, "ratio", "A·ΔH", "±", "direct"
    );
    for r in rows.iter().take(40) {
        let name: String = scene.objects[r.object].chars().take(40).collect();
        println!(
            "{name:40} {:5} {:9.3} {:10.3} {:10.3} {:7.3} {:10.2} {:8.3} {:9.3}",
            r.back,
            r.area,
            r.solver,
            r.other,
            r.solver / r.other,
            r.area * (r.solver - r.other),
            r.stderr,
            r.direct
        );
    }
}

/// Path-traced irradiance at random points of each object (cached per scene and seed).
fn irradiance(o: &Opts, scene: &Scene, tree: &ClusterTree, caster: &RayCaster, sol: &Solution) {
    let mut ropts = ReferenceOptions {
        two_sided: o.two_sided,
        ..Default::default()
    };
    if let Some(d) = o.depth {
        ropts.max_depth = d;
    }
    let pt = PathTracer::new(scene, caster, &ropts);
    let ems = ByArea::new(scene.emitters(), |t| scene.areas[t as usize] as f64);
    let cache = std::env::temp_dir().join("hirad-audit");
    let _ = std::fs::create_dir_all(&cache);
    let key = o.scene.replace(['/', '.'], "_");
    let m = o.samples;
    let covers = Covers::build(scene, tree, o.two_sided);
    let rows = per_object(scene, sol, &covers, o, |obj, back, tris| {
        let file = cache.join(format!(
            "{key}_{}_{obj}_{}_{m}_open{}",
            o.two_sided,
            back as u8,
            o.depth.map_or(String::new(), |d| format!("_d{d}"))
        ));
        if let Some(v) = std::fs::read_to_string(&file).ok().and_then(|c| {
            let v: Vec<f64> = c
                .split_whitespace()
                .filter_map(|x| x.parse().ok())
                .collect();
            (v.len() == 3).then_some(v)
        }) {
            return Estimate {
                value: v[0],
                stderr: v[1],
                direct: v[2],
                solver: None,
            };
        }
        let mut rng = SplitMix64::new(obj as u64 * 7919 + back as u64);
        let (mut s, mut s2, mut sd, mut open) = (0.0f64, 0.0f64, 0.0f64, 0usize);
        for _ in 0..m {
            let t = tris.pick(&mut rng) as usize;
            let n = if back {
                -scene.normals[t]
            } else {
                scene.normals[t]
            };
            let p = sample_triangle(&scene.tri_vertices(t), rng.next_f32(), rng.next_f32());
            // Covered and shut points are not part of the receiver (the solver's H is the
            // mean over open points): they count as the mean, i.e. are left out.
            if covers.covered(t as u32, n, p) {
                continue;
            }
            open += 1;
            let d = cosine_dir(n, rng.next_f32(), rng.next_f32());
            let org = p + n * OFF;
            // Indirect: one path, less the emission of a directly hit emitter front.
            let mut l = pt.radiance(org, d, &mut rng);
            if let Some(h) = caster.closest(org, d, 0.0, f32::INFINITY) {
                if scene.normals[h.tri as usize].dot(d) < 0.0 {
                    l -= scene.material_of(h.tri as usize).emission;
                }
            }
            let dh = direct(scene, caster, &ems, (p, n), &mut rng, |t, _| {
                scene.material_of(t as usize).emission.element_sum() as f64
            });
            let h = PI * l.element_sum() as f64 + dh;
            s += h;
            s2 += h * h;
            sd += dh;
        }
        let n = open.max(1) as f64;
        let mean = s / n;
        let se = ((s2 / n - mean * mean).max(0.0) / n).sqrt();
        let dm = sd / n;
        let _ = std::fs::write(&file, format!("{mean} {se} {dm}"));
        Estimate {
            value: mean,
            stderr: se,
            direct: dm,
            solver: None,
        }
    });
    print_rows(scene, rows, "path tracer");
}

/// What cosine rays gather from the solution's own radiosity at random points of each object.
fn self_consistency(
    o: &Opts,
    scene: &Scene,
    tree: &ClusterTree,
    caster: &RayCaster,
    sol: &Solution,
) {
    let el = &sol.elements;
    // The solver's irradiance is the mean over the points it does not leave out.
    let ems = ByArea::new(scene.emitters(), |t| scene.areas[t as usize] as f64);
    let m = o.samples;
    let leaf_b = |t: u32, back: bool, p: Vec3| el.b[leaf_at(sol, root(sol, t, back), p) as usize];
    let covers = Covers::build(scene, tree, o.two_sided);
    let rows = per_object(scene, sol, &covers, o, |obj, back, tris| {
        let mut rng = SplitMix64::new(obj as u64 * 31 + back as u64);
        let (mut hs, mut hm, mut hd, mut n) = (0.0f64, 0.0f64, 0.0f64, 0usize);
        for _ in 0..m {
            let t = tris.pick(&mut rng) as usize;
            let e = &el.elems[root(sol, t as u32, back) as usize];
            if e.rho.min_element() <= 0.0 {
                continue;
            }
            let nrm = e.normal;
            let p = sample_triangle(&scene.tri_vertices(t), rng.next_f32(), rng.next_f32());
            if covers.covered(t as u32, nrm, p) {
                continue;
            }
            let lf = leaf_at(sol, root(sol, t as u32, back), p);
            hs += leaf_irradiance(el, lf);
            let dh = direct(scene, caster, &ems, (p, nrm), &mut rng, |t, y| {
                leaf_b(t, false, y).element_sum() / PI
            });
            let mut g = dh;
            let d = cosine_dir(nrm, rng.next_f32(), rng.next_f32());
            if let Some(h) = caster.closest(p + nrm * OFF, d, 0.0, f32::INFINITY) {
                let hb = scene.normals[h.tri as usize].dot(d) > 0.0;
                let em = scene.material_of(h.tri as usize).is_emitter();
                // Back faces count when two-sided; emitter fronts come from light sampling.
                if if hb { o.two_sided } else { !em } {
                    let q = p + nrm * OFF + d * h.t;
                    g += leaf_b(h.tri, hb, q).element_sum();
                }
            }
            hm += g;
            hd += dh;
            n += 1;
        }
        let n = n.max(1) as f64;
        // The solver's side of the row: the leaf irradiance at the same points.
        Estimate {
            value: hm / n,
            stderr: 0.0,
            direct: hd / n,
            solver: Some(hs / n),
        }
    });
    print_rows(scene, rows, "rays on B");
}

/// Where the radiosity leaving each object's points lands: one cosine ray per point, weighted
/// by the leaf radiosity there; a back face (one-sided) or nothing means the point emits into
/// a solid or out of the scene.
fn shut(o: &Opts, scene: &Scene, tree: &ClusterTree, caster: &RayCaster, sol: &Solution) {
    let el = &sol.elements;
    // Points the solver leaves out (under a coplanar face or inside a solid) emit nothing.
    let covers = Covers::build(scene, tree, o.two_sided);
    let by = triangles_by_object(scene);
    // Per object: area, Σ A·B, fraction of points whose ray hits a back face, misses, and the
    // B-weighted fractions.
    let rows: Vec<(usize, f64, f64, f64, f64, f64, f64)> = by
        .par_iter()
        .enumerate()
        .filter(|(_, ts)| !ts.is_empty())
        .map(|(obj, ts)| {
            let tris = ByArea::new(ts.clone(), |t| scene.areas[t as usize] as f64);
            let mut rng = SplitMix64::new(obj as u64 * 17 + 3);
            let m = o.samples;
            let (mut sb, mut nb, mut nm, mut wb, mut wm) = (0.0f64, 0usize, 0usize, 0.0f64, 0.0f64);
            for _ in 0..m {
                let t = tris.pick(&mut rng) as usize;
                let nrm = scene.normals[t];
                let p = sample_triangle(&scene.tri_vertices(t), rng.next_f32(), rng.next_f32());
                let b = if covers.covered(t as u32, nrm, p) {
                    0.0
                } else {
                    el.b[leaf_at(sol, root(sol, t as u32, false), p) as usize].element_sum()
                };
                sb += b;
                let d = cosine_dir(nrm, rng.next_f32(), rng.next_f32());
                match caster.closest(p + nrm * OFF, d, 0.0, f32::INFINITY) {
                    Some(h) if scene.normals[h.tri as usize].dot(d) > 0.0 && !o.two_sided => {
                        nb += 1;
                        wb += b;
                    }
                    Some(_) => {}
                    None => {
                        nm += 1;
                        wm += b;
                    }
                }
            }
            let a = tris.total();
            let mf = m as f64;
            (
                obj,
                a,
                a * sb / mf,
                nb as f64 / mf,
                nm as f64 / mf,
                wb / sb.max(1e-30),
                wm / sb.max(1e-30),
            )
        })
        .collect();
    let tot: f64 = rows.iter().map(|r| r.2).sum();
    let lost_b: f64 = rows.iter().map(|r| r.2 * r.5).sum();
    let lost_m: f64 = rows.iter().map(|r| r.2 * r.6).sum();
    let area: f64 = rows.iter().map(|r| r.1).sum();
    let shut_a: f64 = rows.iter().map(|r| r.1 * r.3).sum();
    println!(
        "Σ A·B {tot:.2} W; into back faces {lost_b:.2} W, into nothing {lost_m:.2} W; area {area:.2}, shut {:.4}",
        shut_a / area
    );
    let mut rows = rows;
    rows.sort_by(|a, b| (b.2 * b.5).total_cmp(&(a.2 * a.5)));
    println!(
        "{:40} {:>9} {:>9} {:>7} {:>7} {:>8}",
        "object", "area", "A·B", "shut", "miss", "A·B lost"
    );
    for r in rows.iter().take(25) {
        let name: String = scene.objects[r.0].chars().take(40).collect();
        println!(
            "{name:40} {:9.3} {:9.3} {:7.3} {:7.3} {:8.3}",
            r.1,
            r.2,
            r.3,
            r.4,
            r.2 * r.5
        );
    }
}

/// The triangles of each object.
fn triangles_by_object(scene: &Scene) -> Vec<Vec<u32>> {
    let mut by: Vec<Vec<u32>> = vec![Vec::new(); scene.objects.len()];
    for t in 0..scene.num_triangles() {
        by[scene.tri_object[t] as usize].push(t as u32);
    }
    by
}

/// Root surface elements under element `id` (itself when a surface).
fn member_roots(sol: &Solution, id: u32, out: &mut Vec<u32>) {
    let el = &sol.elements;
    if el.elems[id as usize].kind == Kind::Surface {
        out.push(id);
        return;
    }
    for c in el.children(id) {
        member_roots(sol, c, out);
    }
}

/// One audited link: class (2·receiver is a cluster + source is a cluster), power delivered,
/// power by Monte Carlo, centre distance over the larger end's diameter.
struct LinkRow {
    class: usize,
    got: f64,
    want: f64,
    /// The part of `want` on surfaces of a cluster receiver that its hand-out gives nothing.
    want_unhanded: f64,
    /// `want` with the source element's mean radiosity (as a link without draw or samples
    /// transfers it).
    want_mean: f64,
    /// 0: the source's mean radiosity, 1: drawn at the deposit (`Link::draw`), 2: per-sample
    /// leaves (`Link::samples`).
    treat: usize,
    dist: f64,
}

fn links(o: &Opts, scene: &Scene, tree: &ClusterTree, caster: &RayCaster, sol: &Solution) {
    let el = &sol.elements;
    let set = &sol.links;
    let n = (o.samples / 100).max(16);
    let avg_b = o.source_mean;
    let diam = |e: &Element| match e.kind {
        Kind::Cluster => {
            let b = &tree.nodes[e.tri as usize].bbox;
            (b.max - b.min).length()
        }
        Kind::Surface => {
            let v = e.verts;
            (v[0] - v[1])
                .length()
                .max((v[1] - v[2]).length())
                .max((v[2] - v[0]).length())
        }
    };
    let covers = Covers::build(scene, tree, o.two_sided);
    let rows: Vec<LinkRow> = set
        .links
        .par_iter()
        .enumerate()
        .filter_map(|(li, l)| {
            let (re, se) = (&el.elems[l.recv as usize], &el.elems[l.src as usize]);
            let mut recv = Vec::new();
            member_roots(sol, l.recv, &mut recv);
            if let Some(name) = &o.object {
                let of = |r: &u32| {
                    &scene.objects[scene.tri_object[el.elems[*r as usize].tri as usize] as usize]
                };
                if !recv.iter().any(|r| of(r) == name) {
                    return None;
                }
            }
            let contrib = set.gather(l, el).element_sum();
            // A cluster receiver hands its irradiance to its surfaces by facing weight.
            let got: f64 = recv
                .iter()
                .map(|&r| {
                    let e = &el.elems[r as usize];
                    let w = match re.kind {
                        Kind::Surface => 1.0,
                        Kind::Cluster => {
                            facing_weight(e.centroid, e.normal, se.centroid, se.facing_normal())
                        }
                    };
                    // The solver delivers to the open part only (`Elements::open`).
                    e.area as f64 * el.open[r as usize] as f64 * w * contrib
                })
                .sum();
            let recv = ByArea::new(recv, |r| el.elems[r as usize].area as f64);
            let mut leaves = Vec::new();
            el.leaves_of(l.src, &mut leaves);
            if leaves.is_empty() {
                return None;
            }
            let src = ByArea::new(leaves, |s| el.elems[s as usize].area as f64);
            let mut rng = SplitMix64::new(li as u64 * 977 + 5);
            let (mut acc, mut acc_zero, mut acc_mean) = (0.0, 0.0, 0.0);
            for _ in 0..n {
                let er = &el.elems[recv.pick(&mut rng) as usize];
                let handed = re.kind == Kind::Surface
                    || facing_weight(er.centroid, er.normal, se.centroid, se.facing_normal()) > 0.0;
                let x = sample_triangle(&er.verts, rng.next_f32(), rng.next_f32());
                let sid = src.pick(&mut rng);
                let es = &el.elems[sid as usize];
                let y = sample_triangle(&es.verts, rng.next_f32(), rng.next_f32());
                let d = y - x;
                let r2 = d.length_squared();
                let w = d / r2.sqrt();
                let (cx, cy) = (er.normal.dot(w), -es.normal.dot(w));
                if cx <= 0.0 || cy <= 0.0 {
                    continue;
                }
                // Covered points neither receive nor emit (as in the solver).
                if covers.covered(er.tri, er.normal, x) || covers.covered(es.tri, es.normal, y) {
                    continue;
                }
                let (a, b) = (x + er.normal * OFF, y + es.normal * OFF);
                let t = b - a;
                let tl = t.length();
                if caster.occluded(a, t / tl, 0.0, tl * (1.0 - 1e-5)) {
                    continue;
                }
                let g = (cx * cy) as f64 / (PI * r2 as f64) * src.total();
                let v = el.b[if avg_b { l.src } else { sid } as usize].element_sum() * g;
                acc_mean += el.b[l.src as usize].element_sum() * g;
                acc += v;
                if !handed {
                    acc_zero += v;
                }
            }
            Some(LinkRow {
                class: 2 * (re.kind == Kind::Cluster) as usize
                    + (se.kind == Kind::Cluster) as usize,
                got,
                want: recv.total() * acc / n as f64,
                want_unhanded: recv.total() * acc_zero / n as f64,
                want_mean: recv.total() * acc_mean / n as f64,
                treat: if l.samples != NO_SAMPLES {
                    2
                } else if l.draw.depth() > 0 {
                    1
                } else {
                    0
                },
                dist: ((re.centroid - se.centroid).length() / diam(re).max(diam(se))) as f64,
            })
        })
        .collect();
    println!(
        "{} links, {} audited, {n} samples each",
        set.links.len(),
        rows.len()
    );
    let names = [
        "surface <- surface",
        "surface <- cluster",
        "cluster <- surface",
        "cluster <- cluster",
    ];
    let bins = [0.0, 0.5, 1.0, 1.5, 2.0, 3.0, 5.0, 10.0, f64::INFINITY];
    for (class, name) in names.iter().enumerate() {
        let sum = |f: &dyn Fn(&LinkRow) -> bool| {
            rows.iter()
                .filter(|r| r.class == class && f(r))
                .fold((0usize, 0.0, 0.0), |a, r| {
                    (a.0 + 1, a.1 + r.got, a.2 + r.want)
                })
        };
        let (c, g, w) = sum(&|_| true);
        println!(
            "{name}: {c} links, delivered {g:.4} W, Monte Carlo {w:.4} W, ratio {:.4}",
            g / w
        );
        if class == 0 {
            for (t, name) in ["source mean", "drawn at deposits", "per-sample leaves"]
                .iter()
                .enumerate()
            {
                let rs = rows.iter().filter(|r| r.class == 0 && r.treat == t);
                let (c, g, w, wm) = rs.fold((0usize, 0.0, 0.0, 0.0), |a, r| {
                    (a.0 + 1, a.1 + r.got, a.2 + r.want, a.3 + r.want_mean)
                });
                println!(
                    "  {name}: {c} links, delivered {g:.4} W, Monte Carlo {w:.4} W ({:.4}), with the source's mean {wm:.4} W ({:.4})",
                    g / w,
                    g / wm
                );
            }
        }
        if class >= 2 {
            let unhanded = |near: bool| -> f64 {
                rows.iter()
                    .filter(|r| r.class == class && (!near || r.dist < 1.0))
                    .map(|r| r.want_unhanded)
                    .sum()
            };
            println!(
                "  Monte Carlo on surfaces the hand-out gives nothing: {:.4} W ({:.4} W at distance/diameter below 1)",
                unhanded(false),
                unhanded(true)
            );
        }
        for b in bins.windows(2) {
            let (c, g, w) = sum(&|r| r.dist >= b[0] && r.dist < b[1]);
            if c > 0 {
                println!("  distance/diameter [{:4}, {:4}): {c:8} links, {g:10.4} W against {w:10.4} W, ratio {:.4}", b[0], b[1], g / w);
            }
        }
    }
}

/// Per leaf of one object: solver irradiance (from B = E + ρH) against direct light, both
/// over the leaf's open points (those no coplanar triangle covers and no solid shuts, as the
/// solver counts them).
fn leaves(o: &Opts, scene: &Scene, tree: &ClusterTree, caster: &RayCaster, sol: &Solution) {
    let name = o.object.as_deref().expect("leaves needs --object NAME");
    let obj = scene
        .objects
        .iter()
        .position(|n| n == name)
        .expect("no such object");
    let ems = ByArea::new(scene.emitters(), |t| scene.areas[t as usize] as f64);
    let el = &sol.elements;
    let m = (o.samples / 100).max(16);
    let covers = Covers::build(scene, tree, o.two_sided);
    // With --depth, indirect light too: one path per point, at most `depth` bounces.
    let pt = o.depth.map(|d| {
        let ropts = ReferenceOptions {
            two_sided: o.two_sided,
            max_depth: d,
            ..Default::default()
        };
        PathTracer::new(scene, caster, &ropts)
    });
    let mut ids = Vec::new();
    for t in 0..scene.num_triangles() as u32 {
        if scene.tri_object[t as usize] as usize == obj {
            el.leaves_of(root(sol, t, false), &mut ids);
            if o.two_sided {
                el.leaves_of(root(sol, t, true), &mut ids);
            }
        }
    }
    let rows: Vec<(u32, f64, f64, f64)> = ids
        .par_iter()
        .map(|&id| {
            let e = &el.elems[id as usize];
            let h = leaf_irradiance(el, id);
            let mut rng = SplitMix64::for_item(0x1EAF, id as u64);
            let (mut sum, mut open) = (0.0, 0usize);
            for _ in 0..m {
                let p = sample_triangle(&e.verts, rng.next_f32(), rng.next_f32());
                if covers.covered(e.tri, e.normal, p) {
                    continue;
                }
                open += 1;
                sum += direct(scene, caster, &ems, (p, e.normal), &mut rng, |t, _| {
                    scene.material_of(t as usize).emission.element_sum() as f64
                });
                if let Some(pt) = &pt {
                    let d = cosine_dir(e.normal, rng.next_f32(), rng.next_f32());
                    let org = p + e.normal * OFF;
                    let mut l = pt.radiance(org, d, &mut rng);
                    if let Some(h) = caster.closest(org, d, 0.0, f32::INFINITY) {
                        if scene.normals[h.tri as usize].dot(d) < 0.0 {
                            l -= scene.material_of(h.tri as usize).emission;
                        }
                    }
                    sum += PI * l.element_sum() as f64;
                }
            }
            let open_area = e.area as f64 * open as f64 / m as f64;
            (id, open_area, h, sum / open.max(1) as f64)
        })
        .collect();
    let (sa, sh, sd) = rows.iter().fold((0.0, 0.0, 0.0), |a, r| {
        (a.0 + r.1, a.1 + r.1 * r.2, a.2 + r.1 * r.3)
    });
    println!(
        "{name}: {} leaves, area {sa:.4}, Σ A·H solver {sh:.4}, direct {sd:.4}, ratio {:.4}",
        rows.len(),
        sh / sd
    );
    println!(
        "{:>8} {:>9} {:>8} {:>9} {:>9} {:>7}  centroid",
        "leaf", "tri", "area", "H", "direct", "ratio"
    );
    let mut rows = rows;
    rows.sort_by(|a, b| {
        (b.1 * (b.2 - b.3))
            .abs()
            .total_cmp(&(a.1 * (a.2 - a.3)).abs())
    });
    for r in rows.iter().take(o.rows) {
        let e = &el.elems[r.0 as usize];
        println!(
            "{:8} {:9} {:8.5} {:9.4} {:9.4} {:7.3}  {:.3?} n {:.2?}",
            r.0,
            e.tri,
            r.1,
            r.2,
            r.3,
            r.2 / r.3,
            e.centroid,
            e.normal
        );
    }
}

/// Pixels of one object binned 10 × 8 over the two widest axes of their hit points' box:
/// leaf / path-traced mean luminance per bin (rows from the top of the second axis).
fn image_bins(hits: &[(Vec3, f64, f64)]) {
    let (lo, hi) = hits.iter().fold(
        (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
        |(a, b), h| (a.min(h.0), b.max(h.0)),
    );
    let ext = hi - lo;
    let mut ax = [0usize, 1, 2];
    ax.sort_by(|&a, &b| ext[b].total_cmp(&ext[a]));
    let (u, v) = (ax[0].min(ax[1]), ax[0].max(ax[1]));
    const NU: usize = 10;
    const NV: usize = 8;
    let mut bins = vec![(0u64, 0.0f64, 0.0f64); NU * NV];
    for &(p, l, t) in hits {
        let bu = (((p[u] - lo[u]) / ext[u].max(1e-9)) * NU as f32) as usize;
        let bv = (((p[v] - lo[v]) / ext[v].max(1e-9)) * NV as f32) as usize;
        let b = &mut bins[bv.min(NV - 1) * NU + bu.min(NU - 1)];
        b.0 += 1;
        b.1 += l;
        b.2 += t;
    }
    println!(
        "pixels of --object by axis {u} ({:.2}..{:.2}, columns) and axis {v} ({:.2}..{:.2}, rows from the top): leaf/path mean luminance, pixels",
        lo[u], hi[u], lo[v], hi[v]
    );
    for r in (0..NV).rev() {
        let line: Vec<String> = (0..NU)
            .map(|c| {
                let b = bins[r * NU + c];
                if b.0 == 0 {
                    format!("{:>15}", "-")
                } else {
                    format!(
                        "{:5.1}/{:5.1} {:>3}",
                        b.1 / b.0 as f64,
                        b.2 / b.0 as f64,
                        b.0
                    )
                }
            })
            .collect();
        println!("{}", line.join(" "));
    }
}

/// Mean luminance of the view drawn three ways, and the visible objects behind the gap.
fn image(o: &Opts, scene: &Scene, caster: &RayCaster, sol: &Solution) {
    use hirad::metrics::luminance;
    use hirad::radiosity::output::radiosity_mesh;
    use hirad::render::{render_solution, BackFaces, CameraView, RasterOptions};
    let mut view = CameraView::from_camera(&scene.default_camera());
    view.width = (view.width / 2).max(1);
    view.height = (view.height / 2).max(1);
    if let Some(f) = o.fov {
        view.fov_deg = f;
    }
    let raster = RasterOptions {
        back_faces: if o.two_sided {
            BackFaces::Cull
        } else {
            BackFaces::Black
        },
        ..Default::default()
    };
    let gouraud =
        render_solution(&radiosity_mesh(sol, scene, false), &view, &raster).expect("raster");
    let mut ropts = ReferenceOptions {
        two_sided: o.two_sided,
        ..Default::default()
    };
    if let Some(d) = o.depth {
        ropts.max_depth = d;
    }
    let pt = PathTracer::new(scene, caster, &ropts);
    let frame = view.frame();
    let spp = (o.samples / 100).max(1);
    let el = &sol.elements;
    // Per object: (pixels, leaf luminance sum, path-traced luminance sum).
    // Per image row: per object (pixels, leaf luminance sum, path-traced luminance sum), and
    // per pixel (leaf radiance, path-traced radiance).
    // With --object: (hit point, leaf luminance, path-traced luminance) of its pixels.
    type Row = (
        Vec<(u64, f64, f64)>,
        Vec<(Vec3, Vec3)>,
        Vec<(Vec3, f64, f64)>,
    );
    let focus = o.object.as_deref().map(|n| {
        scene
            .objects
            .iter()
            .position(|m| m == n)
            .expect("no such object")
    });
    let rows: Vec<Row> = (0..view.height)
        .into_par_iter()
        .map(|y| {
            let mut acc = vec![(0u64, 0.0f64, 0.0f64); scene.objects.len() + 1];
            let mut px = Vec::with_capacity(view.width as usize);
            let mut hits = Vec::new();
            let mut rng = SplitMix64::for_item(0xA0D1, y as u64);
            for x in 0..view.width {
                let d = frame.direction(x as f32 + 0.5, y as f32 + 0.5).normalize();
                let mut ptc = Vec3::ZERO;
                for _ in 0..spp {
                    ptc += pt.radiance(frame.eye, d, &mut rng);
                }
                ptc /= spp as f32;
                let ptl = luminance(ptc);
                let (obj, leaf) = match caster.closest(frame.eye, d, 0.0, f32::INFINITY) {
                    Some(h) => {
                        let t = h.tri;
                        let p = frame.eye + d * h.t;
                        let back = scene.normals[t as usize].dot(d) > 0.0;
                        let b = if back && !o.two_sided {
                            glam::DVec3::ZERO
                        } else {
                            el.b[leaf_at(sol, root(sol, t, back), p) as usize]
                        };
                        px.push((b.as_vec3() / std::f32::consts::PI, ptc));
                        if focus == Some(scene.tri_object[t as usize] as usize) {
                            hits.push((p, luminance(b.as_vec3()) / PI, ptl));
                        }
                        (
                            scene.tri_object[t as usize] as usize,
                            luminance(b.as_vec3()) / PI,
                        )
                    }
                    None => {
                        px.push((Vec3::ZERO, ptc));
                        (scene.objects.len(), 0.0)
                    }
                };
                let a = &mut acc[obj];
                a.0 += 1;
                a.1 += leaf;
                a.2 += ptl;
            }
            (acc, px, hits)
        })
        .collect();
    let mut tot = vec![(0u64, 0.0f64, 0.0f64); scene.objects.len() + 1];
    let mut img_leaf = hirad::render::Image::new(view.width, view.height, Vec3::ZERO);
    let mut img_pt = img_leaf.clone();
    let mut hits = Vec::new();
    for (y, (r, px, hs)) in rows.into_iter().enumerate() {
        hits.extend(hs);
        for (x, (l, p)) in px.into_iter().enumerate() {
            img_leaf.set(x as u32, y as u32, l);
            img_pt.set(x as u32, y as u32, p);
        }
        for (t, a) in tot.iter_mut().zip(r) {
            t.0 += a.0;
            t.1 += a.1;
            t.2 += a.2;
        }
    }
    let dir = std::env::temp_dir().join("hirad-audit");
    std::fs::create_dir_all(&dir).ok();
    img_leaf
        .write_exr(&dir.join("image_leaf.exr"))
        .expect("exr");
    img_pt.write_exr(&dir.join("image_path.exr")).expect("exr");
    gouraud
        .write_exr(&dir.join("image_gouraud.exr"))
        .expect("exr");
    // Side by side (leaf | path tracer | ratio: red where the leaf is darker, green brighter).
    let (w, h) = (view.width, view.height);
    let mut side = hirad::render::Image::new(3 * w, h, Vec3::ZERO);
    // The first two panels are exposed to put the path tracer's mean luminance at 0.3.
    let mean_pt = (0..h)
        .flat_map(|y| (0..w).map(move |x| (x, y)))
        .map(|(x, y)| luminance(img_pt.get(x, y)))
        .sum::<f64>()
        / (w * h) as f64;
    let k = (0.3 / mean_pt.max(1e-12)) as f32;
    for y in 0..h {
        for x in 0..w {
            let (l, p) = (img_leaf.get(x, y), img_pt.get(x, y));
            side.set(x, y, l * k);
            side.set(w + x, y, p * k);
            // Ratio of 9×9 box means (the path tracer's pixels are noisy).
            let (mut sl, mut sp) = (0.0, 0.0);
            for yy in y.saturating_sub(4)..(y + 5).min(h) {
                for xx in x.saturating_sub(4)..(x + 5).min(w) {
                    sl += luminance(img_leaf.get(xx, yy));
                    sp += luminance(img_pt.get(xx, yy));
                }
            }
            let r = (sl / f64::max(sp, 1e-9)) as f32;
            let c = if r < 1.0 {
                Vec3::new(1.0 - r, 0.0, 0.0) * 2.0
            } else {
                Vec3::new(0.0, (r - 1.0).min(1.0), 0.0) * 2.0
            };
            side.set(2 * w + x, y, c);
        }
    }
    side.write_png(&dir.join("image_side.png"), 1.0)
        .expect("png");
    println!("images: {}/image_{{leaf,path,gouraud}}.exr", dir.display());
    let n = (view.width * view.height) as f64;
    let (leaf, ptm) = tot.iter().fold((0.0, 0.0), |s, a| (s.0 + a.1, s.1 + a.2));
    let gm = gouraud.pixels.iter().map(|&p| luminance(p)).sum::<f64>() / n;
    println!(
        "{}x{}, {spp} paths per pixel: mean luminance path tracer {:.5}, per-vertex image {:.5} ({:.4}), leaf at the first hit {:.5} ({:.4})",
        view.width,
        view.height,
        ptm / n,
        gm,
        gm / (ptm / n),
        leaf / n,
        leaf / ptm
    );
    let mut idx: Vec<usize> = (0..tot.len()).filter(|&i| tot[i].0 > 0).collect();
    idx.sort_by(|&a, &b| {
        (tot[b].1 - tot[b].2)
            .abs()
            .total_cmp(&(tot[a].1 - tot[a].2).abs())
    });
    println!(
        "{:40} {:>8} {:>10} {:>10} {:>7} {:>9}",
        "object", "pixels", "leaf", "path", "ratio", "Δ/total"
    );
    if !hits.is_empty() {
        image_bins(&hits);
    }
    for &i in idx.iter().take(25) {
        let name: String = if i < scene.objects.len() {
            scene.objects[i].chars().take(40).collect()
        } else {
            "(nothing)".into()
        };
        let t = tot[i];
        println!(
            "{name:40} {:8} {:10.4} {:10.4} {:7.3} {:9.4}",
            t.0,
            t.1 / t.0 as f64,
            t.2 / t.0 as f64,
            t.1 / t.2,
            (t.1 - t.2) / ptm
        );
    }
}

/// Every link into surface leaf `--leaf` and its surface ancestors: irradiance delivered
/// (`K·B`, channel sum) against brute force over the link's receiver (N/10 open points, the
/// analytic form factor to each leaf of the source times one shadow ray, the leaf's own B).
fn leaf_links(o: &Opts, scene: &Scene, tree: &ClusterTree, caster: &RayCaster, sol: &Solution) {
    let el = &sol.elements;
    let covers = Covers::build(scene, tree, o.two_sided);
    let leaf = o.leaf.expect("leaf needs --leaf ID");
    let mut chain = vec![leaf];
    while let Some(&id) = chain.last() {
        let p = el.elems[id as usize].parent;
        if p == u32::MAX || el.elems[p as usize].kind != Kind::Surface {
            break;
        }
        chain.push(p);
    }
    let m = (o.samples / 10).max(64);
    let mut tot = (0.0, 0.0);
    // Per level of the chain: delivered, brute force over the link's receiver, and brute
    // force over the leaf itself (what the leaf should get from the same sources).
    let mut per_level = vec![(0.0f64, 0.0f64, 0.0f64, 0usize); chain.len()];
    let le = &el.elems[leaf as usize];
    println!("leaf {leaf}: H {:.3}", leaf_irradiance(el, leaf));
    println!(
        "{:>8} {:>9} {:>8} {:>7} {:>9} {:>9} {:>9} {:>9} {:>7}",
        "recv", "r.area", "src", "kind", "s.area", "k", "K·B", "brute", "ratio"
    );
    for (lvl, &r) in chain.iter().enumerate() {
        let re = &el.elems[r as usize];
        for l in sol.links.links.iter().filter(|l| l.recv == r) {
            let se = &el.elems[l.src as usize];
            let got = sol.links.gather(l, el).element_sum();
            let mut leaves = Vec::new();
            el.leaves_of(l.src, &mut leaves);
            let mut rng = SplitMix64::for_item(0x001E_AF11, ((r as u64) << 32) | l.src as u64);
            let want = brute_irradiance(el, &covers, caster, re, l.src, m, &mut rng);
            let want_leaf = if r == leaf {
                want
            } else {
                brute_irradiance(el, &covers, caster, le, l.src, m, &mut rng)
            };
            tot.0 += got;
            tot.1 += want;
            let pl = &mut per_level[lvl];
            pl.0 += got;
            pl.1 += want;
            pl.2 += want_leaf;
            pl.3 += 1;
            let src_obj = &scene.objects
                [scene.tri_object[el.elems[leaves[0] as usize].tri as usize] as usize];
            println!(
                "{r:8} {:9.5} {:8} {:>7} {:9.4} {:9.5} {:9.3} {:9.3} {:7.3}  {src_obj} back {} {:.3?} n {:.2?}",
                re.area,
                l.src,
                if se.kind == Kind::Cluster { "cluster" } else { "surface" },
                se.area,
                l.k,
                got,
                want,
                got / want,
                se.back,
                se.centroid,
                se.normal
            );
            if se.kind == Kind::Cluster && got > 2.0 * want && l.samples != u32::MAX {
                let st = l.samples as usize;
                let pl = sol.links.per_link as usize;
                for &(mm, w) in &sol.links.samples[st..st + pl] {
                    if mm == u32::MAX {
                        println!("      sample: none");
                        continue;
                    }
                    let e = &el.elems[mm as usize];
                    let obj = &scene.objects[scene.tri_object[e.tri as usize] as usize];
                    println!(
                        "      sample: {mm} {obj} back {} area {:.4} w {w:.5} B {:.3} centroid {:.3?} n {:.2?}",
                        e.back,
                        e.area,
                        el.b[mm as usize].element_sum(),
                        e.centroid,
                        e.normal
                    );
                }
                println!(
                    "      receiver centroid {:.3?} n {:.2?}",
                    re.centroid, re.normal
                );
            }
        }
    }
    println!(
        "sum: K·B {:.3}, brute {:.3}, ratio {:.4}",
        tot.0,
        tot.1,
        tot.0 / tot.1
    );
    for (lvl, (&r, pl)) in chain.iter().zip(&per_level).enumerate() {
        println!(
            "level {lvl} (element {r}, area {:.4}): {} links, K·B {:.3}, brute over it {:.3}, \
             brute over the leaf {:.3}",
            el.elems[r as usize].area, pl.3, pl.0, pl.1, pl.2
        );
    }
    println!(
        "handed out by clusters, or moved by deposits (H − Σ K·B): {:.3}",
        leaf_irradiance(el, leaf) - tot.0
    );
}

/// Brute-force irradiance over receiver element `re` (open points) from the leaves of `src`
/// (analytic form factor to each leaf times one shadow ray, the leaf's own B).
fn brute_irradiance(
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
            let Some(y) =
                sample_triangle_above(x, re.normal, &es.verts, rng.next_f32(), rng.next_f32())
            else {
                continue;
            };
            if covers.covered(es.tri, es.normal, y) {
                continue;
            }
            let (a, bb) = (x + re.normal * OFF, y + es.normal * OFF);
            let t = bb - a;
            let tl = t.length();
            if !caster.occluded(a, t / tl, 0.0, tl * (1.0 - 1e-5)) {
                sum += f * b;
            }
        }
    }
    sum / open.max(1) as f64
}

/// Links into the surface elements of `--object`: delivered power against brute force, by
/// source class and by source object.
fn object_links(o: &Opts, scene: &Scene, tree: &ClusterTree, caster: &RayCaster, sol: &Solution) {
    let name = o.object.as_deref().expect("objlinks needs --object NAME");
    let obj = scene
        .objects
        .iter()
        .position(|n| n == name)
        .expect("no such object");
    let el = &sol.elements;
    let covers = Covers::build(scene, tree, o.two_sided);
    let m = (o.samples / 100).max(8);
    let rows: Vec<(usize, usize, f64, f64)> = sol
        .links
        .links
        .par_iter()
        .filter_map(|l| {
            let re = &el.elems[l.recv as usize];
            if re.kind != Kind::Surface || scene.tri_object[re.tri as usize] as usize != obj {
                return None;
            }
            let se = &el.elems[l.src as usize];
            let mut rng = SplitMix64::for_item(0x0B1, ((l.recv as u64) << 32) | l.src as u64);
            let a = re.area as f64 * el.open[l.recv as usize] as f64;
            let got = a * sol.links.gather(l, el).element_sum();
            let want = a * brute_irradiance(el, &covers, caster, re, l.src, m, &mut rng);
            let mut leaves = Vec::new();
            el.leaves_of(l.src, &mut leaves);
            let sobj = scene.tri_object[el.elems[leaves[0] as usize].tri as usize] as usize;
            let class = if se.kind == Kind::Cluster {
                0
            } else if (re.centroid - se.centroid).length() < 2.0 * (re.area.max(se.area)).sqrt() {
                1
            } else {
                2
            };
            Some((class, sobj, got, want))
        })
        .collect();
    let names = ["cluster source", "near surface", "far surface"];
    for (c, n) in names.iter().enumerate() {
        let (k, g, w) = rows
            .iter()
            .filter(|r| r.0 == c)
            .fold((0, 0.0, 0.0), |a, r| (a.0 + 1, a.1 + r.2, a.2 + r.3));
        println!(
            "{n}: {k} links, delivered {g:.2} W, brute {w:.2} W, ratio {:.4}",
            g / w
        );
    }
    let mut by: std::collections::BTreeMap<usize, (usize, f64, f64)> = Default::default();
    for r in &rows {
        let e = by.entry(r.1).or_default();
        e.0 += 1;
        e.1 += r.2;
        e.2 += r.3;
    }
    let mut v: Vec<_> = by.into_iter().collect();
    v.sort_by(|a, b| (b.1 .1 - b.1 .2).abs().total_cmp(&(a.1 .1 - a.1 .2).abs()));
    for (s, (k, g, w)) in v.iter().take(o.rows) {
        println!(
            "  from {:40} {k:7} links {g:10.2} W against {w:10.2} W ratio {:.3}",
            scene.objects[*s],
            g / w
        );
    }
}

/// How many links carry each (receiver point, source point) pair: cosine rays from random open
/// points of every receiving surface (by area, both sides when two-sided), each weighted by
/// the radiosity of the leaf it hits; a pair is carried by a link whose receiver is the
/// point's leaf or an ancestor (surfaces, then clusters) and whose source is the hit leaf or
/// an ancestor. In a solution that covers every pair once, all the weight is in "1".
fn coverage(o: &Opts, scene: &Scene, tree: &ClusterTree, caster: &RayCaster, sol: &Solution) {
    let el = &sol.elements;
    let set = &sol.links;
    let covers = Covers::build(scene, tree, o.two_sided);
    let mut range = vec![(0u32, 0u32); el.len()];
    for &(r, a, b) in &set.groups {
        range[r as usize] = (a, b);
    }
    let sides = if o.two_sided { 2 } else { 1 };
    let all: Vec<u32> = (0..scene.num_triangles() as u32 * sides)
        .filter(|&i| {
            el.elems[root(
                sol,
                i % scene.num_triangles() as u32,
                i >= scene.num_triangles() as u32,
            ) as usize]
                .rho
                .max_element()
                > 0.0
        })
        .collect();
    let nt = scene.num_triangles() as u32;
    let pick = ByArea::new(all, |i| scene.areas[(i % nt) as usize] as f64);
    let chain = |mut id: u32| {
        let mut v = Vec::new();
        while id != u32::MAX {
            v.push(id);
            id = el.elems[id as usize].parent;
        }
        v
    };
    const CHUNK: usize = 4096;
    let n = o.samples;
    // Per chunk: weight by number of links carrying the pair (0, 1, 2, 3+), and of the
    // uncovered weight, by (receiver object, source object).
    type Part = ([f64; 4], [f64; 4], Vec<((usize, usize), f64)>);
    let parts: Vec<Part> = (0..n.div_ceil(CHUNK))
        .into_par_iter()
        .map(|c| {
            let mut rng = SplitMix64::new(c as u64 * 7919 + 3);
            let (mut w, mut cnt) = ([0.0f64; 4], [0.0f64; 4]);
            let mut miss: std::collections::HashMap<(usize, usize), f64> = Default::default();
            for _ in 0..CHUNK.min(n - c * CHUNK) {
                let i = pick.pick(&mut rng);
                let (t, back) = (i % nt, i >= nt);
                let r = root(sol, t, back);
                let nrm = el.elems[r as usize].normal;
                let p = sample_triangle(
                    &scene.tri_vertices(t as usize),
                    rng.next_f32(),
                    rng.next_f32(),
                );
                if covers.covered(t, nrm, p) {
                    continue;
                }
                let d = cosine_dir(nrm, rng.next_f32(), rng.next_f32());
                let Some(h) = caster.closest(p + nrm * OFF, d, 0.0, f32::INFINITY) else {
                    continue;
                };
                let hb = scene.normals[h.tri as usize].dot(d) > 0.0;
                if hb && !o.two_sided {
                    continue;
                }
                let q = p + nrm * OFF + d * h.t;
                if covers.covered(
                    h.tri,
                    scene.normals[h.tri as usize] * if hb { -1.0 } else { 1.0 },
                    q,
                ) {
                    continue;
                }
                let sl = leaf_at(sol, root(sol, h.tri, hb), q);
                let wt = el.b[sl as usize].element_sum();
                if wt <= 0.0 {
                    continue;
                }
                let srcs = chain(sl);
                let mut k = 0usize;
                for rid in chain(leaf_at(sol, r, p)) {
                    let (a, b) = range[rid as usize];
                    k += set.links[a as usize..b as usize]
                        .iter()
                        .filter(|l| srcs.contains(&l.src))
                        .count();
                }
                w[k.min(3)] += wt;
                cnt[k.min(3)] += 1.0;
                if k == 0 {
                    *miss
                        .entry((
                            scene.tri_object[t as usize] as usize,
                            scene.tri_object[h.tri as usize] as usize,
                        ))
                        .or_default() += wt;
                }
            }
            (w, cnt, miss.into_iter().collect())
        })
        .collect();
    let (mut w, mut cnt) = ([0.0f64; 4], [0.0f64; 4]);
    let mut miss: std::collections::HashMap<(usize, usize), f64> = Default::default();
    for (pw, pc, pm) in parts {
        for k in 0..4 {
            w[k] += pw[k];
            cnt[k] += pc[k];
        }
        for (key, v) in pm {
            *miss.entry(key).or_default() += v;
        }
    }
    let tw: f64 = w.iter().sum();
    println!(
        "{n} rays; share of the gathered radiosity carried by 0, 1, 2, 3+ links (share of rays):"
    );
    for k in 0..4 {
        println!(
            "  {k}: {:.5} ({:.5})",
            w[k] / tw,
            cnt[k] / cnt.iter().sum::<f64>()
        );
    }
    let mut v: Vec<_> = miss.into_iter().collect();
    v.sort_by(|a, b| b.1.total_cmp(&a.1));
    println!("uncovered, by receiver object <- source object (share of all gathered):");
    for ((ro, so), x) in v.iter().take(o.rows) {
        println!(
            "  {:40} <- {:40} {:.5}",
            scene.objects[*ro],
            scene.objects[*so],
            x / tw
        );
    }
}

/// The shut masks against 64 cosine rays per point (no solve): per object, the share of its
/// area the masks shut, and of that, the share whose rays meet a front face or nothing (light
/// could reach it), as a mean over the shut points.
fn shut_check(o: &Opts, scene: &Scene, tree: &ClusterTree, caster: &RayCaster) {
    let masks = hirad::radiosity::shut::ShutMasks::build(scene, tree, false);
    let by = triangles_by_object(scene);
    let rows: Vec<(usize, f64, f64, f64)> = by
        .par_iter()
        .enumerate()
        .filter(|(_, ts)| !ts.is_empty())
        .map(|(obj, ts)| {
            let tris = ByArea::new(ts.clone(), |t| scene.areas[t as usize] as f64);
            let mut rng = SplitMix64::new(obj as u64 * 13 + 1);
            let (mut n_shut, mut open_sum) = (0usize, 0.0f64);
            for _ in 0..o.samples {
                let t = tris.pick(&mut rng) as usize;
                let nrm = scene.normals[t];
                let p = sample_triangle(&scene.tri_vertices(t), rng.next_f32(), rng.next_f32());
                if !masks.shut(t as u32, p) {
                    continue;
                }
                n_shut += 1;
                let mut open = 0;
                for _ in 0..64 {
                    let d = cosine_dir(nrm, rng.next_f32(), rng.next_f32());
                    match caster.closest(p + nrm * OFF, d, 0.0, f32::INFINITY) {
                        Some(h) if scene.normals[h.tri as usize].dot(d) > 0.0 => {}
                        _ => open += 1,
                    }
                }
                open_sum += open as f64 / 64.0;
            }
            let a = tris.total();
            (
                obj,
                a,
                n_shut as f64 / o.samples as f64,
                open_sum / n_shut.max(1) as f64,
            )
        })
        .collect();
    let area: f64 = rows.iter().map(|r| r.1).sum();
    let shut: f64 = rows.iter().map(|r| r.1 * r.2).sum();
    let open: f64 = rows.iter().map(|r| r.1 * r.2 * r.3).sum();
    println!("area {area:.3}, shut {shut:.3}, of it open to rays {open:.3} (cosine-weighted)");
    let mut rows = rows;
    rows.sort_by(|a, b| (b.1 * b.2 * b.3).total_cmp(&(a.1 * a.2 * a.3)));
    println!("{:40} {:>9} {:>7} {:>7}", "object", "area", "shut", "open");
    for r in rows.iter().take(o.rows) {
        println!(
            "{:40} {:9.3} {:7.3} {:7.3}",
            scene.objects[r.0], r.1, r.2, r.3
        );
    }
}

fn main() {
    let o = parse();
    let scene = Scene::load(&o.scene, &SceneOptions::default()).expect("scene");
    let strategy = Strategy::parse(&o.clustering).expect("clustering");
    let tree = ClusterTree::build(&scene, strategy, &ClusterConfig::default());
    let mut cfg = SolverConfig::preset(&o.preset).expect("preset");
    cfg.two_sided = o.two_sided;
    if let Some(n) = o.rays {
        cfg.shadow_rays = n;
    }
    if let Some(e) = o.eps_rel {
        cfg.eps_rel = e;
    }
    if let Some(m) = o.min_area_rel {
        cfg.min_area_rel = m;
    }
    if let Some(n) = o.iters {
        cfg.max_iters = n;
    }
    if let Some(n) = o.shadow_levels {
        cfg.shadow_levels = n;
    }
    if let Some(v) = &o.visibility {
        cfg.visibility = VisibilityMode::parse(v).expect("visibility");
    }
    if let Some(r) = &o.refine {
        cfg.refine = Oracle::parse(r).expect("refine");
    }
    if o.mode == "shutcheck" {
        return shut_check(&o, &scene, &tree, &RayCaster::new(&scene, &tree));
    }
    let t = std::time::Instant::now();
    let sol = solve(&scene, &tree, &cfg, &NoProgress).expect("solve");
    let p = &sol.stats.power;
    println!(
        "solve {:.1} s; emitted {:.2} W, emitted − absorbed {:.2} W (channel sums)",
        t.elapsed().as_secs_f64(),
        p.emitted,
        p.escaping
    );
    let caster = RayCaster::new(&scene, &tree);
    match o.mode.as_str() {
        "irradiance" => irradiance(&o, &scene, &tree, &caster, &sol),
        "self" => self_consistency(&o, &scene, &tree, &caster, &sol),
        "links" => links(&o, &scene, &tree, &caster, &sol),
        "image" => image(&o, &scene, &caster, &sol),
        "leaves" => leaves(&o, &scene, &tree, &caster, &sol),
        "shut" => shut(&o, &scene, &tree, &caster, &sol),
        "leaf" => leaf_links(&o, &scene, &tree, &caster, &sol),
        "objlinks" => object_links(&o, &scene, &tree, &caster, &sol),
        "coverage" => coverage(&o, &scene, &tree, &caster, &sol),
        m => panic!("unknown mode {m}"),
    }
}
