//! The records a study writes: one per finished unit of work, plus the run's metadata.
//! Every record is self-describing (scene, strategy, parameters) so results from several
//! machines can be merged by copying files.

use hirad_accel::cluster::Strategy;
use hirad_accel::ray::Boxes;
use serde::{Deserialize, Serialize};

/// Facts about the run that produced a record (`experiments.md`: scene, parameters, version,
/// commit, threads, machine).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct RunMeta {
    /// Scene path or built-in name.
    pub scene: String,
    /// Objects (groups) of the scene: 1 for a polygon soup without structure.
    #[serde(default)]
    pub scene_objects: usize,
    /// Version of hirad.
    pub hirad_version: String,
    /// Commit the binary was built from ([`git_commit`]).
    pub git_commit: String,
    /// Worker threads.
    pub threads: usize,
    /// CPU model name (the architecture when unknown).
    pub machine: String,
    /// Cores available to the process.
    pub cores: usize,
    /// Total memory, GiB.
    pub memory_gb: f64,
    /// Unix time the record was made, seconds.
    pub date_unix: u64,
}

impl RunMeta {
    /// Metadata of the current process for `scene`.
    pub fn current(scene: &str) -> RunMeta {
        let cpuinfo = std::fs::read_to_string("/proc/cpuinfo").unwrap_or_default();
        let machine = cpuinfo
            .lines()
            .find(|l| l.starts_with("model name"))
            .and_then(|l| l.split(':').nth(1))
            .map(|s| s.trim().to_string())
            .unwrap_or_else(|| std::env::consts::ARCH.to_string());
        let meminfo = std::fs::read_to_string("/proc/meminfo").unwrap_or_default();
        let memory_gb = meminfo
            .lines()
            .find(|l| l.starts_with("MemTotal"))
            .and_then(|l| l.split_whitespace().nth(1))
            .and_then(|k| k.parse::<f64>().ok())
            .map(|kb| kb / 1024.0 / 1024.0)
            .unwrap_or(0.0);
        RunMeta {
            scene: scene.to_string(),
            scene_objects: 0,
            hirad_version: hirad_core::VERSION.to_string(),
            git_commit: git_commit(),
            threads: rayon::current_num_threads(),
            machine,
            cores: std::thread::available_parallelism()
                .map(|n| n.get())
                .unwrap_or(1),
            memory_gb,
            date_unix: std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .map(|d| d.as_secs())
                .unwrap_or(0),
        }
    }
}

static BUILD_COMMIT: std::sync::OnceLock<String> = std::sync::OnceLock::new();

/// Record the commit the running binary was built from (the `hirad` binary embeds it at build
/// time: 12 hex digits, `-dirty` when tracked files differed from it). First call wins.
pub fn set_build_commit(commit: &str) {
    let _ = BUILD_COMMIT.set(commit.to_string());
}

/// The commit given to [`set_build_commit`], "unknown" when none was: what run records carry,
/// never the checkout's HEAD at run time.
pub fn git_commit() -> String {
    BUILD_COMMIT
        .get()
        .cloned()
        .unwrap_or_else(|| "unknown".into())
}

/// Cluster statistics and build time of one strategy (experiments.md §1).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ClusterRecord {
    /// The run that made the record.
    pub meta: RunMeta,
    /// Clustering strategy.
    pub strategy: Strategy,
    /// Clusters (nodes of the tree).
    pub clusters: usize,
    /// Largest node depth (root = 0).
    pub depth_max: usize,
    /// Mean over surfaces of the depth of the node each is attached to.
    pub depth_mean: f64,
    /// Mean surfaces attached directly, over clusters with at least one.
    pub avg_surfaces: f64,
    /// Mean child clusters, over clusters with at least one.
    pub avg_children: f64,
    /// Mean of child clusters + surfaces, over clusters with at least one child cluster.
    pub branching: f64,
    /// Overlap of sibling boxes relative to their parent's volume, summed.
    pub overlap: f64,
    /// Volume enclosed by the boxes relative to a volume scale of the geometry.
    pub empty_space: f64,
    /// Bytes of the tree's arrays.
    pub tree_bytes: usize,
    /// Median of the timed builds, milliseconds.
    pub build_ms: f64,
}

