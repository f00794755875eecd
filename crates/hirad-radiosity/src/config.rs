//! Solver configuration (`SolverConfig`), its presets and parsing helpers.
//!
//! Default tolerance: when no absolute `eps` is given, the refinement threshold is
//! `eps_rel × B_ref`, where `B_ref = (Φ_emitted + Φ_sun + Φ_sky) / A_total` is the scene's mean
//! emitted exitance spread over all of its surface (W/m²). Both oracles compare a radiosity-like
//! quantity (W/m²) against ε, so the same relative default works for any scene scale. The same
//! holds for the minimum element area: `min_area_rel × A_total` unless `min_area` is given.

use hirad_core::{choice, Error, Result};
use serde::{Deserialize, Serialize};

/// Refinement oracle (`--refine`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "lowercase")]
pub enum Oracle {
    /// Hanrahan's BF: refine while `B_j · F̃_ij > ε`.
    #[default]
    Bf,
    /// Kernel-bounds error: refine while `ρ_i (K_max − K_min) A_j B_j > ε`.
    Error,
}

/// Visibility estimation (`--visibility`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "lowercase")]
pub enum VisibilityMode {
    /// Stratified jittered shadow rays cast through the cluster tree.
    #[default]
    Rays,
    /// Volumetric transmittance through clusters (Sillion 1995).
    Volume,
    /// Everything is mutually visible.
    None,
}

/// How a cluster hands received irradiance to its surfaces (`--cluster-receive`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "lowercase")]
pub enum Reception {
    /// Each surface k gets `H · max(0, cos θ_k)` (θ_k between its normal and the source).
    #[default]
    Oriented,
    /// Each surface gets `H / 4` (the cluster intercepts `H · ΣA / 4`).
    Isotropic,
}

/// How a cluster emits (`--cluster-emission`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "lowercase")]
pub enum ClusterEmission {
    /// Sillion's isotropic cluster: radiant intensity `Φ/4π`, projected area `ΣA/4` in every
    /// direction (the paper's model).
    Isotropic,
    /// Projected area towards the receiver from the order-2 spherical-harmonic expansion of
    /// the contents' `Σ A_k max(0, n_k·d)` ([`ClusterOrient::projected_area`]); its order-0
    /// term is the isotropic model.
    ///
    /// [`ClusterOrient::projected_area`]: super::element::ClusterOrient::projected_area
    #[default]
    Directional,
}

choice!(Oracle, "refinement oracle", Bf => "bf", Error => "error");
choice!(VisibilityMode, "visibility mode", Rays => "rays", Volume => "volume", None => "none");
choice!(Reception, "cluster reception", Oriented => "oriented", Isotropic => "isotropic");
choice!(ClusterEmission, "cluster emission", Isotropic => "isotropic", Directional => "directional");

