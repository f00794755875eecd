//! Modes `shut` (where the radiosity leaving each object lands: back faces, nothing) and
//! `shutcheck` (the solver's shut masks against cosine rays, without a solve).
use crate::elements::{leaf_at, root, short_name, triangles_by_object};
use crate::estimate::{cosine_dir, point_on, ByArea, OFF};
use crate::opts::Opts;
use hirad::cluster::ClusterTree;
use hirad::radiosity::overlap::Covers;
use hirad::radiosity::Solution;
use hirad::ray::RayCaster;
use hirad::rng::SplitMix64;
use hirad::scene::Scene;
use rayon::prelude::*;

/// Where the radiosity leaving each object's points lands: one cosine ray per point, weighted
/// by the leaf radiosity there; a back face (one-sided) or nothing means the point emits into
/// a solid or out of the scene.
pub fn shut(o: &Opts, scene: &Scene, tree: &ClusterTree, caster: &RayCaster, sol: &Solution) {
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
            let tris = ByArea::triangles(scene, ts.clone());
            let mut rng = SplitMix64::new(obj as u64 * 17 + 3);
            let m = o.samples;
            let (mut sb, mut nb, mut nm, mut wb, mut wm) = (0.0f64, 0usize, 0usize, 0.0f64, 0.0f64);
            for _ in 0..m {
                let t = tris.pick(&mut rng) as usize;
                let nrm = scene.normals[t];
                let p = point_on(scene, t, &mut rng);
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
        let name = short_name(scene, r.0);
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

/// The shut masks against 64 cosine rays per point (no solve): per object, the share of its
/// area the masks shut, and of that, the share whose rays meet a front face or nothing (light
/// could reach it), as a mean over the shut points.
pub fn shut_check(o: &Opts, scene: &Scene, tree: &ClusterTree, caster: &RayCaster) {
    let masks = hirad::radiosity::shut::ShutMasks::build(scene, tree, false);
    let by = triangles_by_object(scene);
    let rows: Vec<(usize, f64, f64, f64)> = by
        .par_iter()
        .enumerate()
        .filter(|(_, ts)| !ts.is_empty())
        .map(|(obj, ts)| {
            let tris = ByArea::triangles(scene, ts.clone());
            let mut rng = SplitMix64::new(obj as u64 * 13 + 1);
            let (mut n_shut, mut open_sum) = (0usize, 0.0f64);
            for _ in 0..o.samples {
                let t = tris.pick(&mut rng) as usize;
                let nrm = scene.normals[t];
                let p = point_on(scene, t, &mut rng);
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
