//! Statistics of a solve (`stats.json`, `--bench`).

use serde::{Deserialize, Serialize};

/// One refine+gather iteration.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct IterStat {
    pub iter: u32,
    pub elements: usize,
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
    pub gather: f64,
    pub push_pull: f64,
    pub total: f64,
}

/// Memory accounting.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct MemoryStats {
    /// Peak of our own counted bytes (elements + links + gather buffers).
    pub peak_counted_bytes: u64,
    pub element_bytes: u64,
    pub link_bytes: u64,
    /// Process peak resident set (VmHWM of /proc/self/status), when available.
    pub vm_hwm_bytes: Option<u64>,
    /// The `--max-memory` budget.
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
    pub scene: String,
    pub triangles: usize,
    pub strategy: String,
    pub cluster_nodes: usize,
    pub refine: String,
    /// The refinement threshold used (W/m²).
    pub eps: f64,
    /// Minimum element area used.
    pub min_area: f64,
    pub visibility: String,
    pub shadow_rays: u32,
    pub two_sided: bool,
    pub cluster_receive: String,
    /// Cluster emission model (`isotropic` or `directional`).
    pub cluster_emission: String,
    pub threads: usize,
    /// Triangles partly under a coplanar triangle that owns the overlap (`radiosity::overlap`).
    pub covered_triangles: usize,
    /// Triangles partly inside a closed solid (`radiosity::shut`).
    #[serde(default)]
    pub shut_triangles: usize,
    /// All elements (clusters + surface elements).
    pub elements: usize,
    pub cluster_elements: usize,
    pub surface_elements: usize,
    pub leaf_elements: usize,
    pub links: usize,
    pub links_ss: usize,
    pub links_cs: usize,
    pub links_cc: usize,
    /// Percentage of the gathered power that went through links involving clusters.
    pub cluster_energy_percent: f64,
    pub rays: u64,
    pub iterations: u32,
    pub converged: bool,
    pub history: Vec<IterStat>,
    pub time: PhaseTimes,
    pub memory: MemoryStats,
    pub power: PowerStats,
    /// True when nothing emits (no emitter, sun or sky): the solution is zero.
    pub no_light: bool,
    pub warnings: Vec<String>,
    /// Leaves whose gain `ρ · Σ K` (reflectance times the sum of their link kernels) exceeded
    /// 1 in the last gather (form factors of a leaf sum to at most 1: these kernels
    /// over-estimate; nothing is clamped).
    #[serde(default)]
    pub leaves_gain_above_one: u64,
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
