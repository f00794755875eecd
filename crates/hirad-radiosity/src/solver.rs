//! The hierarchical radiosity loop: refine links with the oracle, gather, push-pull, until
//! the total power converges (`spec/radiosity.md`, "The solver").
//!
//! Determinism: refinement works on a flat list of links in passes; each pass decides every
//! link in parallel (rayon `map` + `collect` keeps the order), then creates the children that
//! the decisions need sequentially in ascending element order, then replaces split links by
//! their children links in list order. Kernels use seeds derived from the link's element ids.
//! Gather runs per receiver in parallel, push-pull per root surface in parallel, and every
//! total is summed sequentially in id order: results do not depend on the thread count.
//!
//! Iterations: the links are refined against the current radiosity on the first iteration,
//! again whenever the total power has moved by more than [`REFINE_DRIFT`] since, and once more
//! when the change of total power falls below `tol_converge` (the solve has converged when an
//! iteration that began with a refinement pass changes the power by less than that); the other
//! iterations only gather and push-pull. Nothing caps a leaf's gain `ρ · Σ K`: the leaves whose
//! gain exceeds 1 are counted (`leaves_gain_above_one`), and a solve whose total power passes
//! what any closed scene can hold, `(Φ_emitted + Φ_direct) / (1 − ρ_max)`, is diverging and
//! stops with an error instead of returning a wrong answer.
//!
//! Resolution: both ends of a link at the minimum element area while the oracle still asks
//! for refinement make the link unresolved; its near-field kernel integrates more finely, and
//! where its transfer varies across a surface receiver (a shadow boundary, a close source) the
//! receiver splits up to `shadow_levels` further levels. A subdivided source whose children's
//! radiosity differs by more than the oracle allows hands out the radiosity of the leaves its
//! samples land on.
//!
//! Deposits: a link whose shadow rays disagree hands its transfer to the parts of a surface
//! receiver where its rays saw the source ([`Deposit`]), not evenly over the receiver, so
//! that the many weak links no oracle refines do not light what furniture hides.
//!
//! Sun and sky: the sun's direct irradiance on each surface element is `E_sun·max(0, n·s)`
//! times the fraction of `shadow_rays` jittered points from which a ray towards the sun escapes;
//! the sky (uniform radiance `L_sky` over the directions above the horizon of the up axis) is
//! gathered as ambient occlusion: `π·L_sky` times the fraction of `sky_rays` cosine-weighted
//! directions that are above the horizon and escape. Both are computed once per surface element
//! when it is created and added to the irradiance of the leaves in push-pull.

use super::config::{ClusterEmission, Oracle, Reception, SolverConfig};
use super::element::{facing_weight, Elements, Kind};
use super::formfactor::{sample_triangle, KernelCtx};
use super::link::{Deposit, Link, LinkKind, LinkSet, Sample, NO_SAMPLES};
use super::oracle::{self, Action};
use super::overlap::Covers;
use super::stats::{self, IterStat, SolveStats};
use super::visibility::Visibility;
use glam::{DVec3, Vec3};
use hirad_accel::cluster::{ClusterTree, NONE};
use hirad_core::progress::Progress;
use hirad_core::rng::SplitMix64;
use hirad_core::{Error, Result};
use hirad_scene::Scene;
use rayon::prelude::*;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

/// Refinement is repeated (before the next gather) when the total power has moved by more
/// than this fraction since the links were last refined, and always once more at
/// convergence; in between, iterations only gather and push-pull over the same links.
const REFINE_DRIFT: f64 = 0.05;

/// A receiver's deposits ([`Deposit`]) are followed down only as many levels as leave this
/// many of their points per cell on average; below that a cell's share is mostly noise.
const DEPOSIT_POINTS_PER_CELL: usize = 4;

/// Links decided at a time in a refinement pass (see [`Solver::refine_chunk`]).
const REFINE_CHUNK: usize = 1 << 18;

/// Receivers gathered at a time (see [`Solver::gather`]).
const GATHER_CHUNK: usize = 1 << 12;

/// What refinement decides for a link: the action, the link (evaluated when kept), the rays
/// cast, and the samples of a kept link from a directional cluster.
type Decided = (Action, Link, u64, Option<Box<[Sample]>>);

