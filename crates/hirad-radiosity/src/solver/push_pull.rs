//! Push-pull: irradiance down through the clusters and the surface quadtrees to the
//! leaves, leaf radiosity `E + ρ (H + H_direct)`, area averages back up, and the power
//! balance of the iteration.

use super::Solver;
use crate::cluster_model::hand_out_weight;
use crate::element::Elements;
use crate::link::Deposit;
use crate::overlap::Covers;
use glam::DVec3;
use hirad_accel::cluster::NONE;
use rayon::prelude::*;

/// Result of push-pull below one root surface.
#[derive(Clone, Debug, Default)]
struct RootResult {
    /// Per element below the root and the root: its radiosity and open share.
    updates: Vec<(u32, DVec3, f32)>,
    incident: DVec3,
    absorbed: f64,
    gathered: f64,
    gathered_cluster: f64,
    direct: f64,
    /// Leaves whose gain `ρ · Σ K` exceeds 1.
    gain_above_one: u64,
    /// Leaves whose irradiance exceeds twice the brightest radiosity before.
    above_brightest: u64,
    /// Leaves' open area, Σ open·K, open area with K < 0.9 and with K > 1.1.
    k_stats: [f64; 4],
}

impl Solver<'_> {
    /// Push irradiance down to the leaves (through clusters, then surface quadtrees), compute
    /// leaf radiosity, pull area averages up; accumulate the power balance.
    pub(super) fn push_pull(&mut self) {
        let roots = self.el.roots();
        let el = &self.el;
        let tree = self.tree;
        let entries = &self.entries;
        let cl_ranges = &self.cl_ranges;
        let (strata, st_ranges) = (&self.strata, &self.st_ranges);
        let h_cluster = &self.h_cluster;
        let k_sum = &self.k_sum;
        let reception = self.cfg.cluster_receive;
        // Twice the brightest radiosity of the iteration before among the elements lit
        // other than through links (emitters, and surfaces the sun or sky reaches): the most
        // any leaf's irradiance from its links may reach (a surface lit only through links
        // cannot be the brightest), with room for the kernels' sampling.
        let bright = 2.0
            * (0..el.len())
                .filter(|&i| {
                    el.elems[i].emission.max_element() > 0.0 || el.direct[i].max_element() > 0.0
                })
                .fold(0.0f64, |m, i| m.max(el.b[i].max_element()));
        let covers = &self.covers;
        let emission = self.cfg.cluster_emission;
        let deps = (&self.deposits[..], &self.dep_ranges[..]);
        // Irradiance handed down by the clusters above each root surface, computed in cluster
        // tree order (`pp_order`) so that the entries of the clusters that consecutive surfaces
        // share stay in cache.
        let from_clusters: Vec<(DVec3, f64)> = self
            .pp_order
            .par_iter()
            .map(|&r| {
                let e = &el.elems[r as usize];
                let n = e.normal;
                let mut hc = DVec3::ZERO;
                let mut kc = 0.0f64;
                let mut node = tree.surface_node[e.tri as usize];
                while node != NONE {
                    if (node as usize) < cl_ranges.len() {
                        let (a, b) = cl_ranges[node as usize];
                        let (c, d) = st_ranges[node as usize];
                        for en in entries[a as usize..b as usize]
                            .iter()
                            .chain(&strata[c as usize..d as usize])
                        {
                            let w = hand_out_weight(
                                reception,
                                emission,
                                (e.centroid, n),
                                en.d,
                                (en.sc, en.sn),
                            );
                            hc += en.h * w;
                            kc += en.k as f64 * w;
                        }
                    }
                    node = tree.nodes[node as usize].parent;
                }
                (hc, kc)
            })
            .collect();
        let mut hk = vec![(DVec3::ZERO, 0.0f64); roots.len()];
        for (&r, v) in self.pp_order.iter().zip(from_clusters) {
            hk[(r - roots.start) as usize] = v;
        }
        let results: Vec<RootResult> = roots
            .clone()
            .into_par_iter()
            .map(|r| {
                let e = &el.elems[r as usize];
                let (hc, kc) = hk[(r - roots.start) as usize];
                let mut out = RootResult::default();
                let area = e.area as f64;
                let open = area * el.open[r as usize] as f64;
                out.gathered_cluster = open * hc.element_sum();
                out.gathered = out.gathered_cluster;
                let (b, open) = push_rec(
                    el,
                    covers,
                    (h_cluster, k_sum, bright),
                    deps,
                    r,
                    (hc, kc, &[]),
                    &mut out,
                );
                out.updates.push((r, b, (open / area.max(1e-300)) as f32));
                out.incident /= area;
                out
            })
            .collect();
        let mut pw = crate::stats::PowerStats::default();
        let mut gain_above_one = 0u64;
        let mut above_brightest = 0u64;
        let mut ks = [0.0f64; 4];
        self.root_irr = Vec::with_capacity(results.len());
        for res in results {
            for (id, b, open) in res.updates {
                self.el.b[id as usize] = b;
                self.el.open[id as usize] = open;
            }
            self.root_irr.push(res.incident);
            pw.absorbed += res.absorbed;
            pw.gathered += res.gathered;
            pw.gathered_cluster += res.gathered_cluster;
            gain_above_one += res.gain_above_one;
            above_brightest += res.above_brightest;
            for (a, b) in ks.iter_mut().zip(res.k_stats) {
                *a += b;
            }
            pw.emitted += res.direct;
        }
        for r in roots {
            let e = &self.el.elems[r as usize];
            pw.emitted += e.emission.as_dvec3().element_sum() * self.open_area(r);
        }
        self.pull_clusters();
        pw.radiosity = self.total_power();
        pw.escaping = pw.radiosity - pw.gathered;
        self.stats.power = pw;
        self.stats.leaves_gain_above_one = gain_above_one;
        self.stats.leaves_above_brightest = above_brightest;
        let a = ks[0].max(1e-300);
        self.stats.kernel_sum_mean = ks[1] / a;
        self.stats.kernel_sum_low = ks[2] / a;
        self.stats.kernel_sum_high = ks[3] / a;
    }

    /// Cluster radiosity = average of the children over their open area (the part that
    /// emits), bottom-up; the cluster's open share is the children's open area over its area.
    pub(super) fn pull_clusters(&mut self) {
        let nc = self.el.num_clusters as usize;
        for id in (0..nc).rev() {
            let e = &self.el.elems[id];
            let (mut acc, mut open) = (DVec3::ZERO, 0.0f64);
            for k in self.el.children(id as u32) {
                let a = self.open_area(k);
                acc += self.el.b[k as usize] * a;
                open += a;
            }
            let a = e.area as f64;
            self.el.b[id] = if open > 0.0 { acc / open } else { DVec3::ZERO };
            self.el.open[id] = if a > 0.0 { (open / a) as f32 } else { 1.0 };
        }
    }

    /// The part of element `id`'s area that receives and emits.
    pub(super) fn open_area(&self, id: u32) -> f64 {
        self.el.elems[id as usize].area as f64 * self.el.open[id as usize] as f64
    }
}

