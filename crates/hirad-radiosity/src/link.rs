//! Links: one energy transfer from a source element to a receiver element, stored flat and
//! grouped by receiver after each refinement (CSR-like groups, see [`LinkSet`]).

use super::element::{Elements, Kind};
use rayon::prelude::*;
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
    /// radiosity there instead of the source's (the source's radiosity where the receiver
    /// sees it and its kernel is strong); none: the source's.
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
/// On a surface source: ends of open rays drawn in proportion to their samples' kernels,
/// where the transfer leaves from (the mean radiosity there, not the source's mean over
/// parts the receiver does not see or sees only at a grazing distance).
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
    /// The sort key of a link set: (receiver, source).
    #[inline]
    pub fn key(&self) -> u64 {
        ((self.recv as u64) << 32) | self.src as u64
    }

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
            // An undivided source reads its own radiosity wherever the draw points.
            if d.depth() == 0 || el.elems[l.src as usize].num_children == 0 {
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

    /// Sort the `kept` links by (receiver, source) and build the groups; `samples` holds the
    /// samples the links refer to (`per_link` each) and `open` their open surfaces' runs,
    /// compacted here to those of the links kept.
    pub fn from_links(
        kept: Kept,
        (samples, open): (Vec<Sample>, Vec<Sample>),
        per_link: u32,
    ) -> LinkSet {
        let Kept {
            mut links,
            mut late,
            ..
        } = kept;
        let out = compact(
            [&mut links, &mut late],
            (&samples, &open),
            per_link as usize,
        );
        // Given back before the merge, which needs room.
        drop((samples, open));
        // (receiver, source) orders the links completely: the order does not depend on the
        // sort or the thread count.
        late.par_sort_unstable_by_key(Link::key);
        merge_late(&mut links, late);
        // Held for the rest of the solve: no spare capacity (the memory budget counts it).
        links.shrink_to_fit();
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
            samples: out.0,
            per_link,
            open_members: out.1,
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

/// The links a refinement sweep keeps, in the order decided: `links` are those at or above
/// the running maximum of (receiver, source), hence in order (a sweep keeps most links of the
/// sorted set before it in their order), and `late` the others, which
/// [`LinkSet::from_links`] sorts and merges in.
#[derive(Debug, Default)]
pub struct Kept {
    links: Vec<Link>,
    late: Vec<Link>,
    max: u64,
}

impl Kept {
    /// Starts from `links`, in (receiver, source) order; links pushed after them go where
    /// they had room.
    pub fn sorted(links: Vec<Link>) -> Kept {
        debug_assert!(links.windows(2).all(|w| w[0].key() < w[1].key()));
        Kept {
            max: links.last().map_or(0, Link::key),
            links,
            late: Vec::new(),
        }
    }

    /// Adds `l` after the links kept so far.
    pub fn push(&mut self, l: Link) {
        let k = l.key();
        if k >= self.max {
            self.max = k;
            self.links.push(l);
        } else {
            self.late.push(l);
        }
    }

    /// Number of links kept out of order (merged in by [`LinkSet::from_links`]).
    pub fn late(&self) -> usize {
        self.late.len()
    }

    /// Number of links kept.
    pub fn len(&self) -> usize {
        self.links.len() + self.late.len()
    }

    /// True when no link is kept.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// Copies the samples and open runs that the links of `parts` refer to into new arrays, in
/// the links' order, and points the links at the copies. Blocks of links copy in parallel,
/// each where the counts of the blocks before it put it.
fn compact(
    parts: [&mut [Link]; 2],
    (samples, open): (&[Sample], &[Sample]),
    per_link: usize,
) -> (Vec<Sample>, Vec<Sample>) {
    const BLOCK: usize = 1 << 14;
    let run = |l: &Link| match l.open_members {
        NO_SAMPLES => 0,
        s => 1 + open[s as usize].0 as usize,
    };
    let has = |l: &Link| if l.samples == NO_SAMPLES { 0 } else { per_link };
    let mut blocks: Vec<&mut [Link]> = parts
        .into_iter()
        .flat_map(|p| p.chunks_mut(BLOCK))
        .collect();
    let counts: Vec<(usize, usize)> = blocks
        .par_iter()
        .map(|c| c.iter().fold((0, 0), |(a, b), l| (a + has(l), b + run(l))))
        .collect();
    let total = counts.iter().fold((0, 0), |(a, b), &(x, y)| (a + x, b + y));
    // Zeroed by the allocator, so the pages are first touched by the parallel copies.
    let mut out = vec![(0u32, 0f32); total.0];
    let mut out_open = vec![(0u32, 0f32); total.1];
    let (mut rest, mut rest_open) = (&mut out[..], &mut out_open[..]);
    let mut dest = Vec::with_capacity(counts.len());
    let mut at = (0, 0);
    for &(x, y) in &counts {
        let (p, r) = std::mem::take(&mut rest).split_at_mut(x);
        let (q, r_open) = std::mem::take(&mut rest_open).split_at_mut(y);
        (rest, rest_open) = (r, r_open);
        dest.push((p, q, at));
        at = (at.0 + x, at.1 + y);
    }
    blocks
        .par_iter_mut()
        .zip(dest)
        .for_each(|(c, (p, q, (s_at, o_at)))| {
            let (mut i, mut j) = (0, 0);
            for l in c.iter_mut() {
                if l.samples != NO_SAMPLES {
                    let s = l.samples as usize;
                    p[i..i + per_link].copy_from_slice(&samples[s..s + per_link]);
                    l.samples = (s_at + i) as u32;
                    i += per_link;
                }
                let n = run(l);
                if n > 0 {
                    let s = l.open_members as usize;
                    q[j..j + n].copy_from_slice(&open[s..s + n]);
                    l.open_members = (o_at + j) as u32;
                    j += n;
                }
            }
        });
    (out, out_open)
}

/// Merges `late`, sorted, into `links`, sorted, from the back. `late` gives its memory back
/// as it is consumed, so the merge holds at most `late`'s size beyond the merged links, and
/// less the more of the late links lie at the top.
fn merge_late(links: &mut Vec<Link>, mut late: Vec<Link>) {
    /// Links consumed from `late` between two returns of its memory.
    const RELEASE: usize = 1 << 16;
    let n = links.len() + late.len();
    links.reserve_exact(late.len());
    let (mut i, mut j) = (links.len(), late.len());
    let mut released = j;
    let base = links.as_mut_ptr();
    // Positions `i + j..n` hold the merged tail; `links[..i]` and `late[..j]` remain.
    while j > 0 {
        let k = i + j - 1;
        // SAFETY: `k < n ≤ capacity`. Positions below `i` hold the links not yet merged,
        // untouched; every write goes to `k ≥ i`, past them. The loop ends with every position
        // in `i..n` written once and those below `i` original, so all `n` are initialised.
        unsafe {
            let v = if i > 0 && (*base.add(i - 1)).key() > late[j - 1].key() {
                i -= 1;
                *base.add(i)
            } else {
                j -= 1;
                late[j]
            };
            base.add(k).write(v);
        }
        if released - j >= RELEASE {
            late.truncate(j);
            late.shrink_to_fit();
            released = j;
        }
    }
    // SAFETY: see above.
    unsafe { links.set_len(n) };
}

#[cfg(test)]
mod tests {
    use super::{merge_late, Deposit, Kept, Link, LinkSet, NO_SAMPLES};
    use hirad_core::rng::SplitMix64;

    #[test]
    fn link_sets_order_links_by_receiver_then_source_and_keep_their_samples() {
        let mut rng = SplitMix64::new(7);
        let mut r = |n: u64| (rng.next_u64() % n) as u32;
        // A sorted set with new links after it, some of them late, and a shuffled one; every
        // link that carries samples or open surfaces points at its own, tagged by its key.
        // More links than one block of the parallel compaction.
        let mut sorted: Vec<Link> = (0..40_000).map(|_| Link::new(r(5000), r(5000))).collect();
        sorted.sort_by_key(|l| (l.recv, l.src));
        sorted.dedup_by_key(|l| (l.recv, l.src));
        let mut extra: Vec<Link> = (0..300).map(|_| Link::new(5000 + r(50), r(5000))).collect();
        extra.extend((0..200).map(|_| Link::new(r(5000), 5000 + r(50))));
        extra.sort_by_key(|l| (l.recv, l.src));
        extra.dedup_by_key(|l| (l.recv, l.src));
        let mut shuffled: Vec<Link> = sorted.iter().chain(&extra).copied().collect();
        for i in (1..shuffled.len()).rev() {
            shuffled.swap(i, r(i as u64 + 1) as usize);
        }
        let per_link = 3;
        let tag = |l: &Link| ((l.recv * 10_007 + l.src) % (1 << 24)) as f32;
        for links in [
            sorted.iter().chain(&extra).copied().collect::<Vec<_>>(),
            sorted.clone(),
            shuffled,
        ] {
            let (mut samples, mut open) = (vec![(7, 0.0)], vec![(0, 0.0)]);
            let mut kept = Kept::default();
            for (i, &l) in links.iter().enumerate() {
                let mut l = l;
                if i % 3 == 0 {
                    l.samples = samples.len() as u32;
                    samples.extend((0..per_link).map(|m| (m, tag(&l))));
                }
                if i % 5 == 0 {
                    l.open_members = open.len() as u32;
                    open.push((2, 0.0));
                    open.extend([(1, tag(&l)), (2, tag(&l))]);
                }
                kept.push(l);
            }
            let set = LinkSet::from_links(kept, (samples, open), per_link);
            let mut want: Vec<_> = links.iter().map(|l| (l.recv, l.src)).collect();
            want.sort();
            let got: Vec<_> = set.links.iter().map(|l| (l.recv, l.src)).collect();
            assert_eq!(got, want);
            let with_samples = links.iter().step_by(3).count();
            assert_eq!(set.samples.len(), with_samples * per_link as usize);
            for l in &set.links {
                if l.samples != NO_SAMPLES {
                    let s = l.samples as usize;
                    assert_eq!(
                        set.samples[s..s + 3],
                        [(0, tag(l)), (1, tag(l)), (2, tag(l))]
                    );
                }
                let o = set.open_members(l);
                assert!(o.is_empty() || o == [(1, tag(l)), (2, tag(l))]);
            }
            let with_open = set.links.iter().filter(|l| l.open_members != NO_SAMPLES);
            assert_eq!(with_open.count(), links.iter().step_by(5).count());
            assert_eq!(set.groups.len(), {
                let mut r: Vec<_> = want.iter().map(|w| w.0).collect();
                r.dedup();
                r.len()
            });
        }
    }

    #[test]
    fn merging_late_links_from_the_back_keeps_every_link_in_order() {
        // More late links than one release step, interleaved with the ordered ones.
        let keys = |v: &[Link]| v.iter().map(Link::key).collect::<Vec<_>>();
        let ordered: Vec<Link> = (0..200_000).map(|i| Link::new(2 * i, 0)).collect();
        let mut late: Vec<Link> = (0..150_000).map(|i| Link::new(2 * i + 1, 1)).collect();
        late.extend((0..10).map(|i| Link::new(1_000_000 + i, 0)));
        let mut links = ordered.clone();
        merge_late(&mut links, late.clone());
        let mut want: Vec<Link> = ordered.into_iter().chain(late).collect();
        want.sort_by_key(Link::key);
        assert_eq!(keys(&links), keys(&want));
        // Nothing late, and nothing in order.
        let mut none = want.clone();
        merge_late(&mut none, Vec::new());
        assert_eq!(keys(&none), keys(&want));
        let mut empty = Vec::new();
        merge_late(&mut empty, want.clone());
        assert_eq!(keys(&empty), keys(&want));
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
