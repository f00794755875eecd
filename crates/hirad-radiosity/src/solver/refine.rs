//! Refinement: one sweep of the oracle over the links, a chunk at a time.
//!
//! Each pass decides every link of a chunk in parallel (rayon `map` + `collect` keeps the
//! order), then creates the children that the decisions need sequentially in ascending
//! element order, then replaces split links by their children links in list order.
//!
//! Resolution: both ends of a link at the minimum element area while the oracle still asks
//! for refinement make the link unresolved; its near-field kernel integrates more finely, and
//! where its transfer varies across a surface receiver (a shadow boundary, a close source) the
//! receiver splits up to `shadow_levels` further levels, and one more beside a close surface
//! source while it is wider than its distance to it. A subdivided source whose children's
//! radiosity differs by more than the oracle allows hands out the radiosity of the leaves its
//! samples land on.
//!
//! Visibility: the hand-out of a link into a cluster whose shadow rays disagree cannot tell the
//! surfaces the source sees from those it does not, whatever the transfer's size: a
//! directional cluster hands it to the surfaces whose samples saw the source instead, an
//! isotropic one splits, as does an isotropic cluster source (its receiver would take the
//! cluster's mean). When all of a directional cluster receiver's rays saw the source, each of
//! its children that no sample landed on is tested with one more ray first: a blocked one
//! makes the rays disagree (a cluster straddling a wall would otherwise light its far side).
//! A directional cluster receiver's link that could have split on its rays' outcome and is
//! kept takes its kernel from independent rays: kept on the rays that chose it, the links
//! whose rays all missed the source would stay dark while those that saw it went down.
//!
//! Outlines: the oracle judges each link alone, so a wall lit by a whole room keeps many weak
//! links at a big element, and their light lands behind what hangs in front of it. A surface
//! receiver whose links with disagreeing rays together carry more than the oracle allows
//! (measured by the gather) sends those links to its children, down to the minimum area; the
//! links it keeps are drawn again with independent rays, so that none is kept for the outcome
//! it was chosen on (those of earlier sweeps once per receiver). A link evaluated again for
//! its source's leaves takes rays independent of those it was first kept on.

use super::budget::Growth;
use super::gather::Entry;
use super::{Solver, STRADDLES, STRADDLE_DECIDED};
use crate::config::{Oracle, VisibilityMode};
use crate::element::{Element, Elements, Kind};
use crate::formfactor::KernelCtx;
use crate::link::{Deposit, Kept, Link, LinkSet, Sample, NO_SAMPLES};
use crate::oracle::{self, Action};
use glam::DVec3;
use hirad_core::{Error, Result};
use rayon::prelude::*;
use std::sync::atomic::{AtomicBool, Ordering};

/// Sample points that share out a kept link's light among the surfaces of a directional
/// cluster receiver whose rays disagree.
const HAND_OUT_POINTS: usize = 16;

/// Links decided at a time in a refinement pass (see [`Solver::settle`]).
const REFINE_CHUNK: usize = 1 << 18;

/// What refinement decides for a link: the action, the link (evaluated when kept), the rays
/// cast, and what a kept link records of its samples.
pub(super) type Decided = (Action, Link, u64, Option<Box<Recorded>>);

/// A decision with what the chunk's serial bookkeeping needs of the link's ends, read beside
/// the decision (in parallel) rather than from scattered elements after it.
pub(super) struct Decision {
    action: Action,
    /// The end split is a surface leaf: it is subdivided before its links come down.
    split_leaf: bool,
    link: Link,
    rays: u32,
    /// A split: the links it makes. Kept: the gather bytes it holds (see [`Solver::gather`]).
    grow: u64,
    rec: Option<Box<Recorded>>,
}

/// The lists filing fills besides the links kept: the links of the next pass, the samples and
/// the open surfaces' runs.
type Lists<'a> = (&'a mut Vec<Link>, &'a mut Vec<Sample>, &'a mut Vec<Sample>);

/// What refinement holds while it settles a chunk: the links kept, the link slots held
/// beside them ([`Growth::room`]), the links to decide in the next pass, and the samples.
struct Sizes {
    kept: usize,
    room: usize,
    next: usize,
    samples: usize,
}

