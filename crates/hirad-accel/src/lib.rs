#![warn(missing_docs)]
//! One cluster tree type, built by every clustering strategy of the paper (and `sah`), and ray
//! casting through it: the tree is both the radiosity hierarchy and the ray accelerator.
//!
//! - [`cluster`]: the tree, one file per strategy, statistics and box dumps;
//! - [`ray`]: the tree's ray layout and traversal, segment sampling, volumetric visibility.

pub mod cluster;
pub mod ray;
