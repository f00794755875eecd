//! Links: one energy transfer from a source element to a receiver element, stored flat and
//! grouped by receiver after each refinement (CSR-like groups, see [`LinkSet`]).

use super::element::{Elements, Kind};
use rayon::slice::ParallelSliceMut;
use serde::{Deserialize, Serialize};

/// A link from `src` to `recv`: the receiver gathers `k · B_src` (irradiance, W/m²).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Link {
    /// Receiver element id.
    pub recv: u32,
    /// Source element id.
    pub src: u32,
    /// Kernel with visibility (form factor receiver → source); NaN until evaluated.
    pub k: f32,
    /// Oracle quantity per unit source radiosity: `F̃` (bf) or `K_max − K_min` (error).
    pub est: f32,
    /// First of the link's samples in [`LinkSet::samples`] (directional cluster sources), or
    /// [`NO_SAMPLES`]: the receiver then gathers `k · B_src`.
    pub samples: u32,
    /// A surface receiver's sample points and whether their rays saw the source
    /// ([`Deposit`]), pooled over the receiver's links to shape its light.
    pub deposit: Deposit,
    /// Where below a surface source the transfer leaves from ([`Deposit`]): the mean
    /// radiosity there instead of the source's; none: the source's.
    pub draw: Deposit,
    /// A directional cluster receiver whose rays disagree: the start of its run in
    /// [`LinkSet::open_members`] (a header `(count, 0)`, then `(surface, g)`: the surfaces
    /// whose samples saw the source, each getting irradiance `g` times the link's instead of
    /// the cluster's hand-out), or [`NO_SAMPLES`].
    pub open_members: u32,
}

/// Points of a link below its ends, as paths down the midpoint subdivision. On a surface
/// receiver: up to four of its sample points and whether their shadow rays were open;
/// pooled over all the receiver's links they show which parts of it see the room (a wall
/// behind furniture pressed close to it), which no single weak link's oracle would refine.
/// On a surface source whose rays disagree: the ends of open rays, where the transfer
/// leaves from (the mean radiosity there, not the source's mean over parts the receiver
/// does not see).
///
/// Code: bits 0..2 the depth (levels below the receiver; 0: no deposit), bits 2..4 the
/// number of points minus one, bits 4..8 the open mask (bit i: point i's ray was open),
/// bits 8 + 6i.. the path of point i (2 bits per level).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Deposit(pub u32);

impl Deposit {
    /// Levels a path records.
    pub const LEVELS: u32 = 3;
    /// Most points a deposit records.
    pub const POINTS: usize = 4;

    /// A deposit at the points with these paths (at most [`Self::POINTS`], each
    /// [`Self::LEVELS`] deep), all open; none for no path.
    pub fn new(paths: &[u32]) -> Deposit {
        Self::with_mask(paths, (1 << Self::POINTS) - 1)
    }

    /// A deposit at the points with these paths whose rays were open where bit i of `open`
    /// is set; none for no path.
    pub fn with_mask(paths: &[u32], open: u32) -> Deposit {
        let c = paths.len().min(Self::POINTS);
        if c == 0 {
            return Deposit(0);
        }
        let mask = open & ((1 << c) - 1);
        let mut code = Self::LEVELS | ((c as u32 - 1) << 2) | (mask << 4);
        for (i, p) in paths[..c].iter().enumerate() {
            code |= (p & 0x3f) << (8 + 6 * i);
        }
        Deposit(code)
    }

    /// One open point at `path`, followed `depth` levels.
    pub fn single(path: u32, depth: u32) -> Deposit {
        Deposit(depth.min(Self::LEVELS) | 1 << 4 | (path & 0x3f) << 8)
    }

    /// Levels below the receiver the paths are followed (0: the transfer is spread evenly).
    pub fn depth(self) -> u32 {
        self.0 & 3
    }

    /// The same deposit followed at most `d` levels.
    pub fn truncated(self, d: u32) -> Deposit {
        Deposit(self.0 & !3 | d.min(self.depth()))
    }

    /// Number of points (0 for none).
    pub fn points(self) -> usize {
        if self.0 == 0 {
            0
        } else {
            ((self.0 >> 2) & 3) as usize + 1
        }
    }

    /// True when point `i`'s ray was open.
    pub fn open(self, i: usize) -> bool {
        (self.0 >> (4 + i)) & 1 == 1
    }

    /// Number of open points.
    pub fn open_points(self) -> usize {
        (0..self.points()).filter(|&i| self.open(i)).count()
    }

    /// True when some of its points' rays were open and some blocked: a shadow's outline
    /// crosses the receiver.
    pub fn mixed(self) -> bool {
        let all = (1u32 << self.points()) - 1;
        let open = (self.0 >> 4) & all;
        open != 0 && open != all
    }

