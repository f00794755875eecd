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

/// `parse` (case-insensitive) and `name` of a command-line choice, from one table of names;
/// the error lists the names ("unknown refinement oracle 'x' (bf or error)"). Defined before
/// the modules so that every module can use it.
macro_rules! choice {
    ($t:ident, $what:literal, $($v:ident => $s:literal),+ $(,)?) => {
        impl $t {
            /// Parse the name given on the command line (any case).
            pub fn parse(s: &str) -> $crate::Result<$t> {
                match s.to_ascii_lowercase().as_str() {
                    $($s => Ok($t::$v),)+
                    _ => Err($crate::Error::Config(format!(
                        "unknown {} '{s}' ({})",
                        $what,
                        $crate::error::alternatives(&[$($s),+])
                    ))),
                }
            }

            /// Name as on the command line.
            pub fn name(self) -> &'static str {
                match self {
                    $($t::$v => $s,)+
                }
            }
        }
    };
}

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
