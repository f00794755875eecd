//! Links: one energy transfer from a source element to a receiver element, stored flat and
//! grouped by receiver after each refinement (CSR-like groups, see [`LinkSet`]).

use super::element::{Elements, Kind};
use serde::{Deserialize, Serialize};

/// A link from `src` to `recv`: the receiver gathers `k · B_src` (irradiance, W/m²).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Link {
    pub recv: u32,
    pub src: u32,
    /// Kernel with visibility (form factor receiver → source); NaN until evaluated.
    pub k: f32,
    /// Oracle quantity per unit source radiosity: `F̃` (bf) or `K_max − K_min` (error).
    pub est: f32,
    /// First of the link's samples in [`LinkSet::samples`] (directional cluster sources), or
    /// [`NO_SAMPLES`]: the receiver then gathers `k · B_src`.
    pub samples: u32,
}

/// [`Link::samples`] of a link that gathers `k · B_src`.
pub const NO_SAMPLES: u32 = u32::MAX;

/// [`Sample`] surface of a sample that found no surface (an empty cluster).
pub const NO_MEMBER: u32 = u32::MAX;

/// One sample of a directional cluster source: the surface element its point lies on and its
/// share of the link's kernel.
pub type Sample = (u32, f32);

impl Link {
    /// A link whose kernel is not evaluated yet.
    pub fn new(recv: u32, src: u32) -> Self {
        Self {
            recv,
            src,
            k: f32::NAN,
            est: f32::NAN,
            samples: NO_SAMPLES,
        }
    }

    /// True when the kernel is evaluated.
    #[inline]
    pub fn evaluated(&self) -> bool {
        !self.k.is_nan()
    }
}

/// Kind of link by the kinds of its ends.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum LinkKind {
    /// Surface–surface.
    Ss,
    /// Cluster–surface (either direction).
    Cs,
    /// Cluster–cluster.
    Cc,
}

impl LinkKind {
    /// Kind of the link between two elements.
    pub fn of(elems: &Elements, l: &Link) -> LinkKind {
        let a = elems.elems[l.recv as usize].kind == Kind::Cluster;
        let b = elems.elems[l.src as usize].kind == Kind::Cluster;
        match (a, b) {
            (false, false) => LinkKind::Ss,
            (true, true) => LinkKind::Cc,
            _ => LinkKind::Cs,
        }
    }
}

/// The links of a solution, sorted by receiver (stable, so the order within a receiver is
/// the deterministic refinement order), with one group per receiver.
#[derive(Clone, Debug, Default)]
pub struct LinkSet {
    pub links: Vec<Link>,
    /// `(receiver, start, end)` ranges into `links`, receivers ascending.
    pub groups: Vec<(u32, u32, u32)>,
    /// Samples of the links with [`Link::samples`], `per_link` each.
    pub samples: Vec<Sample>,
    pub per_link: u32,
}

impl LinkSet {
    /// Irradiance per unit of the radiosities `b` that link `l` gathers.
    #[inline]
    pub fn gather(&self, l: &Link, b: &[glam::DVec3]) -> glam::DVec3 {
        if l.samples == NO_SAMPLES {
            return b[l.src as usize] * l.k as f64;
        }
        let s = l.samples as usize;
        self.samples[s..s + self.per_link as usize]
            .iter()
            .filter(|m| m.0 != NO_MEMBER)
            .map(|&(m, w)| b[m as usize] * w as f64)
            .sum()
    }

    /// Sort `links` by receiver and build the groups; `samples` holds the samples the links
    /// refer to (`per_link` each), compacted here to those of the links kept.
    pub fn from_links(mut links: Vec<Link>, samples: &[Sample], per_link: u32) -> LinkSet {
        let pl = per_link as usize;
        let mut kept = Vec::new();
        for l in links.iter_mut() {
            if l.samples != NO_SAMPLES {
                let s = l.samples as usize;
                l.samples = kept.len() as u32;
                kept.extend_from_slice(&samples[s..s + pl]);
            }
        }
        links.sort_by_key(|l| l.recv);
        let mut groups = Vec::new();
        let mut s = 0usize;
        while s < links.len() {
            let r = links[s].recv;
            let mut e = s + 1;
            while e < links.len() && links[e].recv == r {
                e += 1;
            }
            groups.push((r, s as u32, e as u32));
            s = e;
        }
        LinkSet {
            links,
            groups,
            samples: kept,
            per_link,
        }
    }

    /// Number of links.
    pub fn len(&self) -> usize {
        self.links.len()
    }

    /// True when there are no links.
    pub fn is_empty(&self) -> bool {
        self.links.is_empty()
    }

    /// Bytes used.
    pub fn memory_bytes(&self) -> usize {
        self.links.capacity() * std::mem::size_of::<Link>()
            + self.groups.capacity() * 12
            + self.samples.capacity() * std::mem::size_of::<Sample>()
    }
}
