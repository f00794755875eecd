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
}

impl Link {
    /// A link whose kernel is not evaluated yet.
    pub fn new(recv: u32, src: u32) -> Self {
        Self {
            recv,
            src,
            k: f32::NAN,
            est: f32::NAN,
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
}

impl LinkSet {
    /// Sort `links` by receiver and build the groups.
    pub fn from_links(mut links: Vec<Link>) -> LinkSet {
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
        LinkSet { links, groups }
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
        self.links.capacity() * std::mem::size_of::<Link>() + self.groups.capacity() * 12
    }
}
