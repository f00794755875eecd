#![warn(missing_docs)]

//! The hierarchical radiosity solver with clustering (`spec/radiosity.md`).
//!
//! - [`element`]: one arena of surface elements (triangle quadtrees) and cluster elements;
//! - [`link`]: links stored flat and grouped by receiver;
//! - [`formfactor`]: point-to-disk and analytic point-to-polygon form factors, sampled kernels;
//! - [`cluster_model`]: the isotropic and directional cluster emission models side by side;
//! - [`oracle`]: the `bf` and `error` refinement oracles;
//! - [`visibility`]: shadow rays through the cluster tree (and the volume hook);
//! - [`overlap`]: coplanar overlapping triangles, each overlap given to one of them;
//! - [`shut`]: the parts of triangles inside closed solids;
//! - [`solver`]: refine / gather / push-pull until convergence;
//! - [`config`]: [`SolverConfig`] and presets; [`stats`]: [`SolveStats`];
//! - [`output`]: per-vertex radiosity meshes and result files;
//! - [`memory`]: the whole-process memory budget and its estimate.
//!
//! Entry point: [`solve`].

pub mod cluster_model;
pub mod config;
pub mod element;
pub mod formfactor;
pub mod link;
pub mod memory;
pub mod oracle;
pub mod output;
pub mod overlap;
pub mod shut;
pub mod solver;
pub mod stats;
pub mod visibility;

pub use config::{ClusterEmission, Oracle, Reception, SolverConfig, VisibilityMode};
pub use solver::{solve, solve_cancellable, solve_recording, Solution};
pub use stats::SolveStats;