/// A finished solve: the element hierarchy with its radiosity, the links and the statistics.
#[derive(Clone, Debug)]
pub struct Solution {
    pub elements: Elements,
    pub links: LinkSet,
    /// Area-averaged incident irradiance per root surface element (index `id - first_root`),
    /// including sun and sky.
    pub root_irradiance: Vec<DVec3>,
    pub stats: SolveStats,
}

impl Solution {
    /// Radiosity of input triangle `tri` (front face, or back face when `back` and two-sided).
    pub fn triangle_radiosity(&self, tri: u32, back: bool) -> DVec3 {
        self.elements.b[self.root_id(tri, back) as usize]
    }

    /// Area-averaged incident irradiance of input triangle `tri`.
    pub fn triangle_irradiance(&self, tri: u32, back: bool) -> DVec3 {
        self.root_irradiance[(self.root_id(tri, back) - self.elements.first_root) as usize]
    }

    fn root_id(&self, tri: u32, back: bool) -> u32 {
        let e = &self.elements;
        e.first_root + tri + if back && e.two_sided { e.num_tris } else { 0 }
    }

    /// Leaf surface elements, in depth-first order of the roots.
    pub fn leaves(&self) -> Vec<u32> {
        let mut out = Vec::new();
        for r in self.elements.roots() {
            self.elements.leaves_of(r, &mut out);
        }
        out
    }
}

/// Solve `scene` with the cluster hierarchy `tree`.
pub fn solve(
    scene: &Scene,
    tree: &ClusterTree,
    cfg: &SolverConfig,
    progress: &dyn Progress,
) -> Result<Solution> {
    solve_cancellable(scene, tree, cfg, progress, &AtomicBool::new(false))
}

/// [`solve`] that stops with [`Error::Interrupted`] when `cancel` becomes true.
pub fn solve_cancellable(
    scene: &Scene,
    tree: &ClusterTree,
    cfg: &SolverConfig,
    progress: &dyn Progress,
    cancel: &AtomicBool,
) -> Result<Solution> {
    cfg.validate()?;
    if tree.surface_node.len() != scene.num_triangles() {
        return Err(Error::Config(format!(
            "cluster tree has {} surfaces, scene has {}",
            tree.surface_node.len(),
            scene.num_triangles()
        )));
    }
    let t_start = Instant::now();
    let vis = Visibility::new(scene, tree, cfg.visibility, cfg.vol_ratio)?;
    let mut s = Solver::new(scene, tree, cfg, &vis);
    s.stats.time.setup = t_start.elapsed().as_secs_f64();
    s.run(progress, cancel, t_start)?;
    s.finish(t_start)
}

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
struct Entry {
    /// Unit direction from the cluster's centroid to the source's.
    d: Vec3,
    /// Source centroid and [`Element::facing_normal`] (for [`facing_weight`]).
    ///
    /// [`Element::facing_normal`]: super::element::Element::facing_normal
    sc: Vec3,
    sn: Vec3,
    /// Irradiance `K·B_src`.
    h: DVec3,
    /// Kernel.
    k: f32,
}

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
    /// Leaves' open area, Σ open·K, open area with K < 0.9 and with K > 1.1.
    k_stats: [f64; 4],
}

struct Solver<'a> {
    scene: &'a Scene,
    tree: &'a ClusterTree,
    cfg: &'a SolverConfig,
    vis: &'a Visibility<'a>,
    /// Coplanar overlaps ([`Covers`]).
    covers: Covers,
    el: Elements,
    links: Vec<Link>,
    set: LinkSet,
    eps: f64,
    min_area: f64,
    /// Minimum area of a surface receiver split at a shadow boundary.
    shadow_min_area: f64,
    budget_hit: bool,
    peak: u64,
    rays: u64,
    /// Per cluster: range into `entries`.
    cl_ranges: Vec<(u32, u32)>,
    /// Root surfaces sorted by their surface's cluster node (push-pull's pass over the
    /// clusters' entries).
    pp_order: Vec<u32>,
    entries: Vec<Entry>,
    /// Deposits of the surface receivers' links, and per element its range in them.
    deposits: Vec<(Deposit, DVec3)>,
    dep_ranges: Vec<(u32, u32)>,
    /// Per element: irradiance (channel sum) gathered from cluster sources.
    h_cluster: Vec<f64>,
    /// Per element: sum of the kernels of its own links (surface receivers).
    k_sum: Vec<f64>,
    root_irr: Vec<DVec3>,
    has_sun_sky: bool,
    /// Largest total power any converged solution can have (see the module docs).
    power_bound: f64,
    stats: SolveStats,
}