    /// Path of point `i`.
    pub fn path(self, i: usize) -> u32 {
        (self.0 >> (8 + 6 * i)) & 0x3f
    }
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
            deposit: Deposit(0),
            draw: Deposit(0),
            open_members: NO_SAMPLES,
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

/// The links of a solution, sorted by receiver and then source (so the order does not depend
/// on the thread count), with one group per receiver.
#[derive(Clone, Debug, Default)]
pub struct LinkSet {
    /// The links, sorted by receiver.
    pub links: Vec<Link>,
    /// `(receiver, start, end)` ranges into `links`, receivers ascending.
    pub groups: Vec<(u32, u32, u32)>,
    /// Samples of the links with [`Link::samples`], `per_link` each.
    pub samples: Vec<Sample>,
    /// Samples per link that has them (the shadow rays per link).
    pub per_link: u32,
    /// Runs of open surfaces of the links with [`Link::open_members`].
    pub open_members: Vec<Sample>,
}

impl LinkSet {
    /// Irradiance that link `l` gathers from the radiosities of `el`.
    #[inline]
    pub fn gather(&self, l: &Link, el: &Elements) -> glam::DVec3 {
        let b = &el.b;
        if l.samples == NO_SAMPLES {
            let d = l.draw;
            if d.depth() == 0 {
                return b[l.src as usize] * l.k as f64;
            }
            let mut sum = glam::DVec3::ZERO;
            for i in 0..d.points() {
                let (mut id, mut p) = (l.src, d.path(i));
                for _ in 0..d.depth() {
                    let e = &el.elems[id as usize];
                    if e.num_children == 0 || e.kind != Kind::Surface {
                        break;
                    }
                    id = e.first_child + (p & 3);
                    p >>= 2;
                }
                sum += b[id as usize];
            }
            return sum * (l.k as f64 / d.points() as f64);
        }
        let s = l.samples as usize;
        self.samples[s..s + self.per_link as usize]
            .iter()
            .filter(|m| m.0 != NO_MEMBER)
            .map(|&(m, w)| b[m as usize] * w as f64)
            .sum()
    }

    /// The surfaces of link `l` into a cluster that saw the source, with their irradiance per
    /// unit of the link's ([`Link::open_members`]); empty when it has none.
    #[inline]
    pub fn open_members(&self, l: &Link) -> &[Sample] {
        if l.open_members == NO_SAMPLES {
            return &[];
        }
        let s = l.open_members as usize;
        let n = self.open_members[s].0 as usize;
        &self.open_members[s + 1..s + 1 + n]
    }