/// What [`file()`] kept: links, the gather bytes they will hold, and their samples.
#[derive(Default)]
struct Filed {
    links: usize,
    gather_bytes: usize,
    samples: usize,
}

/// Files settled decisions: kept links go to `keep` (their samples to `samples`, their open
/// surfaces to `open`), the `new_links` children of split ones to `next`.
fn file(
    el: &Elements,
    (decided, new_links): (Vec<Decision>, usize),
    keep: &mut impl FnMut(Link),
    (next, samples, open): Lists,
) -> Filed {
    let mut f = Filed::default();
    next.reserve(new_links);
    for d in decided {
        let mut l = d.link;
        match d.action {
            Action::Keep => {
                f.links += 1;
                f.gather_bytes += d.grow as usize;
                if let Some(m) = d.rec {
                    if !m.samples.is_empty() {
                        f.samples += m.samples.len();
                        l.samples = samples.len() as u32;
                        samples.extend_from_slice(&m.samples);
                    }
                    if !m.open.is_empty() {
                        f.samples += m.open.len() + 1;
                        l.open_members = open.len() as u32;
                        open.push((m.open.len() as u32, 0.0));
                        open.extend_from_slice(&m.open);
                    }
                }
                keep(l)
            }
            Action::Drop => {}
            Action::SplitRecv => {
                for c in el.children(l.recv) {
                    next.push(Link::new(c, l.src));
                }
            }
            Action::SplitSrc => {
                for c in el.children(l.src) {
                    next.push(Link::new(l.recv, c));
                }
            }
            Action::SplitBoth => {
                let kids: Vec<u32> = el.children(l.recv).collect();
                for &a in &kids {
                    for &b in &kids {
                        next.push(Link::new(a, b));
                    }
                }
            }
        }
    }
    f
}

/// The samples a kept link records: from a directional cluster source, each sample's surface
/// and share ([`Link::samples`]); into a cluster whose rays disagreed, the surfaces that
/// saw the source ([`Link::open_members`]).
pub(super) struct Recorded {
    samples: Vec<Sample>,
    open: Vec<Sample>,
}

