//! Modes `leaf` (every link into one leaf and its surface ancestors) and `objlinks` (every
//! link into one object's surfaces): delivered irradiance against brute force.
use crate::elements::{leaf_irradiance, object_index, object_of};
use crate::estimate::brute_irradiance;
use crate::opts::Opts;
use hirad::cluster::ClusterTree;
use hirad::radiosity::element::Kind;
use hirad::radiosity::link::Deposit;
use hirad::radiosity::overlap::Covers;
use hirad::radiosity::Solution;
use hirad::ray::RayCaster;
use hirad::rng::SplitMix64;
use hirad::scene::Scene;
use rayon::prelude::*;

/// Every link into surface leaf `--leaf` and its surface ancestors: irradiance delivered
/// (`K·B`, channel sum) against brute force over the link's receiver (N/10 open points, the
/// analytic form factor to each leaf of the source times one shadow ray, the leaf's own B).
pub fn leaf_links(o: &Opts, scene: &Scene, tree: &ClusterTree, caster: &RayCaster, sol: &Solution) {
    let el = &sol.elements;
    let covers = Covers::build(scene, tree, o.two_sided);
    let leaf = match o.leaf.expect("leaf needs --leaf ID|max") {
        // The leaf of the largest radiosity (channel sum) that emits nothing.
        u32::MAX => {
            let el = &sol.elements;
            let l = sol
                .leaves()
                .into_iter()
                .filter(|&l| el.elems[l as usize].emission.max_element() <= 0.0)
                .max_by(|&a, &b| {
                    el.b[a as usize]
                        .element_sum()
                        .total_cmp(&el.b[b as usize].element_sum())
                })
                .expect("a leaf");
            println!(
                "leaf {l}: B {:?}, centroid {:?}, area {:.3e}",
                el.b[l as usize], el.elems[l as usize].centroid, el.elems[l as usize].area
            );
            l
        }
        id => id,
    };
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
            let src_obj = &scene.objects[object_of(scene, el, l.src)];
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
    // The pooled shaping's view of the leaf: per ancestor within `Deposit::LEVELS`, its links'
    // sample points (and open ones) on the leaf's side of each level, against all of them.
    for (lvl, &r) in chain.iter().enumerate().skip(1) {
        if lvl > Deposit::LEVELS as usize {
            break;
        }
        let mut want = 0u32;
        for k in 0..lvl {
            let c = chain[k];
            let p = &el.elems[chain[k + 1] as usize];
            want |= (c - p.first_child) << (2 * (lvl - 1 - k));
        }
        // Whether a path follows the leaf's for its first `j` levels.
        let towards_leaf = |path: u32, j: usize| {
            let mask = (1u32 << (2 * j)) - 1;
            path & mask == want & mask
        };
        let mut at = vec![(0u64, 0u64); lvl + 1];
        let mut by: std::collections::BTreeMap<&str, (u64, u64, u64, u64)> = Default::default();
        for l in sol.links.links.iter().filter(|l| l.recv == r) {
            let d = l.deposit;
            let b = by
                .entry(scene.objects[object_of(scene, el, l.src)].as_str())
                .or_default();
            for i in 0..d.points() {
                let open = d.open(i) as u64;
                b.0 += 1;
                b.1 += open;
                if towards_leaf(d.path(i), lvl) {
                    b.2 += 1;
                    b.3 += open;
                }
                for (j, a) in at.iter_mut().enumerate() {
                    if towards_leaf(d.path(i), j) {
                        a.0 += 1;
                        a.1 += open;
                    }
                }
            }
        }
        let shares: Vec<String> = at
            .iter()
            .map(|a| format!("{}/{} ({:.2})", a.1, a.0, a.1 as f64 / a.0.max(1) as f64))
            .collect();
        println!(
            "level {lvl}: open/points from the element down to the leaf: {}",
            shares.join(" → ")
        );
        for (obj, b) in &by {
            println!(
                "  from {obj}: open/points {}/{} over the element, {}/{} on the leaf",
                b.1, b.0, b.3, b.2
            );
        }
    }
    println!(
        "handed out by clusters, or moved by deposits (H − Σ K·B): {:.3}",
        leaf_irradiance(el, leaf) - tot.0
    );
}

/// Links into the surface elements of `--object`: delivered power against brute force, by
/// source class and by source object.
pub fn object_links(
    o: &Opts,
    scene: &Scene,
    tree: &ClusterTree,
    caster: &RayCaster,
    sol: &Solution,
) {
    let name = o.object.as_deref().expect("objlinks needs --object NAME");
    let obj = object_index(scene, name);
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
            let sobj = object_of(scene, el, l.src);
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