    /// Sort `links` by (receiver, source) and build the groups; `samples` holds the samples the
    /// links refer to (`per_link` each) and `open` their open surfaces' runs, compacted here
    /// to those of the links kept. The sort sets aside at most `max_late` links beside them
    /// (see `sort_links`).
    pub fn from_links(
        mut links: Vec<Link>,
        (samples, open): (&[Sample], &[Sample]),
        per_link: u32,
        max_late: usize,
    ) -> LinkSet {
        let pl = per_link as usize;
        let mut kept = Vec::new();
        let mut kept_open = Vec::new();
        for l in links.iter_mut() {
            if l.samples != NO_SAMPLES {
                let s = l.samples as usize;
                l.samples = kept.len() as u32;
                kept.extend_from_slice(&samples[s..s + pl]);
            }
            if l.open_members != NO_SAMPLES {
                let s = l.open_members as usize;
                let n = open[s].0 as usize;
                l.open_members = kept_open.len() as u32;
                kept_open.extend_from_slice(&open[s..s + 1 + n]);
            }
        }
        // (receiver, source) orders the links completely: the order does not depend on the
        // sort or the thread count.
        sort_links(&mut links, max_late);
        // Held for the rest of the solve: no spare capacity (the memory budget counts it).
        links.shrink_to_fit();
        kept.shrink_to_fit();
        kept_open.shrink_to_fit();
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
        groups.shrink_to_fit();
        LinkSet {
            links,
            groups,
            samples: kept,
            per_link,
            open_members: kept_open,
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
            + (self.samples.capacity() + self.open_members.capacity())
                * std::mem::size_of::<Sample>()
    }
}

/// Sort `links` by (receiver, source). A refinement pass keeps most links of the sorted set
/// before it in their order and adds the new ones: the links below the running maximum are
/// set aside, sorted and merged back from the end, unless they are more than a sixteenth of
/// the whole or more than `max_late` (then one parallel sort, in place: the set-aside copy
/// would cost more memory than it saves time, or than a memory budget leaves).
fn sort_links(links: &mut [Link], max_late: usize) {
    let key = |l: &Link| ((l.recv as u64) << 32) | l.src as u64;
    let mut max = 0u64;
    let late = links
        .iter()
        .filter(|l| {
            let k = key(l);
            max = max.max(k);
            k < max
        })
        .count();
    if late > (links.len() / 16).min(max_late) {
        links.par_sort_unstable_by_key(key);
        return;
    }
    let mut rest = Vec::with_capacity(late);
    let mut kept = 0;
    let mut max = 0u64;
    for r in 0..links.len() {
        let l = links[r];
        let k = key(&l);
        if k >= max {
            max = k;
            links[kept] = l;
            kept += 1;
        } else {
            rest.push(l);
        }
    }
    rest.par_sort_unstable_by_key(key);
    // Merge from the back: `links[..kept]` and `rest`, both sorted, into `links`.
    let (mut i, mut j) = (kept, rest.len());
    for k in (0..links.len()).rev() {
        if j == 0 {
            break;
        }
        if i > 0 && key(&links[i - 1]) > key(&rest[j - 1]) {
            links[k] = links[i - 1];
            i -= 1;
        } else {
            links[k] = rest[j - 1];
            j -= 1;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::{sort_links, Deposit, Link};
    use hirad_core::rng::SplitMix64;

    #[test]
    fn sort_links_orders_by_receiver_then_source() {
        let mut rng = SplitMix64::new(7);
        let mut r = |n: u64| (rng.next_u64() % n) as u32;
        // A sorted set with new links after it (the merge) and a shuffled one (the full sort).
        let mut sorted: Vec<Link> = (0..3000).map(|_| Link::new(r(500), r(500))).collect();
        sorted.sort_by_key(|l| (l.recv, l.src));
        sorted.dedup_by_key(|l| (l.recv, l.src));
        let mut extra: Vec<Link> = (0..300).map(|_| Link::new(500 + r(50), r(500))).collect();
        extra.extend((0..200).map(|_| Link::new(r(500), 500 + r(50))));
        extra.sort_by_key(|l| (l.recv, l.src));
        extra.dedup_by_key(|l| (l.recv, l.src));
        for late in [extra.len(), 0] {
            let mut links = sorted.clone();
            links.extend_from_slice(&extra[..late]);
            let mut want = links.clone();
            want.sort_by_key(|l| (l.recv, l.src));
            let mut shuffled = links.clone();
            for i in (1..shuffled.len()).rev() {
                shuffled.swap(i, r(i as u64 + 1) as usize);
            }
            // usize::MAX: merge where few are out of order; 0: always the full sort.
            for (mut got, max_late) in [(links.clone(), usize::MAX), (links, 0), (shuffled, 99)] {
                sort_links(&mut got, max_late);
                let keys = |v: &[Link]| v.iter().map(|l| (l.recv, l.src)).collect::<Vec<_>>();
                assert_eq!(keys(&got), keys(&want));
            }
        }
    }

    #[test]
    fn deposit_codes_keep_paths_and_open_rays() {
        assert_eq!(Deposit::with_mask(&[], 0b1111).points(), 0);
        let d = Deposit::with_mask(&[0b11_01_10, 0, 0b10_10_10], 0b1101);
        assert_eq!(
            (d.points(), d.depth(), d.open_points()),
            (3, Deposit::LEVELS, 2)
        );
        assert_eq!(
            [d.path(0), d.path(1), d.path(2)],
            [0b11_01_10, 0, 0b10_10_10]
        );
        assert_eq!([d.open(0), d.open(1), d.open(2)], [true, false, true]);
        // Mixed: some rays open and some blocked, among the points it has (the mask's bits
        // past them do not count).
        assert!(d.mixed());
        assert!(!Deposit::with_mask(&[1, 2], 0b1100).mixed());
        assert!(!Deposit::with_mask(&[1, 2], 0b1111).mixed());
        assert!(Deposit::with_mask(&[1, 2], 0b0010).mixed());
        assert!(!Deposit::single(3, 1).mixed());
        assert!(!Deposit(0).mixed());
        let all = Deposit::new(&[1, 2, 3, 4, 5]);
        assert_eq!((all.points(), all.open_points()), (4, 4));
        assert!(!all.mixed());
        let t = all.truncated(1);
        assert_eq!((t.depth(), t.points(), t.path(3)), (1, 4, 4));
        let s = Deposit::single(0b01_11, 2);
        assert_eq!(
            (s.points(), s.depth(), s.path(0), s.open(0)),
            (1, 2, 0b01_11, true)
        );
    }
}
