//! Modes `irradiance` (the solver against the path tracer, per object) and `self` (against
//! one gather of cosine rays on the solution's own radiosity, per object).
use crate::elements::{leaf_at, leaf_irradiance, root};
use crate::estimate::{
    cosine_dir, direct, direct_emitted, indirect_radiance, point_on, ByArea, OFF,
};
use crate::opts::Opts;
use crate::table::{per_object, print_rows, Estimate};
use glam::Vec3;
use hirad::cluster::ClusterTree;
use hirad::radiosity::overlap::Covers;
use hirad::radiosity::Solution;
use hirad::ray::RayCaster;
use hirad::render::PathTracer;
use hirad::rng::SplitMix64;
use hirad::scene::Scene;
use std::f64::consts::PI;

/// Path-traced irradiance at random points of each object (cached per scene and seed).
pub fn irradiance(o: &Opts, scene: &Scene, tree: &ClusterTree, caster: &RayCaster, sol: &Solution) {
    let pt = PathTracer::new(scene, caster, &o.reference_options());
    let ems = ByArea::emitters(scene);
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
        // With `--bins`, per axis of the normal, 6 × 10 bins over the scene's box of (path
        // tracer sum, solver sum, points); the cache is then not read.
        let binning = o.bins;
        let mut bins = vec![[[(0.0f64, 0.0f64, 0usize); 10]; 6]; 3];
        let cached = std::fs::read_to_string(&file).ok().and_then(|c| {
            let v: Vec<f64> = c
                .split_whitespace()
                .filter_map(|x| x.parse().ok())
                .collect();
            (v.len() == 3).then_some(v)
        });
        if let (false, Some(v)) = (binning, cached) {
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
            let p = point_on(scene, t, &mut rng);
            // Covered and shut points are not part of the receiver (the solver's H is the
            // mean over open points): they count as the mean, i.e. are left out.
            if covers.covered(t as u32, n, p) {
                continue;
            }
            open += 1;
            // Indirect: one path, less the emission of a directly hit emitter front.
            let l = indirect_radiance(scene, caster, &pt, (p, n), &mut rng);
            let dh = direct_emitted(scene, caster, &ems, (p, n), &mut rng);
            let h = PI * l.element_sum() as f64 + dh;
            if binning {
                let hs = leaf_irradiance(&sol.elements, leaf_at(sol, root(sol, t as u32, back), p));
                let ax = (0..3)
                    .max_by(|&a, &b| n[a].abs().total_cmp(&n[b].abs()))
                    .unwrap();
                let (u, v) = match ax {
                    0 => (2, 1),
                    1 => (0, 2),
                    _ => (0, 1),
                };
                let bb = scene.bbox;
                let fu =
                    ((p[u] - bb.min[u]) / (bb.max[u] - bb.min[u]) * 10.0).clamp(0.0, 9.0) as usize;
                let fv =
                    ((p[v] - bb.min[v]) / (bb.max[v] - bb.min[v]) * 6.0).clamp(0.0, 5.0) as usize;
                let c = &mut bins[ax][5 - fv][fu];
                c.0 += h;
                c.1 += hs;
                c.2 += 1;
            }
            s += h;
            s2 += h * h;
            sd += dh;
        }
        if binning {
            for (ax, b) in bins.iter().enumerate() {
                if b.iter().flatten().all(|c| c.2 == 0) {
                    continue;
                }
                println!(
                    "object {obj}, normal along axis {ax}: solver / path tracer irradiance and \
                     points per bin (columns: the first other axis, low to high; rows: the \
                     second, high to low; over the scene's box)"
                );
                for row in b {
                    let line: Vec<String> = row
                        .iter()
                        .map(|c| {
                            if c.2 == 0 {
                                "      -    ".into()
                            } else if c.0 <= 0.0 {
                                format!(" dark {:5}", c.2)
                            } else {
                                format!("{:.3} {:5}", c.1 / c.0, c.2)
                            }
                        })
                        .collect();
                    println!("  {}", line.join(" "));
                }
            }
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
pub fn self_consistency(
    o: &Opts,
    scene: &Scene,
    tree: &ClusterTree,
    caster: &RayCaster,
    sol: &Solution,
) {
    let el = &sol.elements;
    // The solver's irradiance is the mean over the points it does not leave out.
    let ems = ByArea::emitters(scene);
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
            let p = point_on(scene, t, &mut rng);
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