impl<'a> Solver<'a> {
    fn new(
        scene: &'a Scene,
        tree: &'a ClusterTree,
        cfg: &'a SolverConfig,
        vis: &'a Visibility<'a>,
    ) -> Self {
        let mut el = Elements::build(scene, tree, cfg.two_sided);
        let total_area = scene.total_area() * if cfg.two_sided { 2.0 } else { 1.0 };
        let footprint = {
            let e = scene.bbox.extent();
            let up = scene.up.vector();
            let ex = e.as_dvec3();
            // Area of the box's projection along the up axis.
            if up == Vec3::Z {
                ex.x * ex.y
            } else {
                ex.x * ex.z
            }
        };
        let sun_power = scene
            .sun
            .map(|s| s.irradiance.as_dvec3().max_element() * footprint)
            .unwrap_or(0.0);
        let sky_power = scene
            .sky
            .map(|l| std::f64::consts::PI * l.as_dvec3().max_element() * footprint)
            .unwrap_or(0.0);
        let b_ref =
            (scene.emitted_power().max_element() + sun_power + sky_power) / total_area.max(1e-30);
        let eps = cfg.eps.unwrap_or(cfg.eps_rel * b_ref).max(1e-30);
        let min_area = cfg.min_area.unwrap_or(cfg.min_area_rel * total_area);
        let has_sun_sky = scene.sun.is_some() || scene.sky.is_some();
        // Initial radiosity: emission (plus reflected direct sun/sky).
        for id in el.roots() {
            el.b[id as usize] = el.elems[id as usize].emission.as_dvec3();
        }
        let nc = el.num_clusters as usize;
        let covers = Covers::build(scene, tree, cfg.two_sided);
        for id in el.roots() {
            let e = &el.elems[id as usize];
            el.open[id as usize] = covers.open_fraction(e.tri, e.normal, &e.verts) as f32;
        }
        let stats = SolveStats {
            scene: scene.name.clone(),
            triangles: scene.num_triangles(),
            strategy: tree.strategy.name().to_string(),
            cluster_nodes: tree.nodes.len(),
            refine: cfg.refine.name().to_string(),
            eps,
            min_area,
            visibility: cfg.visibility.name().to_string(),
            shadow_rays: cfg.shadow_rays,
            two_sided: cfg.two_sided,
            cluster_emission: cfg.cluster_emission.name().into(),
            cluster_receive: cfg.cluster_receive.name().into(),
            threads: rayon::current_num_threads(),
            covered_triangles: covers.covered_triangles(),
            shut_triangles: covers.shut_triangles(),
            ..Default::default()
        };
        if !covers.is_empty() {
            tracing::info!(
                "{} triangles lie partly under coplanar ones; the covered parts take no light",
                stats.covered_triangles
            );
        }
        if stats.shut_triangles > 0 {
            tracing::info!(
                "{} triangles lie partly inside closed solids; those parts take no light",
                stats.shut_triangles
            );
        }
        let mut pp_order: Vec<u32> = el.roots().collect();
        pp_order.sort_by_key(|&r| (tree.surface_node[el.elems[r as usize].tri as usize], r));
        let mut s = Solver {
            scene,
            tree,
            cfg,
            vis,
            covers,
            h_cluster: vec![0.0; el.len()],
            k_sum: vec![0.0; el.len()],
            el,
            links: Vec::new(),
            set: LinkSet::default(),
            eps,
            min_area,
            shadow_min_area: min_area / 4f64.powi(cfg.shadow_levels as i32),
            budget_hit: false,
            peak: 0,
            rays: 0,
            cl_ranges: vec![(0, 0); nc],
            pp_order,
            entries: Vec::new(),
            deposits: Vec::new(),
            dep_ranges: Vec::new(),
            root_irr: Vec::new(),
            has_sun_sky,
            power_bound: f64::INFINITY,
            stats,
        };
        if has_sun_sky {
            let roots = s.el.roots();
            s.compute_direct(roots.start, roots.end);
            for id in s.el.roots() {
                let e = &s.el.elems[id as usize];
                s.el.b[id as usize] =
                    e.emission.as_dvec3() + e.rho.as_dvec3() * s.el.direct[id as usize];
            }
        }
        s.pull_clusters();
        // Power bound: every bounce keeps at most ρ_max of what reaches a surface.
        let rho_max =
            s.el.roots()
                .map(|r| s.el.elems[r as usize].rho.max_element())
                .fold(0.0f32, f32::max) as f64;
        let direct: f64 =
            s.el.roots()
                .map(|r| s.el.direct[r as usize].element_sum() * s.el.elems[r as usize].area as f64)
                .sum();
        let emitted = scene.emitted_power().element_sum();
        s.power_bound = 1.05 * (emitted + direct) / (1.0 - rho_max).max(1e-6);
        s
    }

