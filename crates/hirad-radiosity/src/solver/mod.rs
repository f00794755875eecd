//! The hierarchical radiosity loop: refine links with the oracle, gather, push-pull, until
//! the total power converges (`spec/radiosity.md`, "The solver").
//!
//! Determinism: refinement decides links in parallel but changes the hierarchy and the link
//! list sequentially in list order (`refine`); kernels seed from the link's element ids;
//! gather and push-pull sum every total sequentially in id order. Results do not depend on
//! the thread count.
//!
//! Iterations: the links are refined on the first iteration, again whenever the total power
//! has moved by more than `REFINE_DRIFT` since, and once more when the change of total power
//! per iteration falls below `REFINE_TOL` (or `tol_converge`, if larger) while the power has
//! moved by more than that since the last refinement or that refinement added more than
//! `SETTLED_LINKS` of the links (their light changes the radiosity the oracle weighs where they
//! land); the other iterations only gather and push-pull. The solve stops when the change falls
//! below `tol_converge`, the last refinement added at most `SETTLED_LINKS` of the links and
//! was made against a total power within `REFINE_TOL` of the converged one. Nothing
//! caps a leaf's gain `ρ · Σ K` (those above 1 are counted); a solve whose total power passes
//! `(Φ_emitted + Φ_direct) / (1 − ρ_max)`, the most any closed scene holds, stops with an error.

mod budget;
mod gather;
mod push_pull;
mod refine;
mod sky;

use self::gather::Entry;
use super::config::SolverConfig;
use super::element::{Elements, Kind};
use super::link::{Deposit, Link, LinkKind, LinkSet};
use super::overlap::Covers;
use super::stats::{self, IterStat, SolveStats};
use super::visibility::Visibility;
use glam::{DVec3, Vec3};
use hirad_accel::cluster::ClusterTree;
use hirad_accel::ray::Segment;
use hirad_core::progress::Progress;
use hirad_core::{Error, Result};
use hirad_scene::Scene;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

/// Refinement is repeated (before the next gather) when the total power has moved by more
/// than this fraction since the links were last refined (near convergence: [`REFINE_TOL`]);
/// in between, iterations only gather and push-pull over the same links.
const REFINE_DRIFT: f64 = 0.05;

/// A solution whose total power changes by less than this fraction per iteration is close
/// enough to its fixed point for the oracle (which weighs `B·F̃` against ε; a link changes
/// its decision only within this fraction of the threshold): the links are checked against
/// it, and are not checked again at convergence unless the power has moved by more since.
const REFINE_TOL: f64 = 1e-3;

/// A refinement that adds at most this fraction of the links leaves them settled: no further
/// check is needed once the radiosity has converged over them.
const SETTLED_LINKS: f64 = 0.01;

/// [`Solver::straddle`]: the element's links with disagreeing rays carry more than ε.
const STRADDLES: u8 = 1;
/// [`Solver::straddle`]: a sweep has decided the element's links on [`STRADDLES`].
const STRADDLE_DECIDED: u8 = 2;

/// A finished solve: the element hierarchy with its radiosity, the links and the statistics.
#[derive(Clone, Debug)]
pub struct Solution {
    /// The element hierarchy with its radiosity `b` (W/m²).
    pub elements: Elements,
    /// The final links, grouped by receiver.
    pub links: LinkSet,
    /// Area-averaged incident irradiance per root surface element (index `id - first_root`),
    /// including sun and sky.
    pub root_irradiance: Vec<DVec3>,
    /// Statistics of the solve.
    pub stats: SolveStats,
    /// Sorted leaf elements with no open part that lie within one coplanar face that owns the
    /// place (a duplicated face under its original): what a viewer sees there is that face,
    /// and the output mesh leaves these out.
    pub under_face: Vec<u32>,
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
    Ok(solve_recording(scene, tree, cfg, progress, cancel, None)?.0)
}

