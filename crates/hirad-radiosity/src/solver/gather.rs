//! Gather: each receiver sums `K · B_src` over its links, in parallel per receiver.
//!
//! Cluster receivers keep one [`Entry`] per link, handed to their surfaces in push-pull.
//! A subdivided surface receiver's light is shaped by where its links' shadow rays saw their
//! sources, pooled over all its links ([`Deposit`] holds each link's sample points): a part
//! gets the light in proportion to its open area times its light density, each link's light
//! (capped at the receiver's mean) going to its open points and weighed against its share of
//! all points ([`Cell`]). So the many weak links no oracle refines do not light what
//! furniture hides, a dark link does not outvote a bright one, and the pooled ratio keeps the
//! noise of a few points per link out of the walls. It also sums, per surface receiver, the
//! light of the links whose rays disagreed (`K·B`, `ρ·K·B` for the `error` oracle): above ε
//! the receiver straddles a shadow's outline, and refinement splits it for those links
//! (`refine`).

use super::push_pull::open_area;
use super::{Solver, STRADDLES};
use crate::element::{Element, Elements, Kind};
use crate::link::Deposit;
use crate::oracle;
use crate::overlap::Covers;
use glam::{DVec3, Vec3};
use rayon::prelude::*;

/// A receiver's light is shaped only as many levels down as leave this many of its links'
/// samples per part on average; a part's open share is shrunk towards its parent's as if
/// this many more samples had the parent's share.
const SAMPLES_PER_PART: f64 = 4.0;

/// Receivers gathered at a time (see [`Solver::gather`]).
const GATHER_CHUNK: usize = 1 << 12;

/// Gather output of one receiver.
#[derive(Clone, Debug, Default)]
struct Gathered {
    recv: u32,
    h: DVec3,
    /// Irradiance (channel sum) from cluster sources (surface receivers).
    h_cluster: f64,
    /// Sum of the link kernels (surface receivers).
    k_sum: f64,
    /// Surface receivers: the light of the links whose rays disagreed (see the module doc).
    mixed: f64,
    /// Cluster receivers: one entry per link.
    entries: Vec<Entry>,
    /// Surface receivers: transfers that land where their rays saw the source.
    deposits: Vec<(Deposit, DVec3)>,
    /// Cluster receivers: irradiance of the surfaces whose samples saw the source, from links
    /// whose rays disagreed ([`Link::open_members`]).
    ///
    /// [`Link::open_members`]: crate::link::Link::open_members
    open: Vec<(u32, DVec3)>,
    /// Cluster receivers: the same for the clusters below them that such surfaces stand for,
    /// handed out as entries of those clusters.
    strata: Vec<(u32, Entry)>,
}

/// What a cluster received through one link, handed to its surfaces in push-pull.
#[derive(Clone, Copy, Debug)]
pub(super) struct Entry {
    /// Unit direction from the cluster's centroid to the source's.
    pub(super) d: Vec3,
    /// Source centroid and [`Element::facing_normal`] (for [`facing_weight`](crate::cluster_model::facing_weight)).
    ///
    /// [`Element::facing_normal`]: crate::element::Element::facing_normal
    pub(super) sc: Vec3,
    pub(super) sn: Vec3,
    /// Irradiance `K·B_src`.
    pub(super) h: DVec3,
    /// Kernel.
    pub(super) k: f32,
}

impl Entry {
    /// What cluster `recv` receives from `src`: irradiance `h`, kernel `k`.
    fn new(recv: &Element, src: &Element, h: DVec3, k: f32) -> Entry {
        Entry {
            d: (src.centroid - recv.centroid).normalize_or_zero(),
            sc: src.centroid,
            sn: src.facing_normal(),
            h,
            k,
        }
    }
}