/// Push-pull below surface element `id` with irradiance `down` from above; returns its B
/// and its open area (the part not covered: [`Covers`]).
///
/// `down` carries the irradiance and the kernel sum gathered above the element. Irradiance
/// is the mean over open points (the kernels' receiver), so power is counted on the open
/// area, and a parent's radiosity is its children's average over their open area.
fn push_rec(
    el: &Elements,
    covers: &Covers,
    (h_cluster, k_sum, bright): (&[f64], &[f64], f64),
    deps: Deposits,
    id: u32,
    down: (DVec3, f64, &[Carried]),
    out: &mut RootResult,
) -> (DVec3, f64) {
    let e = &el.elems[id as usize];
    let own = el.h[id as usize];
    let open_here = open_area(el, covers, id);
    out.gathered += open_here * own.element_sum();
    out.gathered_cluster += open_here * h_cluster[id as usize];
    let mut h = down.0 + own;
    let k = down.1 + k_sum[id as usize];
    // Deposits: this element's own, split into their points, and those carried from above;
    // a point with no level left spreads evenly from here.
    let mut carried: Vec<Carried> = Vec::new();
    let (a, b) = deps.1.get(id as usize).copied().unwrap_or((0, 0));
    for &(d, c) in &deps.0[a as usize..b as usize] {
        out.gathered += open_here * c.element_sum();
        let share = c / d.open_points().max(1) as f64;
        carried.extend(
            (0..d.points())
                .filter(|&i| d.open(i))
                .map(|i| (d.path(i), d.depth(), share)),
        );
    }
    carried.extend_from_slice(down.2);
    carried.retain(|&(_, levels, s)| {
        if levels == 0 || e.num_children == 0 {
            h += s;
        }
        levels > 0 && e.num_children > 0
    });
    if e.num_children == 0 {
        out.gain_above_one += (e.rho.max_element() as f64 * k > 1.0) as u64;
        out.above_brightest += (h.max_element() > bright) as u64;
        out.k_stats[0] += open_here;
        out.k_stats[1] += open_here * k;
        out.k_stats[2] += open_here * (k < 0.9) as u8 as f64;
        out.k_stats[3] += open_here * (k > 1.1) as u8 as f64;
        let d = el.direct[id as usize];
        let inc = h + d;
        let rho = e.rho.as_dvec3();
        out.incident += inc * open_here;
        out.absorbed += open_here * ((DVec3::ONE - rho) * inc).element_sum();
        out.direct += open_here * d.element_sum();
        return (e.emission.as_dvec3() + rho * inc, open_here);
    }
    // Each child takes the points in it, at the density of its own open area.
    let mut per_child: [Vec<Carried>; 4] = Default::default();
    if !carried.is_empty() {
        for (j, c) in el.children(id).enumerate() {
            let oc = open_area(el, covers, c);
            for &(p, levels, s) in &carried {
                if (p & 3) as usize == j {
                    if oc > 0.0 {
                        per_child[j].push((p >> 2, levels - 1, s * open_here / oc));
                    } else {
                        h += s;
                    }
                }
            }
        }
    }
    let (mut acc, mut acc_plain, mut open) = (DVec3::ZERO, DVec3::ZERO, 0.0f64);
    for (j, c) in el.children(id).enumerate() {
        let (b, o) = push_rec(
            el,
            covers,
            (h_cluster, k_sum, bright),
            deps,
            c,
            (h, k, &per_child[j]),
            out,
        );
        let ca = el.elems[c as usize].area as f64;
        out.updates.push((c, b, (o / ca.max(1e-300)) as f32));
        acc += b * o;
        acc_plain += b;
        open += o;
    }
    let b = if open > 0.0 {
        acc / open
    } else {
        acc_plain / e.num_children as f64
    };
    (b, open)
}

/// A deposit's point on its way down: remaining path, levels left, irradiance it adds at
/// the current element.
type Carried = (u32, u32, DVec3);

/// The deposits and each element's range in them.
type Deposits<'a> = (&'a [(Deposit, DVec3)], &'a [(u32, u32)]);

/// Open area of surface element `id` (its open share once push-pull has computed it).
pub(super) fn open_area(el: &Elements, covers: &Covers, id: u32) -> f64 {
    let e = &el.elems[id as usize];
    let known = el.open[id as usize];
    e.area as f64
        * if known.is_nan() {
            covers.open_fraction(e.tri, e.normal, &e.verts)
        } else {
            known as f64
        }
}
