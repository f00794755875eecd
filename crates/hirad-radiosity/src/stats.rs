//! Statistics of a solve (`stats.json`, `--bench`).

use serde::{Deserialize, Serialize};

/// One refine+gather iteration.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct IterStat {
    /// Iteration number, from 1.
    pub iter: u32,
    /// Elements after the iteration.
    pub elements: usize,
    /// Links after the iteration.
    pub links: usize,
    /// Total radiosity power Σ A·B over root surfaces (sum of the RGB channels, W).
    pub power: f64,
    /// Relative change of `power` from the previous iteration.
    pub rel_change: f64,
    /// Wall time since the start of the solve.
    pub seconds: f64,
}

/// Wall time per phase, seconds.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct PhaseTimes {
    /// Element arena, cluster data, direct sun/sky of the roots.
    pub setup: f64,
    /// Refinement including kernel evaluation and shadow rays.
    pub refine: f64,
    /// Gather.
    pub gather: f64,
    /// Push-pull (including the power balance).
    pub push_pull: f64,
    /// The whole solve.
    pub total: f64,
}

/// Memory accounting.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct MemoryStats {
    /// Peak of the counted bytes: the fixed part and the solver's arrays (elements, links,
    /// gather and push-pull buffers; [`crate::memory`]).
    pub peak_counted_bytes: u64,
    /// The fixed part of the count: scene, cluster tree, ray layout, overlaps and shut masks,
    /// process, the caller's images.
    #[serde(default)]
    pub fixed_bytes: u64,
    /// Bytes of the element arena (and per-element gather sums) at the end.
    pub element_bytes: u64,
    /// Bytes of the final link set.
    pub link_bytes: u64,
    /// Process peak resident set (VmHWM of /proc/self/status) when the solve ended (the
    /// `stats.json` of `hirad solve` takes it after the mesh files are written), when
    /// available.
    pub vm_hwm_bytes: Option<u64>,
    /// The `--max-memory` budget of the whole process.
    pub budget_bytes: Option<u64>,
    /// True when refinement stopped early because of the budget (solution coarser than ε
    /// asks for).
    pub budget_hit: bool,
}

/// Power balance (sums of the RGB channels, W).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct PowerStats {
    /// Emitted by surfaces plus sun/sky irradiance arriving on surfaces.
    pub emitted: f64,
    /// Absorbed by surfaces: Σ A (1 − ρ) H over leaves.
    pub absorbed: f64,
    /// Leaving surfaces without being gathered by any: Σ A B − Σ A H_gathered.
    pub escaping: f64,
    /// Σ A B over root surfaces.
    pub radiosity: f64,
    /// Gathered through links (all kinds).
    pub gathered: f64,
    /// Gathered through links with a cluster at either end.
    pub gathered_cluster: f64,
}

/// Everything a solve reports.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct SolveStats {
    /// Scene name.
    pub scene: String,
    /// Input triangles.
    pub triangles: usize,
    /// Cluster tree strategy.
    pub strategy: String,
    /// Nodes of the cluster tree.
    pub cluster_nodes: usize,
    /// Refinement oracle (`bf` or `error`).
    pub refine: String,
    /// The refinement threshold used (W/m²).
    pub eps: f64,
    /// Minimum element area used.
    pub min_area: f64,
    /// Visibility mode (`rays`, `volume` or `none`).
    pub visibility: String,
    /// Shadow rays per link.
    pub shadow_rays: u32,
    /// Surfaces have back faces.
    pub two_sided: bool,
    /// Cluster reception model (`oriented` or `isotropic`).
    pub cluster_receive: String,
    /// Cluster emission model (`isotropic` or `directional`).
    pub cluster_emission: String,
    /// Worker threads (results do not depend on them).
    pub threads: usize,
    /// Triangles partly under a coplanar triangle that owns the overlap (`radiosity::overlap`).
    pub covered_triangles: usize,
    /// Triangles partly inside a closed solid (`radiosity::shut`).
    #[serde(default)]
    pub shut_triangles: usize,
    /// All elements (clusters + surface elements).
    pub elements: usize,
    /// Cluster elements.
    pub cluster_elements: usize,
    /// Surface elements (roots and their subdivisions).
    pub surface_elements: usize,
    /// Surface elements without children.
    pub leaf_elements: usize,
    /// Links of the solution.
    pub links: usize,
    /// Surface–surface links.
    pub links_ss: usize,
    /// Links between a cluster and a surface (either direction).
    pub links_cs: usize,
    /// Cluster–cluster links.
    pub links_cc: usize,
    /// Percentage of the gathered power that went through links involving clusters.
    pub cluster_energy_percent: f64,
    /// Shadow and sun/sky rays cast.
    pub rays: u64,
    /// Iterations run.
    pub iterations: u32,
    /// The relative change of power fell below `tol_converge`.
    pub converged: bool,
    /// Per iteration.
    pub history: Vec<IterStat>,
    /// Wall time per phase.
    pub time: PhaseTimes,
    /// Memory accounting.
    pub memory: MemoryStats,
    /// Power balance of the last iteration.
    pub power: PowerStats,
    /// True when nothing emits (no emitter, sun or sky): the solution is zero.
    pub no_light: bool,
    /// Warnings of the solve (not converged, memory budget, no light).
    pub warnings: Vec<String>,
    /// Leaves whose gain `ρ · Σ K` (reflectance times the sum of their link kernels) exceeded
    /// 1 in the last gather (form factors of a leaf sum to at most 1: these kernels
    /// over-estimate; nothing is clamped).
    #[serde(default)]
    pub leaves_gain_above_one: u64,
    /// Leaves whose irradiance from their links (any channel) exceeded twice the brightest
    /// radiosity of an emitter or of a surface the sun or sky lights directly, in the
    /// iteration before: irradiance at a point is at most the brightest radiosity it sees
    /// (`E = ∫ L cos θ dω ≤ π L_max`), and a surface lit only through links is never the
    /// brightest (`B = ρ H < max B`), so such a leaf got light no sampled estimate should
    /// give it.
    #[serde(default)]
    pub leaves_above_brightest: u64,
    /// The leaves' kernel sums `Σ K` in the last gather, weighted by open area: 1 in a closed
    /// scene, where every open point sees surfaces all round.
    #[serde(default)]
    pub kernel_sum_mean: f64,
    /// Share of the leaves' open area whose kernel sum is below 0.9.
    #[serde(default)]
    pub kernel_sum_low: f64,
    /// Share of the leaves' open area whose kernel sum is above 1.1.
    #[serde(default)]
    pub kernel_sum_high: f64,
    /// Refinement passes run (refinement is repeated while the radiosity moves).
    #[serde(default)]
    pub refinements: u32,
}

/// Peak resident set of this process in bytes (VmHWM), on Linux.
pub fn vm_hwm_bytes() -> Option<u64> {
    let s = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = s.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: u64 = line
        .trim_start_matches("VmHWM:")
        .trim()
        .trim_end_matches("kB")
        .trim()
        .parse()
        .ok()?;
    Some(kb * 1024)
}