impl Solver<'_> {
    /// Gather over every link, per receiver, a chunk of receivers at a time (their hand-outs
    /// and deposits go straight into the flat arrays, not held twice).
    pub(super) fn gather(&mut self) {
        for h in self.el.h.iter_mut() {
            *h = DVec3::ZERO;
        }
        for v in self.h_cluster.iter_mut() {
            *v = 0.0;
        }
        for v in self.k_sum.iter_mut() {
            *v = 0.0;
        }
        // A cluster receiver's entries carry its links' geometry, which only refinement changes
        // (it empties them): a later gather on the same links updates their irradiance in
        // place. Entries lie in the order of the groups.
        let mut entries = std::mem::take(&mut self.entries);
        let update = !entries.is_empty();
        let mut slots: Vec<&mut [Entry]> = Vec::new();
        if update {
            let mut rest = &mut entries[..];
            for &(r, _, _) in &self.set.groups {
                let (a, b) = match self.cl_ranges.get(r as usize) {
                    Some(&(a, b)) if self.el.elems[r as usize].kind == Kind::Cluster => (a, b),
                    _ => (0, 0),
                };
                let (slot, after) = std::mem::take(&mut rest).split_at_mut((b - a) as usize);
                slots.push(slot);
                rest = after;
            }
        } else {
            for r in self.cl_ranges.iter_mut() {
                *r = (0, 0);
            }
        }
        let mut built: Vec<Entry> = Vec::new();
        let mut strata: Vec<(u32, Entry)> = Vec::new();
        self.deposits.clear();
        self.dep_ranges.clear();
        self.dep_ranges.resize(self.el.len(), (0, 0));
        self.straddle.resize(self.el.len(), 0);
        for f in self.straddle.iter_mut() {
            *f &= !STRADDLES;
        }
        let n_groups = self.set.groups.len();
        let covers = &self.covers;
        let ok = self.cfg.refine;
        // Exact capacities (what the memory budget projects): an entry per link into a
        // cluster, and for a subdivided surface the parts its light is shaped over.
        let (mut n_entries, mut n_deposits) = (0usize, 0usize);
        for &(r, a, b) in &self.set.groups {
            let re = &self.el.elems[r as usize];
            if re.kind == Kind::Cluster {
                n_entries += (b - a) as usize;
            } else if re.num_children > 0 {
                let samples: usize = self.set.links[a as usize..b as usize]
                    .iter()
                    .map(|l| l.deposit.points())
                    .sum();
                n_deposits += 1 << (2 * shape_depth(samples as u64));
            }
        }
        if !update {
            built.reserve_exact(n_entries);
        }
        self.deposits.reserve_exact(n_deposits);
        let mut slot_chunks = slots.chunks_mut(GATHER_CHUNK);
        for start in (0..n_groups).step_by(GATHER_CHUNK) {
            let el = &self.el;
            let set = &self.set;
            let links = &set.links;
            let groups = &set.groups[start..(start + GATHER_CHUNK).min(n_groups)];
            let mut no_slots: Vec<&mut [Entry]> = Vec::new();
            let chunk_slots = match slot_chunks.next() {
                Some(c) => c,
                None => {
                    no_slots.resize_with(groups.len(), Default::default);
                    &mut no_slots[..]
                }
            };
            let res: Vec<Gathered> = groups
                .par_iter()
                .zip(chunk_slots.par_iter_mut())
                .map_init(
                    Vec::new,
                    |lights: &mut Vec<(Deposit, f64)>, (&(r, a, b), slot)| {
                        // The deposit and light of each link into a subdivided surface receiver.
                        lights.clear();
                        let re = &el.elems[r as usize];
                        let rho = re.rho.as_dvec3();
                        let mut cells: Cells = [Cell::default(); 64];
                        let mut g = Gathered {
                            recv: r,
                            ..Default::default()
                        };
                        let mut slot = slot.iter_mut();
                        for l in &links[a as usize..b as usize] {
                            let contrib = set.gather(l, el);
                            let open = set.open_members(l);
                            if !open.is_empty() {
                                let se = &el.elems[l.src as usize];
                                for &(m, f) in open {
                                    let h = contrib * f as f64;
                                    let me = &el.elems[m as usize];
                                    if me.kind == Kind::Cluster {
                                        g.strata.push((m, Entry::new(me, se, h, 0.0)));
                                    } else {
                                        g.open.push((m, h));
                                    }
                                }
                            } else if re.kind == Kind::Cluster && update {
                                slot.next().expect("an entry per link").h = contrib;
                            } else if re.kind == Kind::Cluster {
                                let se = &el.elems[l.src as usize];
                                g.entries.push(Entry::new(re, se, contrib, l.k));
                            } else {
                                if re.num_children > 0 {
                                    lights.push((l.deposit, contrib.element_sum()));
                                }
                                if l.deposit.mixed() {
                                    g.mixed += oracle::value(ok, 1.0, contrib, rho);
                                }
                                g.h += contrib;
                                g.k_sum += l.k as f64;
                                if el.elems[l.src as usize].kind == Kind::Cluster {
                                    g.h_cluster += contrib.element_sum();
                                }
                            }
                        }
                        if re.kind == Kind::Surface && re.num_children > 0 {
                            add_links(&mut cells, lights);
                            let h = std::mem::take(&mut g.h);
                            g.h = shape(el, covers, r, &cells, h, &mut g.deposits);
                        }
                        g
                    },
                )
                .collect();
            for g in res {
                let id = g.recv as usize;
                // Open surfaces of a cluster add to their own gather (zeroed above), which
                // comes in this chunk or another.
                for &(m, h) in &g.open {
                    self.el.h[m as usize] += h;
                }
                strata.extend_from_slice(&g.strata);
                if !g.deposits.is_empty() {
                    let s = self.deposits.len() as u32;
                    self.deposits.extend_from_slice(&g.deposits);
                    self.dep_ranges[id] = (s, self.deposits.len() as u32);
                }
                if self.el.elems[id].kind == Kind::Cluster {
                    if !update {
                        let s = built.len() as u32;
                        built.extend_from_slice(&g.entries);
                        self.cl_ranges[id] = (s, built.len() as u32);
                    }
                } else {
                    self.el.h[id] += g.h;
                    self.h_cluster[id] = g.h_cluster;
                    self.k_sum[id] = g.k_sum;
                    if g.mixed > self.eps {
                        self.straddle[id] |= STRADDLES;
                    }
                }
            }
        }
        drop(slots);
        self.entries = if update { entries } else { built };
        // Strata by cluster, each cluster's in the order of the groups.
        strata.sort_by_key(|s| s.0);
        for r in self.st_ranges.iter_mut() {
            *r = (0, 0);
        }
        self.strata.clear();
        self.strata.reserve_exact(strata.len());
        for run in strata.chunk_by(|a, b| a.0 == b.0) {
            let s = self.strata.len() as u32;
            self.strata.extend(run.iter().map(|r| r.1));
            self.st_ranges[run[0].0 as usize] = (s, self.strata.len() as u32);
        }
        self.note_peak();
    }
}

