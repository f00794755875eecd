//! The memory budget (`--max-memory`): the bytes the solver holds, counted from the
//! capacities of its arrays, and their peak. Refinement checks each chunk's projected growth
//! against the budget ([`Solver::refine_chunk`]).

use super::{Entry, Solver};
use crate::link::{Deposit, Link};
use glam::DVec3;

impl Solver<'_> {
    pub(super) fn memory_now(&self, extra_links: usize) -> u64 {
        (self.el.memory_bytes()
            + (self.h_cluster.capacity() + self.k_sum.capacity()) * 8
            + self.set.memory_bytes()
            + (self.links.capacity() + extra_links) * std::mem::size_of::<Link>()
            + self.entries.capacity() * std::mem::size_of::<Entry>()
            + self.deposits.capacity() * std::mem::size_of::<(Deposit, DVec3)>()
            + self.dep_ranges.capacity() * 8
            + self.pp_order.capacity() * 4) as u64
    }

    pub(super) fn note_peak(&mut self) {
        let m = self.memory_now(0);
        self.peak = self.peak.max(m);
    }
}