    fn run(&mut self, progress: &dyn Progress, cancel: &AtomicBool, t0: Instant) -> Result<()> {
        let p0 = self.total_power();
        if p0 <= 0.0 {
            self.stats.no_light = true;
            let msg = format!(
                "scene '{}' has no light (no emitter, sun or sky): the solution is zero",
                self.scene.name
            );
            tracing::warn!("{msg}");
            self.stats.warnings.push(msg);
            self.stats.converged = true;
            self.set = LinkSet::default();
            self.push_pull();
            return Ok(());
        }
        progress.start("solve", self.cfg.max_iters as u64);
        let mut prev = p0;
        // Power of the radiosity the links were last refined against.
        let mut p_refined = p0;
        let mut need_refine = true;
        for it in 1..=self.cfg.max_iters {
            if cancel.load(Ordering::Relaxed) {
                progress.finish();
                return Err(Error::Interrupted);
            }
            let refined = need_refine;
            if refined {
                let t = Instant::now();
                self.refine(it == 1, cancel)?;
                self.stats.time.refine += t.elapsed().as_secs_f64();
                self.stats.refinements += 1;
                p_refined = prev;
            }
            let t = Instant::now();
            self.gather();
            self.stats.time.gather += t.elapsed().as_secs_f64();
            let t = Instant::now();
            self.push_pull();
            self.stats.time.push_pull += t.elapsed().as_secs_f64();
            let p = self.total_power();
            if p > self.power_bound {
                progress.finish();
                return Err(Error::Config(format!(
                    "the solve diverges: total power {p:.4e} W after iteration {it} exceeds \
                     {:.4e} W, the most (emitted + direct) / (1 - max reflectance) allows; \
                     some kernels over-estimate (leaves with gain above 1: {})",
                    self.power_bound, self.stats.leaves_gain_above_one
                )));
            }
            let rel = (p - prev).abs() / p.abs().max(1e-300);
            prev = p;
            self.stats.history.push(IterStat {
                iter: it,
                elements: self.el.len(),
                links: self.set.len(),
                power: p,
                rel_change: rel,
                seconds: t0.elapsed().as_secs_f64(),
            });
            self.stats.iterations = it;
            progress.inc(1);
            progress.message(&format!(
                "iter {it}: {} links, {} elements, Δ {:.1e}",
                self.set.len(),
                self.el.len(),
                rel
            ));
            tracing::debug!(
                "iteration {it}: links {} elements {} deposits {} cluster entries {} power \
                 {p:.6e} change {rel:.2e}",
                self.set.len(),
                self.el.len(),
                self.deposits.len(),
                self.entries.len()
            );
            if it > 1 && rel < self.cfg.tol_converge {
                if refined {
                    self.stats.converged = true;
                    break;
                }
                // Check the links against the converged radiosity before stopping.
                need_refine = true;
            } else {
                need_refine = (p - p_refined).abs() > REFINE_DRIFT * p.abs();
            }
        }
        progress.finish();
        if !self.stats.converged {
            let msg = format!(
                "not converged after {} iterations (last relative change {:.2e} > {:.1e})",
                self.stats.iterations,
                self.stats
                    .history
                    .last()
                    .map(|h| h.rel_change)
                    .unwrap_or(0.0),
                self.cfg.tol_converge
            );
            tracing::warn!("{msg}");
            self.stats.warnings.push(msg);
        }
        Ok(())
    }

    fn memory_now(&self, extra_links: usize) -> u64 {
        (self.el.memory_bytes()
            + (self.h_cluster.capacity() + self.k_sum.capacity()) * 8
            + self.set.memory_bytes()
            + (self.links.capacity() + extra_links) * std::mem::size_of::<Link>()
            + self.entries.capacity() * std::mem::size_of::<Entry>()
            + self.deposits.capacity() * std::mem::size_of::<(Deposit, DVec3)>()
            + self.dep_ranges.capacity() * 8
            + self.pp_order.capacity() * 4) as u64
    }