/// Spreads irradiance `h` gathered by surface receiver `id` over its parts in proportion to
/// their open area times their light density (`cells`, 3 levels down: see [`Cell`]), each
/// part's density shrunk towards its parent's where it has few samples; appends one deposit
/// per part and returns what stays even (all of it when there are too few samples).
fn shape(
    el: &Elements,
    covers: &Covers,
    id: u32,
    cells: &Cells,
    h: DVec3,
    out: &mut Vec<(Deposit, DVec3)>,
) -> DVec3 {
    let t = cells.iter().fold(Cell::default(), |a, c| a.plus(c));
    let depth = shape_depth(t.points as u64);
    if depth == 0 || t.open <= 0.0 || h == DVec3::ZERO {
        return h;
    }
    // Light per point of the lit links: what a dark link's point weighs.
    let dark_weight = t.all / (t.points - t.dark).max(1) as f64;
    let cells = cells.map(|c| Cell {
        all: c.all + c.dark as f64 * dark_weight,
        ..c
    });
    let mut sh = Shaper {
        el,
        covers,
        cells: &cells,
        depth,
        prior: SAMPLES_PER_PART * dark_weight,
        h,
        out,
        even: DVec3::ZERO,
    };
    let all = t.all + t.dark as f64 * dark_weight;
    sh.part(id, 0, 0, 1.0, t.open / all);
    sh.even
}

/// Levels below a receiver that its links' `samples` shape ([`SAMPLES_PER_PART`] per part on
/// average, at most [`Deposit::LEVELS`]); its light goes to at most `4^depth` parts, and
/// `4^depth ≤ samples / 4`.
pub(super) fn shape_depth(samples: u64) -> u32 {
    let mut depth = 0;
    while depth < Deposit::LEVELS
        && samples as f64 >= SAMPLES_PER_PART * (4u64 << (2 * depth)) as f64
    {
        depth += 1;
    }
    depth
}

