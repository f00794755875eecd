//! Form factors and link kernels. All kernels are form factors from the receiver to the
//! source (dimensionless): a receiver gathers the irradiance `K_ij · B_j` from a source of
//! radiosity `B_j`.
//!
//! - [`analytic`]: point-to-disk estimate, point-to-polygon form factor;
//! - [`sampling`]: points on triangles (area-uniform, or by the kernel's solid angle),
//!   stratified and jittered-grid samples;
//! - [`KernelCtx`]: the sampled kernels of the solver, with shadow rays ([`KernelEval`]);
//! - near links: surfaces closer than their size integrate on a grid, cluster ends are
//!   bounded ([`KernelCtx::near_bound`]).
//!
//! The cluster emission models sit in [`crate::cluster_model`].

pub mod analytic;
pub(crate) mod kernel;
pub(crate) mod near_field;
pub mod sampling;

pub use self::analytic::{
    parallel_disk_exact, point_to_disk, point_to_polygon, point_to_polygon_many,
};
pub use self::kernel::{KernelCtx, KernelEval};
pub use self::sampling::{
    jittered_grid, sample_triangle, sample_triangle_above, sample_triangle_above_area,
    sample_triangle_inset, stratified_2d,
};
pub use crate::cluster_model::SH2_ERROR;

#[cfg(test)]
mod tests;