/// Every parameter of a solve. `Default` is the `default` preset.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct SolverConfig {
    /// Refinement oracle.
    pub refine: Oracle,
    /// Absolute refinement threshold ε (W/m²); `None`: `eps_rel × B_ref` (module docs).
    pub eps: Option<f64>,
    /// Relative refinement threshold used when `eps` is `None`.
    pub eps_rel: f64,
    /// Absolute minimum element area; `None`: `min_area_rel × total area`.
    pub min_area: Option<f64>,
    /// Relative minimum element area used when `min_area` is `None`.
    pub min_area_rel: f64,
    /// Levels of 4-way subdivision allowed below the minimum element area for a surface
    /// receiver whose link the oracle would still refine and whose transfer varies across it
    /// by more than ε: its shadow rays disagree (a shadow boundary) or its unoccluded kernel
    /// varies (a source close beside it). Beside a close surface source such a receiver goes
    /// one level further while it is wider than its distance to the source.
    pub shadow_levels: u32,
    /// Shadow rays per link (stratified, jittered).
    pub shadow_rays: u32,
    /// Visibility estimation.
    pub visibility: VisibilityMode,
    /// Volume visibility: a cluster is used as a volume when its size is below
    /// `vol_ratio × segment length`.
    pub vol_ratio: f32,
    /// Give each surface a back face with its own radiosity.
    pub two_sided: bool,
    /// Cluster reception model.
    pub cluster_receive: Reception,
    /// How a cluster emits.
    pub cluster_emission: ClusterEmission,
    /// Maximum refine+gather iterations.
    pub max_iters: u32,
    /// Stop when the relative change of total power falls below this.
    pub tol_converge: f64,
    /// Memory budget of the whole process in bytes (`None`: unlimited; see
    /// [`crate::memory`]).
    pub max_memory: Option<u64>,
    /// Bytes the caller holds beside the solve (images) that the budget must leave free.
    pub reserved_memory: u64,
    /// Rays per surface element for sky irradiance (scenes with a sky).
    pub sky_rays: u32,
    /// Seed of every random choice (combined with element and link ids).
    pub seed: u64,
    /// Also refine a link from a cluster while the bound on the error of the isotropic
    /// emission model (`KernelCtx::anisotropy`) times `B_j · F̃` exceeds ε: flat clusters that
    /// face their receiver show up to 4× the isotropic projected area `ΣA/4`.
    pub anisotropy_refine: bool,
}

impl Default for SolverConfig {
    fn default() -> Self {
        Self {
            refine: Oracle::Bf,
            eps: None,
            eps_rel: 0.05,
            min_area: None,
            min_area_rel: 1e-3,
            shadow_levels: 2,
            shadow_rays: 4,
            visibility: VisibilityMode::Rays,
            vol_ratio: 0.1,
            two_sided: false,
            cluster_receive: Reception::Oriented,
            cluster_emission: ClusterEmission::default(),
            max_iters: 100,
            tol_converge: 1e-4,
            max_memory: None,
            reserved_memory: 0,
            sky_rays: 16,
            seed: 1,
            anisotropy_refine: true,
        }
    }
}

