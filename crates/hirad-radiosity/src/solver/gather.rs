//! Gather: each receiver sums `K · B_src` over its links, in parallel per receiver.
//!
//! Cluster receivers keep one [`Entry`] per link, handed to their surfaces in push-pull.
//! Deposits: a link whose shadow rays disagree hands its transfer to the parts of a surface
//! receiver where its rays saw the source ([`Deposit`]), not evenly over the receiver, so
//! that the many weak links no oracle refines do not light what furniture hides.

use super::Solver;
use crate::element::Kind;
use crate::link::Deposit;
use glam::{DVec3, Vec3};
use rayon::prelude::*;

/// A receiver's deposits ([`Deposit`]) are followed down only as many levels as leave this
/// many of their points per cell on average; below that a cell's share is mostly noise.
const DEPOSIT_POINTS_PER_CELL: usize = 4;

/// Receivers gathered at a time (see [`Solver::gather`]).
const GATHER_CHUNK: usize = 1 << 12;

/// Gather output of one receiver.
#[derive(Clone, Debug, Default)]
struct Gathered {
    recv: u32,
    h: DVec3,
    /// Irradiance (channel sum) from cluster sources (surface receivers).
    h_cluster: f64,
    /// Sum of the link kernels (surface receivers).
    k_sum: f64,
    /// Cluster receivers: one entry per link.
    entries: Vec<Entry>,
    /// Surface receivers: transfers that land where their rays saw the source.
    deposits: Vec<(Deposit, DVec3)>,
}

/// What a cluster received through one link, handed to its surfaces in push-pull.
#[derive(Clone, Copy, Debug)]
pub(super) struct Entry {
    /// Unit direction from the cluster's centroid to the source's.
    pub(super) d: Vec3,
    /// Source centroid and [`Element::facing_normal`] (for [`facing_weight`]).
    ///
    /// [`Element::facing_normal`]: crate::element::Element::facing_normal
    pub(super) sc: Vec3,
    pub(super) sn: Vec3,
    /// Irradiance `K·B_src`.
    pub(super) h: DVec3,
    /// Kernel.
    pub(super) k: f32,
}

impl Solver<'_> {
    /// Gather over every link, per receiver, a chunk of receivers at a time (their hand-outs
    /// and deposits go straight into the flat arrays, not held twice).
    pub(super) fn gather(&mut self) {
        for h in self.el.h.iter_mut() {
            *h = DVec3::ZERO;
        }
        for v in self.h_cluster.iter_mut() {
            *v = 0.0;
        }
        for v in self.k_sum.iter_mut() {
            *v = 0.0;
        }
        self.entries.clear();
        for r in self.cl_ranges.iter_mut() {
            *r = (0, 0);
        }
        self.deposits.clear();
        self.dep_ranges.clear();
        self.dep_ranges.resize(self.el.len(), (0, 0));
        let n_groups = self.set.groups.len();
        for start in (0..n_groups).step_by(GATHER_CHUNK) {
            let el = &self.el;
            let set = &self.set;
            let links = &set.links;
            let res: Vec<Gathered> = set.groups[start..(start + GATHER_CHUNK).min(n_groups)]
                .par_iter()
                .map(|&(r, a, b)| {
                    let re = &el.elems[r as usize];
                    let mut g = Gathered {
                        recv: r,
                        ..Default::default()
                    };
                    for l in &links[a as usize..b as usize] {
                        let contrib = set.gather(l, el);
                        let se = &el.elems[l.src as usize];
                        if re.kind == Kind::Cluster {
                            let d = (se.centroid - re.centroid).normalize_or_zero();
                            g.entries.push(Entry {
                                d,
                                sc: se.centroid,
                                sn: se.facing_normal(),
                                h: contrib,
                                k: l.k,
                            });
                        } else {
                            if l.deposit.depth() > 0 {
                                g.deposits.push((l.deposit, contrib));
                            } else {
                                g.h += contrib;
                            }
                            g.k_sum += l.k as f64;
                            if se.kind == Kind::Cluster {
                                g.h_cluster += contrib.element_sum();
                            }
                        }
                    }
                    // Deposits are followed only as deep as the receiver's points give each cell
                    // at least `DEPOSIT_POINTS_PER_CELL` of them; none deep: spread evenly.
                    let pts: usize = g.deposits.iter().map(|d| d.0.points()).sum();
                    let mut depth = 0;
                    while depth < Deposit::LEVELS
                        && pts >= DEPOSIT_POINTS_PER_CELL << (2 * (depth + 1))
                    {
                        depth += 1;
                    }
                    if depth == 0 {
                        for (_, c) in g.deposits.drain(..) {
                            g.h += c;
                        }
                    } else {
                        for d in &mut g.deposits {
                            d.0 = d.0.truncated(depth);
                        }
                    }
                    g
                })
                .collect();
            for g in res {
                let id = g.recv as usize;
                if !g.deposits.is_empty() {
                    let s = self.deposits.len() as u32;
                    self.deposits.extend_from_slice(&g.deposits);
                    self.dep_ranges[id] = (s, self.deposits.len() as u32);
                }
                if self.el.elems[id].kind == Kind::Cluster {
                    let s = self.entries.len() as u32;
                    self.entries.extend_from_slice(&g.entries);
                    self.cl_ranges[id] = (s, self.entries.len() as u32);
                } else {
                    self.el.h[id] = g.h;
                    self.h_cluster[id] = g.h_cluster;
                    self.k_sum[id] = g.k_sum;
                }
            }
        }
        self.note_peak();
    }
}
