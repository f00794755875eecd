//! The memory budget of a solve (`--max-memory`) bounds the whole process, not the solver's
//! arrays alone. Its fixed part — the scene, the cluster tree, the ray layout, overlaps and
//! shut masks, what the caller holds beside the solve (images) and the process itself — is
//! counted when the solve starts and must fit, else the solve fails before any work
//! ([`Error::Budget`]); refinement may spend the rest on elements, links, the gather's and
//! push-pull's buffers and the output mesh, each counted from capacities (`solver::budget`).
//! [`estimate`] predicts the fixed part and a default solve from the triangle count alone, for
//! `hirad info` and for the CLI's check before the cluster tree is built; its per-triangle
//! sizes were measured on the shared scenes (`docs/perf-log.md`, 2026-12-04).

use crate::config::SolverConfig;
use hirad_core::{Error, Result};
use hirad_scene::Scene;

/// Resident bytes of the process outside every counted array: code, libraries, thread
/// stacks, the allocator's per-thread arenas and free lists (with [`THREAD_SCRATCH_BYTES`]
/// an upper pick over what cornell and office leave uncounted, perf-log 2026-12-04).
pub const PROCESS_BYTES: u64 = 24_000_000;

/// Bytes per thread for the scratch of parallel chunks (kernel samples, members, stacks).
pub const THREAD_SCRATCH_BYTES: u64 = 8_000_000;

/// Bytes per input triangle of the cluster tree (17–18 on the shared scenes).
const TREE_PER_TRIANGLE: u64 = 20;
/// Bytes per input triangle of the ray layout and the visibility ranks (about 54–64 with
/// eight-wide nodes).
const LAYOUT_PER_TRIANGLE: u64 = 68;
/// Bytes per input triangle of coplanar overlaps and shut masks (22–34 on the large scenes).
const COVERS_PER_TRIANGLE: u64 = 40;
/// Bytes per root surface element of the initial element arena, clusters and per-element
/// sums included (272–300 on the shared scenes).
const ARENA_PER_ROOT: u64 = 320;
/// Bytes per root surface element (a triangle's side) of a default solve: elements, links,
/// the gather's buffers and the output mesh (VmHWM less the fixed part over the roots of
/// default solves, perf-log 2026-12-04).
pub const SOLVE_PER_ROOT: u64 = 8_000;

/// Predicted bytes of a solve, from the scene's counts (see the module docs).
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct MemoryEstimate {
    /// The scene's arrays (exact).
    pub scene: u64,
    /// The cluster tree (estimated per triangle).
    pub tree: u64,
    /// The ray layout and visibility ranks (estimated per triangle).
    pub layout: u64,
    /// Overlaps and shut masks (estimated per triangle).
    pub covers: u64,
    /// The initial element arena (roots and clusters; estimated per root).
    pub elements: u64,
    /// The process and the threads' scratch ([`PROCESS_BYTES`], [`THREAD_SCRATCH_BYTES`]).
    pub process: u64,
    /// What the caller holds beside the solve (images).
    pub reserved: u64,
    /// Sum of the above: what the budget must hold before refinement starts.
    pub fixed: u64,
    /// Elements, links and buffers of an unbounded default solve (estimated per root surface
    /// element).
    pub solve: u64,
    /// `fixed + solve`.
    pub total: u64,
}

/// Predict the memory of solving `scene` with `cfg` on `threads` threads; `reserved` bytes
/// are held by the caller beside the solve.
pub fn estimate(
    scene: &Scene,
    cfg: &SolverConfig,
    threads: usize,
    reserved: u64,
) -> MemoryEstimate {
    let tris = scene.num_triangles() as u64;
    let roots = tris
        * if scene.any_back(cfg.two_sided || scene.two_sided) {
            2
        } else {
            1
        };
    let mut e = MemoryEstimate {
        scene: scene.memory_bytes() as u64,
        tree: tris * TREE_PER_TRIANGLE,
        layout: tris * LAYOUT_PER_TRIANGLE,
        covers: tris * COVERS_PER_TRIANGLE,
        elements: roots * ARENA_PER_ROOT,
        process: process_bytes(threads),
        reserved,
        ..Default::default()
    };
    e.fixed = e.scene + e.tree + e.layout + e.covers + e.elements + e.process + e.reserved;
    // Measured on the default preset only: other ε and minimum areas are not modelled.
    e.solve = (roots * SOLVE_PER_ROOT).saturating_sub(e.elements);
    e.total = e.fixed + e.solve;
    e
}

/// [`PROCESS_BYTES`] plus the scratch of `threads` threads.
pub fn process_bytes(threads: usize) -> u64 {
    PROCESS_BYTES + threads as u64 * THREAD_SCRATCH_BYTES
}

/// The error of a budget below `needed` bytes, naming both and what `parts` holds.
pub fn too_small(budget: u64, needed: u64, parts: &str) -> Error {
    Error::Budget(format!(
        "--max-memory {} is below the {} that the scene needs before any refinement ({parts}); \
         give at least {}",
        mb(budget),
        mb(needed),
        mb(needed + needed / 4)
    ))
}

/// `budget` bytes as megabytes for messages.
pub fn mb(bytes: u64) -> String {
    format!("{:.0} MB", (bytes as f64 / 1e6).ceil())
}

/// Fail with [`too_small`] when the estimate's fixed part alone passes `cfg.max_memory`.
pub fn check_fixed(e: &MemoryEstimate, cfg: &SolverConfig) -> Result<()> {
    match cfg.max_memory {
        Some(b) if e.fixed > b => Err(too_small(
            b,
            e.fixed,
            &format!(
                "scene {}, cluster tree ~{}, ray layout ~{}, overlaps ~{}, elements ~{}, \
                 process {}, images {}",
                mb(e.scene),
                mb(e.tree),
                mb(e.layout),
                mb(e.covers),
                mb(e.elements),
                mb(e.process),
                mb(e.reserved)
            ),
        )),
        _ => Ok(()),
    }
}