impl SolverConfig {
    /// Names of the presets.
    pub const PRESETS: [&'static str; 4] = ["fast", "default", "fine", "reference"];

    /// A named preset: `fast` (ε×4, 1 shadow ray, elements ×4 larger), `default`, `fine`
    /// (ε/4, 8 rays: little energy left on cluster links, the furnace-accurate setting),
    /// `reference` (ε/16, 16 rays, elements /4).
    pub fn preset(name: &str) -> Result<SolverConfig> {
        let d = SolverConfig::default();
        Ok(match name.to_ascii_lowercase().as_str() {
            "fast" => SolverConfig {
                eps_rel: d.eps_rel * 4.0,
                shadow_rays: 1,
                min_area_rel: d.min_area_rel * 4.0,
                ..d
            },
            "default" => d,
            "fine" => SolverConfig {
                eps_rel: d.eps_rel / 4.0,
                shadow_rays: 8,
                ..d
            },
            "reference" => SolverConfig {
                eps_rel: d.eps_rel / 16.0,
                shadow_rays: 16,
                min_area_rel: d.min_area_rel / 4.0,
                ..d
            },
            _ => {
                return Err(Error::Config(format!(
                    "unknown solver preset '{name}' (one of: {})",
                    Self::PRESETS.join(", ")
                )))
            }
        })
    }

    /// Check parameter ranges.
    pub fn validate(&self) -> Result<()> {
        let bad = |m: String| Err(Error::Config(m));
        if let Some(e) = self.eps {
            if !(e.is_finite() && e > 0.0) {
                return bad(format!("eps must be > 0, got {e}"));
            }
        }
        if !(self.eps_rel.is_finite() && self.eps_rel > 0.0) {
            return bad(format!("eps-rel must be > 0, got {}", self.eps_rel));
        }
        if let Some(a) = self.min_area {
            if !(a.is_finite() && a >= 0.0) {
                return bad(format!("min-area must be >= 0, got {a}"));
            }
        }
        if !(self.min_area_rel.is_finite() && self.min_area_rel >= 0.0) {
            return bad(format!(
                "min-area-rel must be >= 0, got {}",
                self.min_area_rel
            ));
        }
        if self.shadow_levels > 8 {
            return bad(format!(
                "shadow-levels must be in 0..=8, got {}",
                self.shadow_levels
            ));
        }
        if self.shadow_rays == 0 || self.shadow_rays > 1024 {
            return bad(format!(
                "shadow-rays must be in 1..=1024, got {}",
                self.shadow_rays
            ));
        }
        if !(self.vol_ratio.is_finite() && self.vol_ratio > 0.0) {
            return bad(format!("vol-ratio must be > 0, got {}", self.vol_ratio));
        }
        if self.max_iters == 0 {
            return bad("max-iters must be >= 1".into());
        }
        if !(self.tol_converge.is_finite() && self.tol_converge >= 0.0) {
            return bad(format!(
                "tol-converge must be >= 0, got {}",
                self.tol_converge
            ));
        }
        if self.sky_rays == 0 {
            return bad("sky-rays must be >= 1".into());
        }
        Ok(())
    }
}

/// Parse a byte size such as `4GB`, `512MiB`, `100M`, `2e9` (decimal and binary units).
pub fn parse_bytes(s: &str) -> Result<u64> {
    let t = s.trim();
    let split = t.find(|c: char| c.is_ascii_alphabetic()).unwrap_or(t.len());
    let (num, unit) = t.split_at(split);
    let v: f64 = num
        .trim()
        .parse()
        .map_err(|_| Error::Config(format!("cannot parse memory size '{s}'")))?;
    let mult: f64 = match unit.trim().to_ascii_lowercase().as_str() {
        "" | "b" => 1.0,
        "k" | "kb" => 1e3,
        "m" | "mb" => 1e6,
        "g" | "gb" => 1e9,
        "t" | "tb" => 1e12,
        "kib" => 1024.0,
        "mib" => 1024.0 * 1024.0,
        "gib" => 1024.0 * 1024.0 * 1024.0,
        _ => return Err(Error::Config(format!("unknown unit in memory size '{s}'"))),
    };
    let b = v * mult;
    if !(b.is_finite() && b >= 1.0) {
        return Err(Error::Config(format!("memory size '{s}' must be positive")));
    }
    Ok(b as u64)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_sizes_and_presets() {
        assert_eq!(parse_bytes("4GB").unwrap(), 4_000_000_000);
        assert_eq!(parse_bytes("512MiB").unwrap(), 512 * 1024 * 1024);
        assert_eq!(parse_bytes("1000").unwrap(), 1000);
        assert!(parse_bytes("lots").is_err());
        assert!(parse_bytes("-1GB").is_err());
        for p in SolverConfig::PRESETS {
            SolverConfig::preset(p).unwrap().validate().unwrap();
        }
        assert!(SolverConfig::preset("x").is_err());
        let c: SolverConfig = serde_json::from_str(r#"{"refine":"error","eps":0.5}"#).unwrap();
        assert_eq!(c.refine, Oracle::Error);
        assert_eq!(c.eps, Some(0.5));
        assert_eq!(c.shadow_rays, 4);
    }

    #[test]
    fn choices_parse_their_names_and_list_them_on_error() {
        assert_eq!(Oracle::parse("BF").unwrap(), Oracle::Bf);
        assert_eq!(VisibilityMode::parse("volume").unwrap().name(), "volume");
        assert_eq!(Reception::parse("isotropic").unwrap(), Reception::Isotropic);
        assert_eq!(ClusterEmission::Directional.name(), "directional");
        let msg = |e: Error| e.to_string();
        assert!(msg(VisibilityMode::parse("x").unwrap_err())
            .contains("unknown visibility mode 'x' (rays, volume or none)"));
        assert!(msg(Oracle::parse("y").unwrap_err())
            .contains("unknown refinement oracle 'y' (bf or error)"));
        assert_eq!(hirad_core::error::alternatives(&["a"]), "a");
    }
}
