//! Mode `coverage`: how many links carry each (receiver point, source point) pair, sampled by
//! cosine rays weighted by the radiosity they reach; a complete solution carries each once.
use crate::elements::{leaf_at, root};
use crate::estimate::{cosine_dir, point_on, ByArea, OFF};
use crate::opts::Opts;
use hirad::cluster::ClusterTree;
use hirad::radiosity::overlap::Covers;
use hirad::radiosity::Solution;
use hirad::ray::RayCaster;
use hirad::rng::SplitMix64;
use hirad::scene::Scene;
use rayon::prelude::*;
use std::collections::HashMap;

/// How many links carry each (receiver point, source point) pair: cosine rays from random open
/// points of every receiving surface (by area, both sides when two-sided), each weighted by
/// the radiosity of the leaf it hits; a pair is carried by a link whose receiver is the
/// point's leaf or an ancestor (surfaces, then clusters) and whose source is the hit leaf or
/// an ancestor. In a solution that covers every pair once, all the weight is in "1".
pub fn coverage(o: &Opts, scene: &Scene, tree: &ClusterTree, caster: &RayCaster, sol: &Solution) {
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
            let mut miss: HashMap<(usize, usize), f64> = Default::default();
            for _ in 0..CHUNK.min(n - c * CHUNK) {
                let i = pick.pick(&mut rng);
                let (t, back) = (i % nt, i >= nt);
                let r = root(sol, t, back);
                let nrm = el.elems[r as usize].normal;
                let p = point_on(scene, t as usize, &mut rng);
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
    let mut miss: HashMap<(usize, usize), f64> = Default::default();
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