/// One cell 3 levels below a surface receiver ([`Deposit::LEVELS`]): its links' sample points
/// there, weighted by light (`K·B`, channel sum, capped: [`add_links`]). A lit link adds its
/// light per point to `all` at each point and its light per open point to `open` at each open
/// point, so that over a part `open / all` estimates its light density over the receiver's
/// mean, and a dark link (the back of a mirror lighting the wall behind it) weighs what it
/// carries. A link that carries nothing (its rays all blocked, or a dark source) counts its
/// points in `dark`; they weigh in `all` as much as an average lit point ([`shape`]): where
/// its rays were blocked, light of the kind the receiver gets is blocked.
#[derive(Clone, Copy, Debug, Default)]
struct Cell {
    /// Sample points, of lit and dark links.
    points: u32,
    /// Sample points of links that carry no light.
    dark: u32,
    all: f64,
    open: f64,
}

impl Cell {
    fn plus(self, o: &Cell) -> Cell {
        Cell {
            points: self.points + o.points,
            dark: self.dark + o.dark,
            all: self.all + o.all,
            open: self.open + o.open,
        }
    }
}

/// Adds the sample points of a receiver's links (deposit, light), each link's light capped at
/// the mean of its lit links: a few bright links' points would otherwise decide the shape
/// alone (1 to 4 points each).
fn add_links(cells: &mut Cells, links: &[(Deposit, f64)]) {
    let n_lit = links.iter().filter(|x| x.1 > 0.0).count();
    let mean = links.iter().map(|x| x.1).sum::<f64>() / n_lit.max(1) as f64;
    for &(d, light) in links {
        add_points(cells, d, light.min(mean));
    }
}

/// Adds the sample points of a link that carries `light` (see [`Cell`]).
fn add_points(cells: &mut Cells, d: Deposit, light: f64) {
    let n = d.points();
    if n == 0 {
        return;
    }
    let per_point = light / n as f64;
    let per_open = light / d.open_points().max(1) as f64;
    for i in 0..n {
        let c = &mut cells[d.path(i) as usize];
        c.points += 1;
        if light > 0.0 {
            c.all += per_point;
            if d.open(i) {
                c.open += per_open;
            }
        } else {
            c.dark += 1;
        }
    }
}

type Cells = [Cell; 64];

/// The state of [`shape`]'s descent.
struct Shaper<'a> {
    el: &'a Elements,
    covers: &'a Covers,
    cells: &'a Cells,
    depth: u32,
    /// The weight of [`SAMPLES_PER_PART`] average points.
    prior: f64,
    h: DVec3,
    out: &'a mut Vec<(Deposit, DVec3)>,
    even: DVec3,
}

