#![warn(missing_docs)]
//! hirad — hierarchical radiosity with clustering, after Hasenfratz, Damez, Sillion & Drettakis
//! (EG'99): one [`cluster::ClusterTree`] built by every clustering strategy of the paper serves
//! as the radiosity hierarchy and as the ray accelerator. This facade re-exports the crates in
//! data-flow order: `hirad-core` ([`error`], [`geom`], [`io`], [`rng`], [`progress`]) →
//! `hirad-scene` ([`scene`]) → `hirad-accel` ([`cluster`], [`ray`]) → `hirad-radiosity`
//! ([`radiosity`]) → `hirad-render` ([`render`], [`metrics`]) → `hirad-study` ([`study`]).
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
//! for tri in 0..scene.num_triangles() as u32 {
//!     let b = solution.triangle_radiosity(tri, false); // W/m², RGB
//!     assert!(b.is_finite() && b.min_element() >= 0.0);
//! }
//! assert!(solution.links.len() > 0);
//! # Ok::<(), hirad::Error>(())
//! ```

pub use hirad_accel::{cluster, ray};
pub use hirad_core::{error, geom, io, progress, rng, Error, Result, VERSION};
pub use hirad_radiosity as radiosity;
pub use hirad_render::{self as render, metrics};
pub use hirad_scene as scene;
pub use hirad_study as study;