/// Ray-casting test of one strategy (experiments.md §2).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RayRecord {
    /// The run that made the record.
    pub meta: RunMeta,
    /// Clustering strategy.
    pub strategy: Strategy,
    /// Segments cast.
    pub pairs: usize,
    /// Seed of the segments.
    pub seed: u64,
    /// Boxes the traversal tested (records written before the choice existed: tight).
    #[serde(default)]
    pub boxes: Boxes,
    /// Time to build the tree and its caster, milliseconds.
    pub build_ms: f64,
    /// Time to cast the segments, milliseconds.
    pub query_ms: f64,
    /// Segments cast per second, millions.
    pub mrays_per_s: f64,
    /// The `sah` tree's rate on the same segments, timed in the same unit in turns with this
    /// strategy (`ray::turns`): the baseline of "vs sah", free of the drift between units and
    /// of the differences between machines (records written before it: none).
    #[serde(default)]
    pub sah_mrays_per_s: Option<f64>,
    /// Segments found occluded.
    pub occluded: usize,
    /// Mean nodes visited per segment.
    pub nodes_per_ray: f64,
    /// Mean triangle tests per segment.
    pub tris_per_ray: f64,
}

/// One solve of a sweep (experiments.md §4).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SolveRecord {
    /// The run that made the record.
    pub meta: RunMeta,
    /// Clustering strategy.
    pub strategy: Strategy,
    /// Refinement oracle (`bf` or `error`).
    pub refine: String,
    /// Visibility mode of the solve.
    pub visibility: String,
    /// Relative refinement threshold ε of the solve.
    pub eps: f64,
    /// Solve time, seconds (the tree built beforehand).
    pub solve_s: f64,
    /// Elements of the solution.
    pub elements: usize,
    /// Links of the solution.
    pub links: usize,
    /// Energy gathered through links that involve a cluster, percent.
    pub cluster_energy_pct: f64,
    /// RMS ΔE*uv per viewpoint, in the order of the study's viewpoints.
    pub errors: Vec<f64>,
    /// Images written (relative to the study directory).
    pub images: Vec<String>,
}

impl SolveRecord {
    /// Mean error over viewpoints.
    pub fn error(&self) -> f64 {
        if self.errors.is_empty() {
            f64::NAN
        } else {
            self.errors.iter().sum::<f64>() / self.errors.len() as f64
        }
    }
}

/// A reference image (experiments.md §3).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ReferenceRecord {
    /// The run that made the record.
    pub meta: RunMeta,
    /// Viewpoint (camera name).
    pub viewpoint: String,
    /// How the image was made (path tracer and its samples per pixel).
    pub method: String,
    /// Render time, seconds.
    pub seconds: f64,
    /// PNG of the image, relative to the study directory.
    pub image: String,
}

/// The references' own noise at a viewpoint: RMS ΔE*uv between the reference and a second
/// one of another seed (same samples per pixel), the scale below which two solves' errors
/// against the reference cannot be told apart.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct NoiseRecord {
    /// The run that made the record.
    pub meta: RunMeta,
    /// Viewpoint (camera name).
    pub viewpoint: String,
    /// Seed of the second reference.
    pub seed: u64,
    /// RMS ΔE*uv of the second reference against the reference.
    pub delta_e: f64,
    /// Render time of the second reference, seconds.
    pub seconds: f64,
    /// PNG of the second reference, relative to the study directory.
    pub image: String,
}

/// One invocation of a study on a directory: what it computed, what it found done and skipped,
/// and how it ended. A study that was interrupted and resumed has several; their wall times add
/// up to the study's.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct RunRecord {
    /// The run that made the record.
    pub meta: RunMeta,
    /// Unix time the invocation started, seconds.
    pub started_unix: f64,
    /// Wall time of the invocation, seconds.
    pub wall_s: f64,
    /// Keys of the units computed by this invocation, in order.
    pub computed: Vec<String>,
    /// Keys of the units found on disk and skipped.
    pub skipped: Vec<String>,
    /// Temporary files of an earlier, killed invocation that were removed at start.
    pub removed_temp: usize,
    /// `finished`, `interrupted` or `failed: <message>`.
    pub outcome: String,
}
