#![warn(missing_docs)]
//! Images: pinhole camera, z-buffer rasteriser of per-vertex radiance, path-traced references,
//! EXR and PNG output.
//!
//! - [`camera`]: [`CameraView`] (eye, target, up, vertical fov, size) and its frame;
//! - [`image`]: [`Image`] (linear RGB f32, row-major, top row first), EXR/PNG writers and readers;
//! - [`raster`]: z-buffer rasteriser of a triangle mesh with per-vertex (Gouraud,
//!   perspective-correct) or per-triangle radiance, supersampling, near-plane clipping;
//! - [`pathtrace`]: the path-traced reference with the solver's conventions;
//! - [`gather`]: final gather, a path-traced first bounce that reads indirect light from a
//!   solution.
//!
//! Pixels are radiance in W/(m²·sr). A radiosity solution stores radiosity B (W/m²) per vertex;
//! a diffuse surface of radiosity B has radiance B/π, which is what [`raster::render_solution`]
//! draws, so rasterised solutions compare directly with path-traced references.

pub mod camera;
mod facing;
pub mod gather;
pub mod image;
pub mod metrics;
pub mod pathtrace;
pub mod raster;
mod sample;

pub use camera::{CameraFrame, CameraOverrides, CameraView};
pub use gather::{render_gather, GatherOptions, GatherStats, Gatherer, Lookup, SolutionLookup};
pub use image::{Image, ImageFormat};
pub use pathtrace::{
    render_reference, PathTracer, RayLog, RayReplay, ReferenceOptions, ReferenceStats,
};
pub use raster::{rasterize, render_solution, BackFaces, MeshColors, RasterMesh, RasterOptions};