/// [`solve_cancellable`] that also returns one in `every` of the shadow segments cast between
/// link ends (chosen by a hash of their end points, sorted; none when `every` is `None`): the
/// solver's rays for ray-casting benchmarks (`hirad solve --export-rays`).
pub fn solve_recording(
    scene: &Scene,
    tree: &ClusterTree,
    cfg: &SolverConfig,
    progress: &dyn Progress,
    cancel: &AtomicBool,
    every: Option<u32>,
) -> Result<(Solution, Vec<Segment>)> {
    cfg.validate()?;
    if tree.surface_node.len() != scene.num_triangles() {
        return Err(Error::Config(format!(
            "cluster tree has {} surfaces, scene has {}",
            tree.surface_node.len(),
            scene.num_triangles()
        )));
    }
    let t_start = Instant::now();
    let mut vis = Visibility::new(scene, tree, cfg.visibility, cfg.vol_ratio)?;
    if let Some(k) = every {
        vis.record(k);
    }
    // The budget's fixed part: checked before the overlaps are searched, and again with them
    // and the element arena before refinement.
    let fixed = (scene.memory_bytes() + tree.memory_bytes() + vis.memory_bytes()) as u64
        + crate::memory::process_bytes(rayon::current_num_threads())
        + cfg.reserved_memory;
    if let Some(b) = cfg.max_memory {
        if fixed > b {
            return Err(crate::memory::too_small(
                b,
                fixed,
                "scene, cluster tree, ray layout, process and images",
            ));
        }
    }
    let mut s = Solver::new(scene, tree, cfg, &vis);
    s.fixed = fixed + s.covers.memory_bytes() as u64;
    tracing::info!(
        "memory: fixed {} B (scene {}, cluster tree {}, visibility {}, overlaps {}), elements {}",
        s.fixed,
        scene.memory_bytes(),
        tree.memory_bytes(),
        vis.memory_bytes(),
        s.covers.memory_bytes(),
        s.el.memory_bytes()
    );
    s.check_start()?;
    s.note_peak();
    s.stats.time.setup = t_start.elapsed().as_secs_f64();
    s.run(progress, cancel, t_start)?;
    let sol = s.finish(t_start)?;
    Ok((sol, vis.recorded()))
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
    /// Bytes of the budget's fixed part ([`crate::memory`]).
    fixed: u64,
    /// Links kept by the current refinement, and the bytes of gather entries and deposits
    /// they will need (the ratio the budget's projection uses).
    kept_links: usize,
    kept_gather_bytes: usize,
    /// Samples kept by the current refinement.
    kept_samples: usize,
    peak: u64,
    rays: u64,
    /// Per cluster: range into `entries`.
    cl_ranges: Vec<(u32, u32)>,
    /// Root surfaces sorted by their surface's cluster node (push-pull's pass over the
    /// clusters' entries).
    pp_order: Vec<u32>,
    entries: Vec<Entry>,
    /// Per cluster: range into `strata`, the hand-outs of the open surfaces of links into
    /// clusters above it ([`crate::formfactor::kernel::KernelEval::open_members`]).
    st_ranges: Vec<(u32, u32)>,
    strata: Vec<Entry>,
    /// Deposits of the surface receivers' links, and per element its range in them.
    deposits: Vec<(Deposit, DVec3)>,
    dep_ranges: Vec<(u32, u32)>,
    /// Per element: irradiance (channel sum) gathered from cluster sources.
    h_cluster: Vec<f64>,
    /// Per element: sum of the kernels of its own links (surface receivers).
    k_sum: Vec<f64>,
    /// Per element: [`STRADDLES`] when its mixed links' light (`K·B`, `ρ·K·B` for the `error`
    /// oracle) passes ε
    /// (`gather`), so refinement splits it for those links; [`STRADDLE_DECIDED`] once a
    /// sweep has decided its links on that (`refine`).
    straddle: Vec<u8>,
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
        // Front faces, and the back faces that take part.
        let total_area: f64 = (0..scene.num_triangles())
            .map(|t| scene.areas[t] as f64 * if el.has_back[t] { 2.0 } else { 1.0 })
            .sum();
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
            el.open[id as usize] = if el.is_dead(id) {
                0.0
            } else {
                covers.open_fraction(e.tri, e.normal, &e.verts) as f32
            };
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
            two_sided: el.two_sided,
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
        let mut pp_order: Vec<u32> = el.roots().filter(|&r| !el.is_dead(r)).collect();
        pp_order.sort_by_key(|&r| (tree.surface_node[el.elems[r as usize].tri as usize], r));
        let mut s = Solver {
            scene,
            tree,
            cfg,
            vis,
            covers,
            h_cluster: vec![0.0; el.len()],
            k_sum: vec![0.0; el.len()],
            straddle: vec![0; el.len()],
            el,
            links: Vec::new(),
            set: LinkSet::default(),
            eps,
            min_area,
            shadow_min_area: min_area / 4f64.powi(cfg.shadow_levels as i32),
            budget_hit: false,
            fixed: 0,
            kept_links: 0,
            kept_gather_bytes: 0,
            kept_samples: 0,
            peak: 0,
            rays: 0,
            cl_ranges: vec![(0, 0); nc],
            pp_order,
            entries: Vec::new(),
            st_ranges: vec![(0, 0); nc],
            strata: Vec::new(),
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
        let near = REFINE_TOL.max(self.cfg.tol_converge);
        // The last refinement added at most `SETTLED_LINKS` of the links.
        let mut settled = false;
        for it in 1..=self.cfg.max_iters {
            if cancel.load(Ordering::Relaxed) {
                progress.finish();
                return Err(Error::Interrupted);
            }
            let refined = need_refine;
            if refined {
                let t = Instant::now();
                let before = self.set.len();
                self.refine(it == 1, cancel)?;
                self.stats.time.refine += t.elapsed().as_secs_f64();
                let added = self.set.len().saturating_sub(before);
                settled = it > 1 && added as f64 <= SETTLED_LINKS * self.set.len() as f64;
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
                "iteration {it}: links {} elements {} deposits {} cluster entries {} strata {} \
                 power {p:.6e} change {rel:.2e}",
                self.set.len(),
                self.el.len(),
                self.deposits.len(),
                self.entries.len(),
                self.strata.len()
            );
            // Power moved since the links were last refined, relative.
            let moved = (p - p_refined).abs() / p.abs().max(1e-300);
            if it > 1 && rel < self.cfg.tol_converge && settled && (refined || moved <= near) {
                self.stats.converged = true;
                break;
            }
            // Check the links against the (nearly) converged radiosity.
            need_refine =
                moved > REFINE_DRIFT || (it > 1 && rel < near && (moved > near || !settled));
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
}

impl Solver<'_> {
    /// Σ A·B over the open part of the root surfaces (channel sum), summed in id order.
    fn total_power(&self) -> f64 {
        self.el
            .roots()
            .map(|r| self.el.b[r as usize].element_sum() * self.open_area(r))
            .sum()
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
        st.memory.fixed_bytes = self.fixed;
        st.memory.element_bytes = (self.el.memory_bytes()
            + self.h_cluster.capacity() * 8
            + self.straddle.capacity()) as u64;
        st.memory.link_bytes = self.set.memory_bytes() as u64;
        st.memory.vm_hwm_bytes = stats::vm_hwm_bytes();
        st.memory.budget_bytes = self.cfg.max_memory;
        st.memory.budget_hit = self.budget_hit;
        st.time.total = t0.elapsed().as_secs_f64();
        let under_face = (0..self.el.elems.len() as u32)
            .filter(|&id| {
                let e = &self.el.elems[id as usize];
                e.kind == Kind::Surface
                    && e.num_children == 0
                    && self.el.open[id as usize] == 0.0
                    && self.covers.within_coplanar_owner(e.tri, &e.verts)
            })
            .collect();
        Ok(Solution {
            elements: self.el,
            links: self.set,
            root_irradiance: self.root_irr,
            stats: self.stats,
            under_face,
        })
    }
}