    fn note_peak(&mut self) {
        let m = self.memory_now(0);
        self.peak = self.peak.max(m);
    }

    /// One refinement sweep over every link (the root self-link on the first iteration).
    fn refine(&mut self, first: bool, cancel: &AtomicBool) -> Result<()> {
        let per_link = self.cfg.shadow_rays.max(1);
        let (mut frontier, mut samples): (Vec<Link>, Vec<Sample>) = if first {
            (vec![Link::new(0, 0)], Vec::new())
        } else {
            let set = std::mem::take(&mut self.set);
            (set.links, set.samples)
        };
        // The gather rebuilds its hand-outs and deposits from the refined links.
        self.entries = Vec::new();
        self.deposits = Vec::new();
        let mut done: Vec<Link> = Vec::with_capacity(frontier.len());
        while !frontier.is_empty() {
            // One pass over the frontier, a chunk at a time: the decisions of a chunk are all
            // that is held beside the links, and the frontier's memory is given back as it is
            // consumed (reversed, so that chunks come off its end in order).
            frontier.reverse();
            let mut next: Vec<Link> = Vec::new();
            while !frontier.is_empty() {
                let mut chunk =
                    frontier.split_off(frontier.len() - frontier.len().min(REFINE_CHUNK));
                frontier.shrink_to_fit();
                chunk.reverse();
                self.refine_chunk(
                    &chunk,
                    (&mut done, &mut next, &mut samples),
                    frontier.len(),
                    cancel,
                )?;
            }
            frontier = next;
        }
        self.set = LinkSet::from_links(done, &samples, per_link);
        self.note_peak();
        Ok(())
    }

    /// Decide the links of `chunk`: kept links go to `done` (their samples to `samples`), the
    /// children of split ones to `next`; `rest` links of the pass are still to come. When the
    /// growth would pass the memory budget, the chunk is decided again without refinement.
    fn refine_chunk(
        &mut self,
        chunk: &[Link],
        (done, next, samples): (&mut Vec<Link>, &mut Vec<Link>, &mut Vec<Sample>),
        rest: usize,
        cancel: &AtomicBool,
    ) -> Result<()> {
        let oracle_kind = self.cfg.refine;
        loop {
            if cancel.load(Ordering::Relaxed) {
                return Err(Error::Interrupted);
            }
            let allow = !self.budget_hit;
            let decided: Vec<Decided> = {
                let ctx = self.ctx();
                let this = &*self;
                chunk
                    .par_iter()
                    .map(|l| this.decide(&ctx, l, allow, oracle_kind))
                    .collect()
            };
            // Growth of this chunk.
            let mut new_links = 0usize;
            let mut to_split: Vec<u32> = Vec::new();
            for (a, l, _, _) in &decided {
                let nk = |id: u32| -> usize {
                    let e = &self.el.elems[id as usize];
                    if e.kind == Kind::Surface {
                        4
                    } else {
                        e.num_children as usize
                    }
                };
                match a {
                    Action::SplitRecv => {
                        new_links += nk(l.recv);
                        to_split.push(l.recv);
                    }
                    Action::SplitSrc => {
                        new_links += nk(l.src);
                        to_split.push(l.src);
                    }
                    Action::SplitBoth => new_links += nk(l.recv) * nk(l.recv),
                    _ => {}
                }
            }
            to_split.retain(|&id| {
                let e = &self.el.elems[id as usize];
                e.kind == Kind::Surface && e.num_children == 0
            });
            to_split.sort_unstable();
            to_split.dedup();
            let projected = self
                .memory_now(done.len() + rest + chunk.len() + next.len() + new_links)
                + (to_split.len() * 4 * (Elements::BYTES_PER_ELEMENT + 8)) as u64;
            for (_, _, r, _) in &decided {
                self.rays += r;
            }
            if let Some(budget) = self.cfg.max_memory {
                if new_links > 0 && projected > budget {
                    self.budget_hit = true;
                    let msg = format!(
                        "memory budget {:.3} GB reached ({} links, {} elements): refinement \
                         stopped, the solution is coarser than eps = {:.3e} asks for",
                        budget as f64 / 1e9,
                        done.len() + rest + chunk.len() + next.len(),
                        self.el.len(),
                        self.eps
                    );
                    tracing::warn!("{msg}");
                    self.stats.warnings.push(msg);
                    // Decide this chunk again without refinement: every link is kept.
                    continue;
                }
            }
            for &id in &to_split {
                self.el.subdivide(id);
            }
            if !to_split.is_empty() {
                let n_before = self.h_cluster.len();
                self.h_cluster.resize(self.el.len(), 0.0);
                self.k_sum.resize(self.el.len(), 0.0);
                if self.has_sun_sky {
                    self.compute_direct(n_before as u32, self.el.len() as u32);
                }
            }
            next.reserve(new_links);
            for (a, mut l, _, m) in decided {
                match a {
                    Action::Keep => {
                        if let Some(m) = m {
                            l.samples = samples.len() as u32;
                            samples.extend_from_slice(&m);
                        }
                        done.push(l)
                    }
                    Action::Drop => {}
                    Action::SplitRecv => {
                        for c in self.el.children(l.recv) {
                            next.push(Link::new(c, l.src));
                        }
                    }
                    Action::SplitSrc => {
                        for c in self.el.children(l.src) {
                            next.push(Link::new(l.recv, c));
                        }
                    }
                    Action::SplitBoth => {
                        let kids: Vec<u32> = self.el.children(l.recv).collect();
                        for &a in &kids {
                            for &b in &kids {
                                next.push(Link::new(a, b));
                            }
                        }
                    }
                }
            }
            // The peak counts the links held now: decided, kept, to come and new.
            self.links = std::mem::take(done);
            let held = rest + chunk.len() + next.capacity();
            let m = self.memory_now(held)
                + (chunk.len() * std::mem::size_of::<Decided>()
                    + samples.capacity() * std::mem::size_of::<Sample>()) as u64;
            self.peak = self.peak.max(m);
            *done = std::mem::take(&mut self.links);
            return Ok(());
        }
    }