impl Shaper<'_> {
    /// Part `node` at `level` below the receiver (its path `prefix`) gets `frac` of the
    /// power; `p_par` is its light density.
    fn part(&mut self, node: u32, level: u32, prefix: u32, frac: f64, p_par: f64) {
        let e = &self.el.elems[node as usize];
        let mut w = [0.0f64; 4];
        let mut p = [0.0f64; 4];
        if level < self.depth && e.num_children == 4 {
            let mask = (1u32 << (2 * (level + 1))) - 1;
            for j in 0..4u32 {
                let want = prefix | j << (2 * level);
                let c = self
                    .cells
                    .iter()
                    .enumerate()
                    .filter(|(c, _)| *c as u32 & mask == want)
                    .fold(Cell::default(), |a, (_, c)| a.plus(c));
                p[j as usize] = (c.open + self.prior * p_par) / (c.all + self.prior);
                w[j as usize] = open_area(self.el, self.covers, e.first_child + j) * p[j as usize];
            }
        }
        let total: f64 = w.iter().sum();
        if total <= 0.0 {
            if level == 0 {
                self.even += self.h * frac;
            } else {
                self.out
                    .push((Deposit::single(prefix, level), self.h * frac));
            }
            return;
        }
        for j in 0..4u32 {
            let f = frac * w[j as usize] / total;
            self.part(
                e.first_child + j,
                level + 1,
                prefix | j << (2 * level),
                f,
                p[j as usize],
            );
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use hirad_accel::cluster::{ClusterConfig, ClusterTree, Strategy};
    use hirad_scene::{Material, RawScene, Scene, SceneOptions};

    /// A link's points, one in each child of a once-subdivided receiver, open in children 0
    /// and 2 and blocked in 1 and 3.
    fn half_open() -> Deposit {
        Deposit::with_mask(&[0, 1, 2, 3], 0b0101)
    }

    /// Share of the light that [`shape`] gives children 1 and 3 of a once-subdivided triangle
    /// receiver from `links` (deposit, light, how many such links).
    fn share_in_1_and_3(links: &[(Deposit, f64, usize)]) -> f64 {
        let raw = RawScene {
            name: "wall".into(),
            positions: vec![Vec3::ZERO, Vec3::X * 2.0, Vec3::Y * 2.0],
            triangles: vec![[0, 1, 2]],
            tri_material: vec![0],
            tri_object: vec![0],
            objects: vec!["wall".into()],
            materials: vec![Material::diffuse("grey", Vec3::splat(0.5))],
            ..Default::default()
        };
        let scene = Scene::from_raw(raw, &SceneOptions::default()).unwrap();
        let tree = ClusterTree::build(&scene, Strategy::Proxi, &ClusterConfig::default());
        let mut el = Elements::build(&scene, &tree, false);
        let covers = Covers::build(&scene, &tree, false);
        let id = el.first_root;
        el.subdivide(id);
        let mut cells: Cells = [Cell::default(); 64];
        let all: Vec<(Deposit, f64)> = links
            .iter()
            .flat_map(|&(d, light, n)| std::iter::repeat_n((d, light), n))
            .collect();
        add_links(&mut cells, &all);
        let mut out = Vec::new();
        let even = shape(&el, &covers, id, &cells, DVec3::ONE, &mut out);
        assert_eq!(even, DVec3::ZERO, "the light is shaped");
        let total: f64 = out.iter().map(|(_, h)| h.x).sum();
        assert!(
            (total - 1.0).abs() < 1e-12,
            "shaping keeps the light: {total}"
        );
        out.iter()
            .filter(|(d, _)| d.path(0) & 1 == 1)
            .map(|(_, h)| h.x)
            .sum()
    }

    #[test]
    fn a_dark_link_does_not_draw_a_bright_links_light_where_its_rays_were_blocked() {
        // Dark links (1% of the bright ones' light; the back of a mirror) see their source
        // only from children 1 and 3, where the bright links' rays were blocked:
        // light-weighted, those children get the dark links' light, 1% (2% with the bright
        // links capped at the mean), plus the prior's pull towards the mean. Counting rays
        // alone, they would get half.
        let dark = Deposit::with_mask(&[0, 1, 2, 3], 0b1010);
        let s = share_in_1_and_3(&[(half_open(), 1.0, 16), (dark, 0.01, 16)]);
        assert!(s > 0.01 && s < 0.1, "dark links: {s}");
        // Links as bright as the others light children 1 and 3 as much as those light 0
        // and 2.
        let s = share_in_1_and_3(&[(half_open(), 1.0, 16), (dark, 1.0, 16)]);
        assert!((s - 0.5).abs() < 1e-9, "equally bright links: {s}");
    }

    #[test]
    fn a_link_that_carries_nothing_counts_its_blocked_points() {
        // With only the half-open links, children 1 and 3 get the prior's pull towards the
        // mean; links that carry nothing, their rays blocked there, weigh as average lit
        // points and leave them less.
        let alone = share_in_1_and_3(&[(half_open(), 1.0, 16)]);
        let blocked = Deposit::with_mask(&[1, 3, 1, 3], 0);
        let with = share_in_1_and_3(&[(half_open(), 1.0, 16), (blocked, 0.0, 16)]);
        assert!(alone > 0.0 && alone < 0.15, "alone: {alone}");
        assert!(
            with < 0.6 * alone,
            "with blocked links: {with}, alone {alone}"
        );
    }
}