impl Solver<'_> {
    /// One refinement sweep over every link (the root self-link on the first iteration).
    pub(super) fn refine(&mut self, first: bool, cancel: &AtomicBool) -> Result<()> {
        let per_link = self.cfg.shadow_rays.max(1);
        let (links, mut samples, mut open) = if first {
            (Vec::new(), Vec::new(), Vec::new())
        } else {
            let set = std::mem::take(&mut self.set);
            (set.links, set.samples, set.open_members)
        };
        // The gather rebuilds its hand-outs and deposits from the refined links.
        self.entries = Vec::new();
        self.strata = Vec::new();
        self.deposits = Vec::new();
        self.kept_links = 0;
        self.kept_gather_bytes = 0;
        self.kept_samples = 0;
        // The first pass decides the links of the last sweep, a chunk at a time, and writes
        // the ones it keeps over those decided (never more than were decided): in their
        // order, and with no second copy of the links.
        let mut next: Vec<Link> = Vec::new();
        let mut links = links;
        let (mut read, mut write) = (0, 0);
        while read < links.len() {
            if cancel.load(Ordering::Relaxed) {
                return Err(Error::Interrupted);
            }
            let end = (read + REFINE_CHUNK).min(links.len());
            let chunk = &links[read..end];
            let decided = self.decide_chunk(chunk, !self.budget_hit);
            let sizes = Sizes {
                kept: write,
                room: read - write,
                next: next.len(),
                samples: samples.len() + open.len(),
            };
            let settled = self.settle(chunk, decided, sizes, links.len() - end)?;
            let mut keep = |l: Link| {
                links[write] = l;
                write += 1;
            };
            self.file(settled, &mut keep, (&mut next, &mut samples, &mut open));
            read = end;
        }
        // The slots of the links not kept are given back.
        links.truncate(write);
        links.shrink_to_fit();
        let mut done = Kept::sorted(links);
        let mut frontier = if first { vec![Link::new(0, 0)] } else { next };
        while !frontier.is_empty() {
            // Each later pass decides the children of the links split, a chunk at a time:
            // the decisions of a chunk are all that is held beside the links, and the
            // frontier's memory is given back as it is consumed (reversed, so that chunks
            // come off its end in order).
            frontier.reverse();
            let mut next: Vec<Link> = Vec::new();
            while !frontier.is_empty() {
                if cancel.load(Ordering::Relaxed) {
                    return Err(Error::Interrupted);
                }
                let mut chunk =
                    frontier.split_off(frontier.len() - frontier.len().min(REFINE_CHUNK));
                frontier.shrink_to_fit();
                chunk.reverse();
                let decided = self.decide_chunk(&chunk, !self.budget_hit);
                let sizes = Sizes {
                    kept: done.len(),
                    room: done.late(),
                    next: next.len(),
                    samples: samples.len() + open.len(),
                };
                let settled = self.settle(&chunk, decided, sizes, frontier.len())?;
                let mut keep = |l: Link| done.push(l);
                self.file(settled, &mut keep, (&mut next, &mut samples, &mut open));
            }
            frontier = next;
        }
        self.set = LinkSet::from_links(done, (samples, open), per_link);
        for f in self.straddle.iter_mut() {
            if *f & STRADDLES != 0 {
                *f |= STRADDLE_DECIDED;
            }
        }
        self.note_peak();
        Ok(())
    }

    /// The decisions on the links of `chunk` (refinement allowed or not).
    fn decide_chunk(&self, chunk: &[Link], allow: bool) -> Vec<Decision> {
        let ctx = self.ctx();
        chunk
            .par_iter()
            .map(|l| self.decision(self.decide(&ctx, l, allow, self.cfg.refine)))
            .collect()
    }

    /// Settles the decisions on `chunk`: counts their growth against the memory budget (past
    /// it, the chunk is decided again without refinement), subdivides the surfaces split and
    /// marks the children of straddling receivers. `sizes` are what is held now (see
    /// [`Sizes`]); `rest` links of the pass are still to come. Returns the decisions, to file,
    /// and the links their splits make.
    fn settle(
        &mut self,
        chunk: &[Link],
        mut decided: Vec<Decision>,
        Sizes {
            kept,
            room,
            next,
            samples,
        }: Sizes,
        rest: usize,
    ) -> Result<(Vec<Decision>, usize)> {
        let held = kept + rest + chunk.len() + next;
        let (new_links, to_split) = loop {
            // Growth of this chunk.
            let mut new_links = 0usize;
            let mut to_split: Vec<u32> = Vec::new();
            for d in &decided {
                match d.action {
                    Action::SplitRecv | Action::SplitSrc | Action::SplitBoth => {
                        new_links += d.grow as usize
                    }
                    _ => {}
                }
                if d.split_leaf {
                    to_split.push(match d.action {
                        Action::SplitRecv => d.link.recv,
                        _ => d.link.src,
                    });
                }
            }
            to_split.sort_unstable();
            to_split.dedup();
            let projected = self.projected(&Growth {
                links: held + new_links,
                elements: to_split.len() * 4,
                samples,
                pending: rest + chunk.len() + next + new_links,
                // A later pass decides the first chunk of all the links.
                chunk: REFINE_CHUNK.min(held + new_links),
                room,
            });
            match self.cfg.max_memory {
                Some(budget) if new_links > 0 && projected > budget => {
                    self.budget_hit = true;
                    let msg = format!(
                        "memory budget {:.3} GB reached ({} links, {} elements): refinement \
                         stopped, the solution is coarser than eps = {:.3e} asks for",
                        budget as f64 / 1e9,
                        held,
                        self.el.len(),
                        self.eps
                    );
                    tracing::warn!("{msg}");
                    self.stats.warnings.push(msg);
                    // Decide this chunk again without refinement: every link is kept.
                    self.rays += decided.iter().map(|d| d.rays as u64).sum::<u64>();
                    decided = self.decide_chunk(chunk, false);
                }
                _ => break (new_links, to_split),
            }
        };
        self.rays += decided.iter().map(|d| d.rays as u64).sum::<u64>();
        for &id in &to_split {
            self.el.subdivide(id);
        }
        if !to_split.is_empty() {
            let n_before = self.h_cluster.len();
            self.h_cluster.resize(self.el.len(), 0.0);
            self.k_sum.resize(self.el.len(), 0.0);
            self.straddle.resize(self.el.len(), 0);
            if self.has_sun_sky {
                self.compute_direct(n_before as u32, self.el.len() as u32);
            }
        }
        // Children of a straddling receiver split here straddle until their own gather
        // says: new ones, and those it had, whose own links were kept on other grounds
        // (marked decided: only the links coming down are decided on their rays).
        for d in &decided {
            let id = d.link.recv as usize;
            if d.action == Action::SplitRecv && self.straddle[id] & STRADDLES != 0 {
                let e = &self.el.elems[id];
                if e.kind == Kind::Surface {
                    let first = e.first_child as usize;
                    for f in &mut self.straddle[first..first + 4] {
                        if *f & STRADDLES == 0 {
                            *f |= STRADDLES | STRADDLE_DECIDED;
                        }
                    }
                }
            }
        }
        // The peak counts the links held once these are filed: decided, kept, to come and new,
        // by length (the capacity reserved ahead of them is not touched, so not resident), and
        // the slots held beside them.
        let m = self.fixed
            + self.memory_now(held + new_links + room)
            + (chunk.len() * std::mem::size_of::<Decision>()
                + samples * std::mem::size_of::<Sample>()) as u64;
        self.peak = self.peak.max(m);
        Ok((decided, new_links))
    }

    /// Files settled decisions ([`file()`]) and adds what they keep to the counts the memory
    /// budget projects from.
    fn file(&mut self, settled: (Vec<Decision>, usize), keep: &mut impl FnMut(Link), lists: Lists) {
        let f = file(&self.el, settled, keep, lists);
        self.kept_links += f.links;
        self.kept_gather_bytes += f.gather_bytes;
        self.kept_samples += f.samples;
    }

    /// `d` with the growth it brings (see [`Decision`]).
    fn decision(&self, (action, link, rays, rec): Decided) -> Decision {
        let elem = |id: u32| &self.el.elems[id as usize];
        let nk = |id: u32| match elem(id).kind {
            Kind::Surface => 4,
            Kind::Cluster => elem(id).num_children as u64,
        };
        let leaf = |id: u32| elem(id).kind == Kind::Surface && elem(id).num_children == 0;
        let (grow, split_leaf) = match action {
            Action::SplitRecv => (nk(link.recv), leaf(link.recv)),
            Action::SplitSrc => (nk(link.src), leaf(link.src)),
            Action::SplitBoth => (nk(link.recv) * nk(link.recv), false),
            Action::Keep if elem(link.recv).kind == Kind::Cluster => {
                (std::mem::size_of::<Entry>() as u64, false)
            }
            // A shaped receiver has at most one part per 4 of its links' samples
            // (`gather::shape_depth`).
            Action::Keep => (
                (std::mem::size_of::<(Deposit, DVec3)>() * link.deposit.points() / 4) as u64,
                false,
            ),
            Action::Drop => (0, false),
        };
        Decision {
            action,
            split_leaf,
            link,
            rays: rays as u32,
            grow,
            rec,
        }
    }

    /// Receiver `r` below the shadow levels' area, beside surface source `s` and wider than
    /// its distance to it (`A_r > d²`, `d` a lower bound: the larger of the distance from
    /// `r`'s centroid to `s`'s plane and to its bounding sphere), above a quarter of that
    /// area (one more level at most, a cost bound).
    fn beside_close_source(&self, r: &Element, s: &Element) -> bool {
        if s.kind != Kind::Surface || r.area as f64 <= self.shadow_min_area / 4.0 {
            return false;
        }
        let plane = s.normal.dot(r.centroid - s.verts[0]).abs();
        let radius = s
            .verts
            .iter()
            .map(|v| v.distance(s.centroid))
            .fold(0.0, f32::max);
        let d = plane.max(r.centroid.distance(s.centroid) - radius) as f64;
        r.area as f64 > d * d
    }

    pub(super) fn ctx(&self) -> KernelCtx<'_> {
        KernelCtx {
            elems: &self.el,
            tree: self.tree,
            vis: self.vis,
            covers: &self.covers,
            n_rays: self.cfg.shadow_rays as usize,
            seed: self.cfg.seed,
            emission: self.cfg.cluster_emission,
            reception: self.cfg.cluster_receive,
            occlusion: true,
        }
    }

    /// Decide what to do with one link; kept links come back evaluated.
    pub(super) fn decide(&self, ctx: &KernelCtx, l: &Link, allow: bool, ok: Oracle) -> Decided {
        let (ri, sj) = (l.recv, l.src);
        let r = &self.el.elems[ri as usize];
        let s = &self.el.elems[sj as usize];
        if ri == sj {
            return if r.kind == Kind::Cluster && r.num_children > 0 {
                (Action::SplitBoth, *l, 0, None)
            } else {
                (Action::Drop, *l, 0, None)
            };
        }
        let mut link = *l;
        let mut rays = 0;
        let mut eval = None;
        let mut est_raw = None;
        // The unoccluded kernel's range over a surface receiver, when the estimate took it.
        let mut spread = None;
        let mut members = None;
        // The link's estimate is a bound where the ends are near ([`KernelCtx::near_bound`]).
        let mut bounded = false;
        if !link.evaluated() {
            if ctx.is_zero(ri, sj) {
                return (Action::Drop, link, 0, None);
            }
            // Error bound of the isotropic model of a cluster source, per unit F̃.
            let g = if self.cfg.anisotropy_refine {
                ctx.anisotropy(ri, sj)
            } else {
                0.0
            };
            // Near a cluster end the centroid estimate misses the members next to the other
            // end: judge such links on a geometric bound of their kernel instead, down to
            // the minimum element area (below it on both ends refinement cannot resolve the
            // near field, and opening clusters of finely tessellated objects only multiplies
            // links).
            let near = if (r.area.max(s.area) as f64) < self.min_area {
                0.0
            } else {
                ctx.near_bound(ri, sj)
            };
            bounded = near > 0.0;
            match ok {
                Oracle::Bf => {
                    let e = if r.kind == Kind::Surface {
                        let sp = ctx.spread(ri, sj);
                        spread = Some(sp);
                        sp.1
                    } else {
                        ctx.estimate(ri, sj)
                    };
                    est_raw = Some(e);
                    link.est = (e * g.max(1.0)).max(near) as f32;
                }
                Oracle::Error => {
                    let ev = ctx.evaluate(ri, sj, true);
                    rays += ev.rays;
                    link.est = (ev.kmax - ev.kmin).max(ev.est * g).max(near).max(0.0) as f32;
                    eval = Some(ev);
                }
            }
        }
        // The split the oracle asks for when it judges the link on `est`, if either end can be
        // split.
        let split = |est: f64| {
            (allow
                && oracle::wants_refine(
                    ok,
                    self.eps,
                    est,
                    self.el.b[sj as usize],
                    r.rho.as_dvec3(),
                ))
            .then(|| oracle::choose_split(r, s, self.min_area))
            .flatten()
        };
        if let Some(a) = split(link.est as f64) {
            return (a, link, rays, None);
        }
        // A surface receiver whose mixed links together carry more than the oracle allows
        // (a shadow's outline crosses it, [`Solver::straddle`]): those links go to its
        // children down to the minimum area.
        let straddles = allow
            && r.kind == Kind::Surface
            && self.straddle[ri as usize] & STRADDLES != 0
            && r.area as f64 > self.min_area;
        // Rays independent of those a decision was taken on: a link kept because its rays
        // agreed would otherwise keep the outcome it was chosen for (all open or all blocked).
        // `independent` gives the same rays in every sweep (a link evaluated again for its
        // source's leaves: the solution would not settle otherwise), `fresh` new ones each
        // sweep (a link drawn anew, whose earlier rays came from either).
        let independent = KernelCtx {
            seed: ctx.seed ^ 0x0DD5_EED5_0F5E_ED00,
            ..*ctx
        };
        let fresh = KernelCtx {
            seed: independent.seed
                ^ (self.stats.refinements as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15),
            ..*ctx
        };
        // A link evaluated in an earlier sweep on a receiver that straddles since: split when
        // its rays disagree, else drawn again (once: a later sweep would decide on the new
        // rays and keep what it chose).
        let redrawn =
            straddles && link.evaluated() && self.straddle[ri as usize] & STRADDLE_DECIDED == 0;
        if redrawn {
            if link.deposit.mixed() {
                return (Action::SplitRecv, *l, rays, None);
            }
            link.samples = NO_SAMPLES;
            link.open_members = NO_SAMPLES;
        }
        // A subdivided surface source whose children's radiosity differs by more than the
        // oracle allows: its samples take the radiosity of the leaf they land on (a link
        // evaluated before, on the mean, is evaluated again).
        let leaves = s.kind == Kind::Surface && s.num_children > 0 && {
            let (mut lo, mut hi) = (DVec3::splat(f64::INFINITY), DVec3::ZERO);
            for c in self.el.children(sj) {
                lo = lo.min(self.el.b[c as usize]);
                hi = hi.max(self.el.b[c as usize]);
            }
            oracle::wants_refine(ok, self.eps, link.est as f64, hi - lo, r.rho.as_dvec3())
        };
        // A near-field kernel keeps no per-sample leaves: such a link goes down to the
        // source's children instead.
        if leaves && allow && ctx.is_near_field(ri, sj) {
            return (Action::SplitSrc, link, rays, None);
        }
        // A link evaluated before is evaluated again (drawn anew, or for its source's leaves)
        // with rays independent of those it was kept on, and not decided on them again.
        let again = l.evaluated();
        if !link.evaluated() || (leaves && link.samples == NO_SAMPLES) || redrawn {
            // The oracle asks for refinement, but both ends are at their minimum size.
            let unresolved = allow
                && oracle::wants_refine(
                    ok,
                    self.eps,
                    link.est as f64,
                    self.el.b[sj as usize],
                    r.rho.as_dvec3(),
                );
            let mut c_used = ctx;
            let mut ev = match eval {
                Some(ev) => ev,
                None => {
                    c_used = if redrawn {
                        &fresh
                    } else if again {
                        &independent
                    } else {
                        ctx
                    };
                    let ev = c_used.evaluate_with(ri, sj, false, est_raw, unresolved, leaves);
                    rays += ev.rays;
                    ev
                }
            };
            // An unresolved link whose transfer varies across a surface receiver by more than
            // ε — a shadow boundary crosses it (its rays disagree) or the source is close
            // beside it (the unoccluded kernel varies) — may split the receiver
            // `shadow_levels` levels below the minimum area: a view sees the parts of an
            // element apart (the lit side of a shadow, a ceiling beside a lamp). Keeping or
            // splitting on the rays' outcome would bias the kept links (those whose rays all
            // missed the source would stay, those that saw it would be drawn again), so a kept
            // link that could have split takes a kernel from independent rays; so does one
            // kept on a straddling receiver because its rays agreed. Beside a close surface
            // source the receiver goes on while it is wider than its distance to the source,
            // the scale on which the kernel varies ([`Solver::beside_close_source`]).
            let mut redraw = false;
            if unresolved && r.kind == Kind::Surface && !again {
                let shadow = oracle::choose_split(r, s, self.shadow_min_area);
                let split =
                    shadow.or_else(|| self.beside_close_source(r, s).then_some(Action::SplitRecv));
                if let Some(a) = split {
                    let varies = || {
                        let (fmin, fmax) = spread.unwrap_or_else(|| ctx.spread(ri, sj));
                        oracle::wants_refine(
                            Oracle::Error,
                            self.eps,
                            fmax - fmin,
                            self.el.b[sj as usize],
                            r.rho.as_dvec3(),
                        )
                    };
                    if (ev.mixed && shadow.is_some()) || varies() {
                        return (a, *l, rays, None);
                    }
                    // Beside a close source the choice did not read the rays.
                    redraw = shadow.is_some();
                }
            }
            if straddles && !again {
                if ev.deposit.mixed() {
                    return (Action::SplitRecv, *l, rays, None);
                }
                redraw = true;
            }
            // A cluster receiver hands what it receives to all of its surfaces that face the
            // source: when some samples see the source and some do not, a shadow boundary
            // crosses the cluster and the hand-out would light surfaces the source cannot
            // see, whatever the transfer's size. A directional cluster hands it to the surfaces
            // whose samples saw the source instead ([`Link::open_members`]); an isotropic one,
            // which samples no surface (so the kernel names none), goes down to its children,
            // as does a directional one whose samples all saw the source where a child no
            // sample landed on does not.
            let recv_splits = r.kind == Kind::Cluster && allow && r.num_children > 0;
            if ev.mixed && recv_splits && (ev.open_members.is_empty() || ev.hidden_child) {
                return (Action::SplitRecv, *l, rays, None);
            }
            // Likewise a cluster source whose samples do not carry their own surface's
            // radiosity (the isotropic model): the receiver would take the cluster's mean over
            // surfaces it does not see.
            let src_splits =
                s.kind == Kind::Cluster && ev.members.is_empty() && allow && s.num_children > 0;
            if ev.mixed && src_splits {
                return (Action::SplitSrc, *l, rays, None);
            }
            // The split of a directional cluster receiver follows its rays' outcome: kept on
            // the rays that chose it, the links whose rays all missed the source would stay
            // dark while those whose rays saw it went down, so a kept one takes its kernel from
            // independent rays (which hand it to the surfaces they saw, if they disagree). The
            // isotropic models keep their rays: drawn again, rays that disagree would light
            // surfaces behind a wall. Without shadow rays no split follows an outcome.
            if recv_splits
                && ctx.hands_out_by_surface()
                && ctx.vis.mode() != VisibilityMode::None
                && !redraw
            {
                let second = KernelCtx {
                    seed: c_used.seed ^ 0x5EC0_D0D5_A3F1_17E5,
                    ..*c_used
                };
                ev = second.evaluate_with(ri, sj, false, est_raw, unresolved, leaves);
                rays += ev.rays;
            }
            if redraw {
                ev = fresh.evaluate_with(ri, sj, false, est_raw, unresolved, leaves);
                rays += ev.rays;
            }
            // A kept link into a directional cluster whose rays disagree hands its light to
            // the surfaces its samples saw and the parts of the cluster around them, in
            // proportion to what they received (`KernelEval::open_members`): a few samples
            // would pour a whole cluster's light onto a few (possibly tiny) surfaces. The
            // shares come from a denser, independent draw instead; the light, its total, stays
            // this link's.
            if ev.mixed && !ev.open_members.is_empty() {
                let dense = KernelCtx {
                    seed: c_used.seed ^ 0x4A4D_0075_5EED_5A4E,
                    n_rays: c_used.n_rays.max(HAND_OUT_POINTS),
                    ..*c_used
                };
                let d = dense.evaluate_with(ri, sj, false, est_raw, unresolved, false);
                rays += d.rays;
                if d.mixed && !d.open_members.is_empty() {
                    ev.open_members = d.open_members;
                }
            }
            link.k = ev.k as f32;
            link.deposit = ev.deposit;
            link.draw = ev.draw;
            let has_members = !ev.members.is_empty();
            if has_members || !ev.open_members.is_empty() {
                members = Some(Box::new(Recorded {
                    samples: ev.members,
                    open: ev.open_members,
                }));
            }
            // Where no bound judged the link, a sampled kernel above the estimate shows that
            // the estimate missed something (surfaces of a cluster much nearer the other end
            // than its centre, or in front of a plane its centre lies behind): judge that on
            // the unoccluded kernel (the estimate's quantity) of sample points drawn apart from
            // those the link keeps, so that neither the rays' outcome nor where the kept points
            // fell chooses which links stay (judged on the kept points, the links whose points
            // came out low stayed: a bias towards dark). Between two surfaces the estimate is
            // the kernel's largest value over the receiver ([`KernelCtx::spread`]), which the
            // kept points seldom exceed: judged on them.
            if !bounded {
                let cluster_end = r.kind == Kind::Cluster || s.kind == Kind::Cluster;
                let ku = if cluster_end && split(f64::INFINITY).is_some() {
                    let judge = KernelCtx {
                        seed: c_used.seed ^ 0x1D6E_5A3B_0C4F_77E1,
                        occlusion: false,
                        ..*c_used
                    };
                    judge
                        .evaluate_with(ri, sj, false, est_raw, unresolved, false)
                        .ku
                } else {
                    ev.ku
                };
                if ku > link.est as f64 {
                    link.est = ku as f32;
                    if let Some(a) = split(ku) {
                        return (a, *l, rays, None);
                    }
                }
                // A form factor is at most one: kept points that say more (a point beside a
                // speck of the other end, weighed by the speck's share of the area) are an
                // outlier the judge's points missed, which kept would let a leaf return more
                // than it receives. Refined wherever an end can be split.
                if cluster_end && ev.ku >= 1.0 && allow {
                    if let Some(a) = oracle::choose_split(r, s, self.min_area) {
                        return (a, *l, rays, None);
                    }
                }
            }
        }
        (Action::Keep, link, rays, members)
    }
}
