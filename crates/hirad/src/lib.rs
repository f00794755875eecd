#![warn(missing_docs)]
//! hirad — hierarchical radiosity with clustering.
//!
//! The system studied in Hasenfratz, Damez, Sillion & Drettakis, *A Practical Analysis of
//! Clustering Strategies for Hierarchical Radiosity* (EG'99): one [`cluster::ClusterTree`] type
//! built by every clustering strategy of the paper, used both as the radiosity cluster hierarchy
//! and as the ray-casting accelerator. This crate re-exports the workspace's crates in the order
//! data flows through them:
//!
//! | module | crate | what |
//! |---|---|---|
//! | [`error`], [`geom`], [`io`], [`rng`], [`progress`] | `hirad-core` | errors, boxes, atomic files, random numbers, progress hook |
//! | [`scene`] | `hirad-scene` | scene model, loaders (OBJ, glTF, PLY, MGF, TOML), exporters, built-ins |
//! | [`cluster`], [`ray`] | `hirad-accel` | cluster trees (one file per strategy), ray casting |
//! | [`radiosity`] | `hirad-radiosity` | elements, links, the cluster model, the solver |
//! | [`render`], [`metrics`] | `hirad-render` | camera, rasteriser, path tracer, final gather, images, CIELUV |
//! | [`study`] | `hirad-study` | the paper's experiments, plots, reports |
//!
//! Solve the built-in Cornell box and read the solution:
//!
//! ```
//! use hirad::cluster::{ClusterConfig, ClusterTree, Strategy};
//! use hirad::progress::NoProgress;
//! use hirad::radiosity::{solve, SolverConfig};
//! use hirad::scene::{Scene, SceneOptions};
//!
//! let scene = Scene::load("cornell", &SceneOptions::default())?;
//! let tree = ClusterTree::build(&scene, Strategy::Proxi, &ClusterConfig::default());
//! let solution = solve(&scene, &tree, &SolverConfig::preset("fast")?, &NoProgress)?;
//! // The back wall (white, lit by the ceiling lamp) has a positive radiosity.
//! assert!(solution.triangle_radiosity(0, false).max_element() >= 0.0);
//! assert!(solution.links.len() > 0);
//! # Ok::<(), hirad::Error>(())
//! ```

pub use hirad_accel::{cluster, ray};
pub use hirad_core::{error, geom, io, progress, rng, Error, Result, VERSION};
pub use hirad_radiosity as radiosity;
pub use hirad_render::{self as render, metrics};
pub use hirad_scene as scene;
pub use hirad_study as study;
