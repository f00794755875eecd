//! The memory budget (`--max-memory`, [`crate::memory`]): the bytes the solver holds, counted
//! from the capacities of its arrays on top of the fixed part counted at the start, and their
//! peak. Refinement checks each chunk's projection of the solve's later peaks against the
//! budget ([`Solver::settle`]): refinement itself (the links held and the next chunk's
//! decisions), gather and push-pull (the final links with their entries, deposits and
//! per-root results), and the output mesh written from the solution.

use super::gather::Entry;
use super::refine::Decision;
use super::Solver;
use crate::element::Elements;
use crate::link::{Deposit, Link, Sample};
use glam::DVec3;
use hirad_core::Result;
use std::mem::size_of;

/// Bytes per leaf of the output mesh, its vertex index and fit arrays and the file buffers
/// (`output::write_outputs`), estimated from their element sizes for about two vertices per
/// leaf (not measured on its own).
const OUTPUT_PER_LEAF: u64 = 600;

/// Bytes per root of push-pull's per-root results and their allocations, besides
/// [`PUSH_PULL_PER_ELEMENT`] (from the sizes of the types).
const PUSH_PULL_PER_ROOT: u64 = 250;
/// Bytes per element of push-pull's updates.
const PUSH_PULL_PER_ELEMENT: u64 = 48;

/// Growth of the held links a projection is asked about.
pub(super) struct Growth {
    /// Links held after the chunk (kept, to come and new).
    pub links: usize,
    /// New surface elements.
    pub elements: usize,
    /// Samples held (kept links' from directional clusters).
    pub samples: usize,
    /// Links of `links` not decided yet (each may keep samples).
    pub pending: usize,
    /// Links a chunk decides at a time.
    pub chunk: usize,
    /// Link slots held beside the links while refining: those a first pass decided in place
    /// and did not keep, and the room the merge of the late links takes
    /// ([`crate::link::LinkSet::from_links`]).
    pub room: usize,
}

impl Solver<'_> {
    /// Bytes of the solver's arrays now, plus `extra_links` links held outside them.
    pub(super) fn memory_now(&self, extra_links: usize) -> u64 {
        (self.el.memory_bytes()
            + (self.h_cluster.capacity() + self.k_sum.capacity()) * 8
            + self.straddle.capacity()
            + self.set.memory_bytes()
            + (self.links.capacity() + extra_links) * size_of::<Link>()
            + (self.entries.capacity() + self.strata.capacity()) * size_of::<Entry>()
            + self.deposits.capacity() * size_of::<(Deposit, DVec3)>()
            + (self.dep_ranges.capacity() + self.cl_ranges.capacity() + self.st_ranges.capacity())
                * 8
            + self.root_irr.capacity() * size_of::<DVec3>()
            + self.pp_order.capacity() * 4) as u64
    }

    /// Record the peak of the fixed part and the arrays held now.
    pub(super) fn note_peak(&mut self) {
        let m = self.fixed + self.memory_now(0);
        self.peak = self.peak.max(m);
    }

    /// The largest of the solve's later peaks if refinement grows to `g`: refinement (the
    /// links, the samples twice while the link set is built, a chunk's decisions), gather and
    /// push-pull (the links with their entries and deposits, at the ratio of the links kept so
    /// far, and push-pull's results), and the output mesh beside the solution.
    pub(super) fn projected(&self, g: &Growth) -> u64 {
        let roots = self.el.roots().len() as u64;
        let elements = (self.el.len() + g.elements) as u64;
        let surfaces = elements - self.el.num_clusters as u64;
        // Leaves: the roots and 3 of every 4 children (each split turns a leaf into 4).
        let leaves = roots + (surfaces - roots) * 3 / 4;
        let base = self.fixed
            + self.memory_now(0)
            + (g.elements * (Elements::BYTES_PER_ELEMENT + 2 * 8 + 8 + 1)) as u64;
        let links = (g.links * size_of::<Link>()) as u64;
        // Samples the pending links will keep, at the ratio of the links kept so far.
        let per_kept = if self.kept_links >= 1000 {
            self.kept_samples as f64 / self.kept_links as f64
        } else {
            self.cfg.shadow_rays as f64
        };
        let samples =
            ((g.samples as f64 + g.pending as f64 * per_kept) * size_of::<Sample>() as f64) as u64;
        // A chunk held while it is decided: its links, their decisions and new samples.
        let per_link = size_of::<Link>()
            + size_of::<Decision>()
            + self.cfg.shadow_rays as usize * size_of::<Sample>();
        let refine =
            links + (g.room * size_of::<Link>()) as u64 + 2 * samples + (g.chunk * per_link) as u64;
        let gather = if self.kept_links >= 1000 {
            self.kept_gather_bytes as f64 / self.kept_links as f64
        } else {
            size_of::<Entry>() as f64
        } * g.links as f64;
        let groups = g.links.min(elements as usize) as u64 * 12;
        let push_pull = roots * PUSH_PULL_PER_ROOT + elements * PUSH_PULL_PER_ELEMENT;
        let after = links + samples + groups + gather as u64 + push_pull;
        let output = links + samples + groups + leaves * OUTPUT_PER_LEAF;
        if self
            .cfg
            .max_memory
            .is_some_and(|b| base + refine.max(after).max(output) > b)
        {
            tracing::debug!(
                "memory projection over the budget: base {base} B (fixed {}), refinement \
                 {refine}, gather and push-pull {after}, output {output}",
                self.fixed
            );
        }
        base + refine.max(after).max(output)
    }

    /// Fail before any refinement when the fixed part and the initial arrays pass the budget.
    pub(super) fn check_start(&self) -> Result<()> {
        let Some(b) = self.cfg.max_memory else {
            return Ok(());
        };
        let need = self.projected(&Growth {
            links: 1,
            elements: 0,
            samples: 0,
            pending: 1,
            chunk: 1,
            room: 0,
        });
        if need <= b {
            return Ok(());
        }
        let mb = crate::memory::mb;
        Err(crate::memory::too_small(
            b,
            need,
            &format!(
                "scene {}, cluster tree {}, ray layout {}, overlaps and shut masks {}, \
                 process {}, images {}, elements {}",
                mb(self.scene.memory_bytes() as u64),
                mb(self.tree.memory_bytes() as u64),
                mb(self.vis.memory_bytes() as u64),
                mb(self.covers.memory_bytes() as u64),
                mb(crate::memory::process_bytes(rayon::current_num_threads())),
                mb(self.cfg.reserved_memory),
                mb(need - self.fixed)
            ),
        ))
    }
}
