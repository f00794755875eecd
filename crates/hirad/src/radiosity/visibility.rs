//! Visibility between link ends (`--visibility rays|volume|none`).
//!
//! `rays` casts each shadow segment through the [`ClusterTree`] with the shared
//! [`RayCaster`] (paper §3.2.2: one structure for clustering and ray casting). `none` makes
//! everything mutually visible. `volume` (Sillion 1995 transmittance) is answered by the ray
//! module's volumetric traversal when it is available; until then asking for it is a
//! configuration error rather than a silent fallback.

use super::config::VisibilityMode;
use crate::cluster::ClusterTree;
use crate::ray::RayCaster;
use crate::scene::Scene;
use crate::{Error, Result};
use glam::Vec3;

/// Visibility oracle of a solve.
pub struct Visibility<'a> {
    mode: VisibilityMode,
    caster: RayCaster<'a>,
    /// Volume mode: clusters smaller than `vol_ratio × segment length` act as volumes.
    pub vol_ratio: f32,
}

impl<'a> Visibility<'a> {
    /// Prepare visibility queries of `mode` over `scene` and its `tree`.
    pub fn new(
        scene: &'a Scene,
        tree: &'a ClusterTree,
        mode: VisibilityMode,
        vol_ratio: f32,
    ) -> Result<Self> {
        if mode == VisibilityMode::Volume {
            return Err(Error::Config(
                "--visibility volume needs the volumetric traversal of the ray module, which \
                 is not available in this build; use rays or none"
                    .into(),
            ));
        }
        Ok(Self {
            mode,
            caster: RayCaster::new(scene, tree),
            vol_ratio,
        })
    }

    /// The mode in use.
    pub fn mode(&self) -> VisibilityMode {
        self.mode
    }

    /// Fraction of light passing along `origin + t·dir`, `t ∈ [t0, t1]`: 0 or 1 for rays,
    /// 1 for `none`. `_from` and `_to` are the centres of the link ends (used by the volume
    /// traversal to exclude the end clusters).
    #[inline]
    pub fn transmittance(
        &self,
        origin: Vec3,
        dir: Vec3,
        t0: f32,
        t1: f32,
        _from: Vec3,
        _to: Vec3,
    ) -> f64 {
        match self.mode {
            VisibilityMode::None => 1.0,
            VisibilityMode::Rays | VisibilityMode::Volume => {
                if self.caster.occluded(origin, dir, t0, t1) {
                    0.0
                } else {
                    1.0
                }
            }
        }
    }

    /// True when the ray towards a distant light (sun, sky) is blocked.
    #[inline]
    pub fn blocked_to_infinity(&self, origin: Vec3, dir: Vec3, tmin: f32) -> bool {
        match self.mode {
            VisibilityMode::None => false,
            _ => self.caster.occluded(origin, dir, tmin, f32::MAX),
        }
    }
}
