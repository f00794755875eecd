//! Refinement oracles (`--refine bf|error`) and the choice of which end to subdivide.

use super::config::Oracle;
use super::element::{Element, Kind};
use glam::DVec3;

/// What refinement does with a link.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Action {
    /// Keep the link at this level.
    Keep,
    /// Drop it: its kernel is identically zero (or a surface self-link).
    Drop,
    /// Replace by links from the source to each child of the receiver.
    SplitRecv,
    /// Replace by links from each child of the source to the receiver.
    SplitSrc,
    /// Self-link of a cluster: links between every pair of its children.
    SplitBoth,
}

/// Oracle value of a link: `B_j · F̃` (bf) or `ρ_i (K_max − K_min) B_j` (error), taking the
/// largest colour channel. `est` is the stored per-unit-radiosity quantity of the link.
#[inline]
pub fn value(oracle: Oracle, est: f64, b_src: DVec3, rho_recv: DVec3) -> f64 {
    match oracle {
        Oracle::Bf => est * b_src.max_element(),
        Oracle::Error => est * (b_src * rho_recv).max_element(),
    }
}

/// True when the oracle asks for refinement.
#[inline]
pub fn wants_refine(oracle: Oracle, eps: f64, est: f64, b_src: DVec3, rho_recv: DVec3) -> bool {
    value(oracle, est, b_src, rho_recv) > eps
}

/// Which end to subdivide when refining (receiver `r`, source `s`, distinct elements):
/// clusters before surfaces, otherwise the larger by area; a surface is subdivided only when
/// its area is above `min_area`. `None` when neither can be subdivided.
pub fn choose_split(r: &Element, s: &Element, min_area: f64) -> Option<Action> {
    let can = |e: &Element| match e.kind {
        Kind::Cluster => e.num_children > 0,
        Kind::Surface => e.area as f64 > min_area,
    };
    let rc = r.kind == Kind::Cluster;
    let sc = s.kind == Kind::Cluster;
    let first = match (rc, sc) {
        (true, false) => Action::SplitRecv,
        (false, true) => Action::SplitSrc,
        _ => {
            if r.area >= s.area {
                Action::SplitRecv
            } else {
                Action::SplitSrc
            }
        }
    };
    let (a, b) = (can(r), can(s));
    match first {
        Action::SplitRecv if a => Some(Action::SplitRecv),
        Action::SplitSrc if b => Some(Action::SplitSrc),
        // The preferred end is at its minimum size: split the other one only when it is a
        // surface above the minimum (never a cluster against a surface preference).
        Action::SplitRecv if b && !rc => Some(Action::SplitSrc),
        Action::SplitSrc if a && !sc => Some(Action::SplitRecv),
        _ => None,
    }
}