    fn ctx(&self) -> KernelCtx<'_> {
        KernelCtx {
            elems: &self.el,
            tree: self.tree,
            vis: self.vis,
            covers: &self.covers,
            n_rays: self.cfg.shadow_rays as usize,
            seed: self.cfg.seed,
            emission: self.cfg.cluster_emission,
            reception: self.cfg.cluster_receive,
        }
    }

    /// Decide what to do with one link; kept links come back evaluated.
    fn decide(&self, ctx: &KernelCtx, l: &Link, allow: bool, ok: Oracle) -> Decided {
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
                    let e = ctx.estimate(ri, sj);
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
        if !link.evaluated() || (leaves && link.samples == NO_SAMPLES) {
            // The oracle asks for refinement, but both ends are at their minimum size.
            let unresolved = allow
                && oracle::wants_refine(
                    ok,
                    self.eps,
                    link.est as f64,
                    self.el.b[sj as usize],
                    r.rho.as_dvec3(),
                );
            let mut ev = match eval {
                Some(ev) => ev,
                None => {
                    let ev = ctx.evaluate_with(ri, sj, false, est_raw, unresolved, leaves);
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
            // link that could have split takes a kernel from independent rays.
            if unresolved && r.kind == Kind::Surface {
                if let Some(a) = oracle::choose_split(r, s, self.shadow_min_area) {
                    let varies = || {
                        let (fmin, fmax) = ctx.spread(ri, sj);
                        oracle::wants_refine(
                            Oracle::Error,
                            self.eps,
                            fmax - fmin,
                            self.el.b[sj as usize],
                            r.rho.as_dvec3(),
                        )
                    };
                    if ev.mixed || varies() {
                        return (a, *l, rays, None);
                    }
                    let fresh = KernelCtx {
                        seed: ctx.seed ^ 0x0DD5_EED5_0F5E_ED00,
                        ..*ctx
                    };
                    ev = fresh.evaluate_with(ri, sj, false, est_raw, unresolved, leaves);
                    rays += ev.rays;
                }
            }
            link.k = ev.k as f32;
            link.deposit = ev.deposit;
            link.draw = ev.draw;
            if !ev.members.is_empty() {
                members = Some(ev.members.into_boxed_slice());
            }
            // A cluster receiver hands what it receives to all of its surfaces that face the
            // source: when some samples see the source and some do not, some surfaces get up
            // to the whole transfer wrongly, and interreflection among the cluster's surfaces
            // multiplies that by up to ρ / (1 − ρ) (a closed thin box of ρ = 0.93: 13×).
            // Judge such a link on its largest sampled kernel times that gain.
            if ev.mixed && r.kind == Kind::Cluster {
                let rho = (r.rho.max_element() as f64).min(0.999);
                link.est = (ev.kmax * (rho / (1.0 - rho)).max(1.0)) as f32;
                if let Some(a) = split(link.est as f64) {
                    return (a, *l, rays, None);
                }
            }
            // Where no bound judged the link, a sampled kernel above the estimate shows that
            // the estimate missed something (surfaces of a cluster much nearer the other end
            // than its centre, or in front of a plane its centre lies behind): judge that.
            // This keeps the links whose few samples came out low, a bias towards dark, which
            // is why near links have the bound.
            if !bounded && ev.k > link.est as f64 {
                link.est = ev.k as f32;
                if let Some(a) = split(ev.k) {
                    return (a, *l, rays, None);
                }
            }
        }
        (Action::Keep, link, rays, members)
    }

    /// Gather over every link, per receiver, a chunk of receivers at a time (their hand-outs
    /// and deposits go straight into the flat arrays, not held twice).
    fn gather(&mut self) {
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

    /// Push irradiance down to the leaves (through clusters, then surface quadtrees), compute
    /// leaf radiosity, pull area averages up; accumulate the power balance.
    fn push_pull(&mut self) {
        let roots = self.el.roots();
        let el = &self.el;
        let tree = self.tree;
        let entries = &self.entries;
        let cl_ranges = &self.cl_ranges;
        let h_cluster = &self.h_cluster;
        let k_sum = &self.k_sum;
        let reception = self.cfg.cluster_receive;
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
                        for en in &entries[a as usize..b as usize] {
                            let w = match (reception, emission) {
                                (Reception::Oriented, ClusterEmission::Directional) => {
                                    facing_weight(e.centroid, n, en.sc, en.sn)
                                }
                                (Reception::Oriented, ClusterEmission::Isotropic) => {
                                    n.dot(en.d).max(0.0) as f64
                                }
                                (Reception::Isotropic, _) => 0.25,
                            };
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
                    (h_cluster, k_sum),
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
        let mut pw = super::stats::PowerStats::default();
        let mut gain_above_one = 0u64;
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
        let a = ks[0].max(1e-300);
        self.stats.kernel_sum_mean = ks[1] / a;
        self.stats.kernel_sum_low = ks[2] / a;
        self.stats.kernel_sum_high = ks[3] / a;
    }

    /// Cluster radiosity = average of the children over their open area (the part that
    /// emits), bottom-up; the cluster's open share is the children's open area over its area.
    fn pull_clusters(&mut self) {
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
    fn open_area(&self, id: u32) -> f64 {
        self.el.elems[id as usize].area as f64 * self.el.open[id as usize] as f64
    }

    /// Σ A·B over the open part of the root surfaces (channel sum), summed in id order.
    fn total_power(&self) -> f64 {
        self.el
            .roots()
            .map(|r| self.el.b[r as usize].element_sum() * self.open_area(r))
            .sum()
    }

    /// Direct sun and sky irradiance of surface elements `lo..hi`.
    fn compute_direct(&mut self, lo: u32, hi: u32) {
        let scene = self.scene;
        let vis = self.vis;
        let el = &self.el;
        let n_sun = self.cfg.shadow_rays as usize;
        let n_sky = self.cfg.sky_rays as usize;
        let seed = self.cfg.seed ^ 0x5u64.wrapping_mul(0x9E37_79B9);
        let up = scene.up.vector();
        let tmin = 1e-5 * scene.bbox.extent().length().max(1e-12);
        let covers = &self.covers;
        let vals: Vec<(DVec3, u64)> = (lo..hi)
            .into_par_iter()
            .map(|id| {
                let e = &el.elems[id as usize];
                if e.kind != Kind::Surface {
                    return (DVec3::ZERO, 0);
                }
                let mut rng = SplitMix64::for_item(seed, id as u64);
                let mut h = DVec3::ZERO;
                let mut rays = 0u64;
                let n = e.normal;
                let offset = n * tmin;
                if let Some(sun) = scene.sun {
                    let c = n.dot(sun.direction);
                    if c > 0.0 {
                        let mut pts = Vec::new();
                        super::formfactor::stratified_2d(n_sun, &mut rng, &mut pts);
                        let (mut open, mut n_open) = (0.0, 0usize);
                        for p in &pts {
                            let x = sample_triangle(&e.verts, p[0], p[1]);
                            // Irradiance is the mean over the element's open points.
                            if covers.covered(e.tri, e.normal, x) {
                                continue;
                            }
                            n_open += 1;
                            rays += 1;
                            open += vis.open_to_infinity(x + offset, sun.direction, tmin, e.tri);
                        }
                        h += sun.irradiance.as_dvec3() * (c as f64 * open / n_open.max(1) as f64);
                    }
                }
                if let Some(sky) = scene.sky {
                    let mut dirs = Vec::new();
                    super::formfactor::stratified_2d(n_sky, &mut rng, &mut dirs);
                    let mut pts = Vec::new();
                    super::formfactor::stratified_2d(n_sky, &mut rng, &mut pts);
                    let (t, b) = n.any_orthonormal_pair();
                    let (mut open, mut n_open) = (0.0, 0usize);
                    for (d, p) in dirs.iter().zip(&pts) {
                        let x = sample_triangle(&e.verts, p[0], p[1]);
                        if covers.covered(e.tri, e.normal, x) {
                            continue;
                        }
                        n_open += 1;
                        // Cosine-weighted direction about n.
                        let r = d[0].sqrt();
                        let phi = std::f32::consts::TAU * d[1];
                        let w = (t * (r * phi.cos())
                            + b * (r * phi.sin())
                            + n * (1.0 - d[0]).max(0.0).sqrt())
                        .normalize_or_zero();
                        if w.dot(up) <= 0.0 {
                            continue;
                        }
                        rays += 1;
                        open += vis.open_to_infinity(x + offset, w, tmin, e.tri);
                    }
                    h += sky.as_dvec3() * (std::f64::consts::PI * open / n_open.max(1) as f64);
                }
                (h, rays)
            })
            .collect();
        for (k, (h, r)) in vals.into_iter().enumerate() {
            self.el.direct[lo as usize + k] = h;
            self.rays += r;
        }
    }

    fn finish(mut self, t0: Instant) -> Result<Solution> {
        let st = &mut self.stats;
        st.elements = self.el.len();
        st.cluster_elements = self.el.num_clusters as usize;
        st.surface_elements = st.elements - st.cluster_elements;
        st.leaf_elements = self
            .el
            .elems
            .iter()
            .filter(|e| e.kind == Kind::Surface && e.num_children == 0)
            .count();
        st.links = self.set.len();
        for l in &self.set.links {
            match LinkKind::of(&self.el, l) {
                LinkKind::Ss => st.links_ss += 1,
                LinkKind::Cs => st.links_cs += 1,
                LinkKind::Cc => st.links_cc += 1,
            }
        }
        st.cluster_energy_percent = if st.power.gathered > 0.0 {
            100.0 * st.power.gathered_cluster / st.power.gathered
        } else {
            0.0
        };
        st.rays = self.rays;
        st.memory.peak_counted_bytes = self.peak;
        st.memory.element_bytes = (self.el.memory_bytes() + self.h_cluster.capacity() * 8) as u64;
        st.memory.link_bytes = self.set.memory_bytes() as u64;
        st.memory.vm_hwm_bytes = stats::vm_hwm_bytes();
        st.memory.budget_bytes = self.cfg.max_memory;
        st.memory.budget_hit = self.budget_hit;
        st.time.total = t0.elapsed().as_secs_f64();
        Ok(Solution {
            elements: self.el,
            links: self.set,
            root_irradiance: self.root_irr,
            stats: self.stats,
        })
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
    (h_cluster, k_sum): (&[f64], &[f64]),
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
        let share = c / d.points() as f64;
        carried.extend((0..d.points()).map(|i| (d.path(i), d.depth(), share)));
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
            (h_cluster, k_sum),
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
fn open_area(el: &Elements, covers: &Covers, id: u32) -> f64 {
    let e = &el.elems[id as usize];
    let known = el.open[id as usize];
    e.area as f64
        * if known.is_nan() {
            covers.open_fraction(e.tri, e.normal, &e.verts)
        } else {
            known as f64
        }
}
