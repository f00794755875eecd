//! hirad — hierarchical radiosity with clustering.
//!
//! Implements the system studied in Hasenfratz, Damez, Sillion & Drettakis,
//! *A Practical Analysis of Clustering Strategies for Hierarchical Radiosity* (EG'99):
//! one [`cluster::ClusterTree`] type built by every clustering strategy of the paper, used both
//! as the radiosity cluster hierarchy and as the ray-casting accelerator.
//!
//! Module map (one concept each):
//! - [`scene`]: the scene model (flat arrays), loaders (OBJ/MTL, glTF, PLY, TOML scene files),
//!   built-in procedural scenes;
//! - [`cluster`]: the cluster tree and one file per construction strategy, statistics;
//! - [`ray`]: ray casting through a cluster tree, the paper's ray-casting test;
//! - [`radiosity`]: the hierarchical radiosity solver;
//! - [`render`]: camera, rasteriser, path-traced references, image output;
//! - [`metrics`]: CIELUV image error;
//! - [`study`]: the paper's experiments as reproducible sweeps.

pub mod cluster;
pub mod error;
pub mod geom;
pub mod io;
pub mod metrics;
pub mod progress;
pub mod radiosity;
pub mod ray;
pub mod render;
pub mod rng;
pub mod scene;
pub mod study;

pub use error::{Error, Result};

/// Version of the library, recorded in every experiment output.
pub const VERSION: &str = env!("CARGO_PKG_VERSION");
