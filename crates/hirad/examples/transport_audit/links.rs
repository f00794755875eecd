//! Mode `links`: each link's delivered power against Monte Carlo between its two ends (exact
//! visibility), summed by link class, source treatment and distance over diameter.
use crate::elements::member_roots;
use crate::estimate::{visible, ByArea};
use crate::opts::Opts;
use hirad::cluster::ClusterTree;
use hirad::radiosity::element::{facing_weight, Element, Kind};
use hirad::radiosity::formfactor::sample_triangle;
use hirad::radiosity::link::NO_SAMPLES;
use hirad::radiosity::overlap::Covers;
use hirad::radiosity::Solution;
use hirad::ray::RayCaster;
use hirad::rng::SplitMix64;
use hirad::scene::Scene;
use rayon::prelude::*;
use std::f64::consts::PI;

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
    /// Link index.
    li: usize,
}

/// Audits every link (or those into `--object`) and prints the sums.
pub fn links(o: &Opts, scene: &Scene, tree: &ClusterTree, caster: &RayCaster, sol: &Solution) {
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
                if !visible(caster, (x, er.normal), (y, es.normal)) {
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
                li,
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
    // The surface <- surface links that take the source's mean whose Monte Carlo with the
    // leaves' radiosity differs most from that with the mean.
    let mut top: Vec<&LinkRow> = rows
        .iter()
        .filter(|r| r.class == 0 && r.treat == 0)
        .collect();
    top.sort_by(|a, b| {
        (b.want - b.want_mean)
            .abs()
            .total_cmp(&(a.want - a.want_mean).abs())
    });
    println!(
        "surface <- surface links with the source's mean, largest |MC(leaves) - MC(mean)| first:"
    );
    println!("    link   recv    src lvl(r,s) leaves  B min/mean/max (src)     dist   got        MC(leaves)  MC(mean)   src object");
    for r in top.iter().take(o.rows) {
        let l = &set.links[r.li];
        let (re, se) = (&el.elems[l.recv as usize], &el.elems[l.src as usize]);
        let mut leaves = Vec::new();
        el.leaves_of(l.src, &mut leaves);
        let (lo, hi) = leaves.iter().fold((f64::MAX, 0f64), |a, &s| {
            let b = el.b[s as usize].element_sum();
            (a.0.min(b), a.1.max(b))
        });
        println!(
            "{:8} {:6} {:6} {:3},{:3} {:6}  {:7.3}/{:7.3}/{:7.3} {:6.2} {:10.3e} {:10.3e} {:10.3e} {}",
            r.li, l.recv, l.src, re.level, se.level, leaves.len(), lo,
            el.b[l.src as usize].element_sum(), hi, r.dist, r.got, r.want, r.want_mean,
            scene.objects[scene.tri_object[se.tri as usize] as usize]
        );
    }
}
