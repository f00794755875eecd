//! Mode `leaves`: per leaf of one object, the solver's irradiance against direct light (and,
//! with `--depth`, one path of indirect light), largest difference in power first.
use crate::elements::{leaf_irradiance, object_index, root};
use crate::estimate::{direct_emitted, indirect_radiance, ByArea};
use crate::opts::Opts;
use hirad::cluster::ClusterTree;
use hirad::radiosity::formfactor::sample_triangle;
use hirad::radiosity::overlap::Covers;
use hirad::radiosity::Solution;
use hirad::ray::RayCaster;
use hirad::render::PathTracer;
use hirad::rng::SplitMix64;
use hirad::scene::Scene;
use rayon::prelude::*;
use std::f64::consts::PI;

/// Per leaf of one object: solver irradiance (from B = E + ρH) against direct light, both
/// over the leaf's open points (those no coplanar triangle covers and no solid shuts, as the
/// solver counts them).
pub fn leaves(o: &Opts, scene: &Scene, tree: &ClusterTree, caster: &RayCaster, sol: &Solution) {
    let name = o.object.as_deref().expect("leaves needs --object NAME");
    let obj = object_index(scene, name);
    let ems = ByArea::emitters(scene);
    let el = &sol.elements;
    let m = (o.samples / 100).max(16);
    let covers = Covers::build(scene, tree, o.two_sided);
    // With --depth, indirect light too: one path per point, at most `depth` bounces.
    let pt = o
        .depth
        .map(|_| PathTracer::new(scene, caster, &o.reference_options()));
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
                sum += direct_emitted(scene, caster, &ems, (p, e.normal), &mut rng);
                if let Some(pt) = &pt {
                    let l = indirect_radiance(scene, caster, pt, (p, e.normal), &mut rng);
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
