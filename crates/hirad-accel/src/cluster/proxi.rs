//! Strategy `proxi`: bottom-up proximity clustering after size filtering (Sillion & Drettakis
//! 1995). Surfaces are filtered by size into levels; from the finest level up, the objects of
//! a level (its surfaces and the clusters the finer levels passed up) are hashed into a grid
//! of cells of about the level's size, and each seed greedily grows a group from its
//! neighbours while the group stays dense (floored volume ratio ≤ 1) and fits the next level;
//! groups become clusters, lone objects move one level up, until one object remains. The
//! algorithm and its cost are given in full on [`build`]; [`build_subset`] re-clusters part of
//! a scene (`okdt-p`). Generic helpers live elsewhere: Morton codes and the cell hasher in
//! `hirad_core`, the nearest-neighbour k-d tree in `cluster::knn`.

use super::knn::PointTree;
use super::{BuildNode, BuildTree, ClusterConfig, Prims};
use glam::Vec3;
use hirad_core::geom::Aabb;
use hirad_core::hash::U64Map;
use hirad_core::morton::morton;
use rayon::prelude::*;
use std::collections::BTreeMap;

/// Bits per axis of the global quantisation grid (Morton codes use 63 bits).
const GRID_BITS: u32 = 21;
/// Finest level used for size filtering.
const MAX_LEVEL: i32 = 64;
/// `φ`: minimum edge of a box, as a fraction of its size, in the floored volume.
const VOLUME_FLOOR: f64 = 0.25;
/// Largest volume ratio `ρ` of a group (see [`build`]).
const MAX_RATIO: f64 = 1.0;
/// Candidates taken from the seed's own cell.
const OWN_CELL_CANDIDATES: usize = 32;
/// Candidates taken from each neighbouring cell.
const CELL_CANDIDATES: usize = 8;
/// Candidates kept (nearest centres) for the greedy growth.
const MAX_CANDIDATES: usize = 16;
/// Levels with at least this many objects sort in parallel.
const PAR_SORT_MIN: usize = 16_384;

/// Build the PROXI tree over every surface.
///
/// # Algorithm
/// Let `s_ref` be the largest surface size (`size` = longest bounding-box edge). Surfaces are
/// filtered by size into levels: level `k` holds the objects of size in
/// `[s_ref/2^(k+1), s_ref/2^k)` (zero-size surfaces and surfaces finer than the finest level go
/// to the finest level, which is the level of the smallest positive size, at most 64). Levels
/// are processed finest first; level `k` has the nominal object size `c_k = s_ref/2^k`, and
/// levels `k < 0` (`c_k > s_ref`) continue until a single object remains, the root.
///
/// At level `k` the objects (surfaces of that size plus what the finer levels passed up) are
/// hashed into a regular grid whose cells have edge `C_k`, the smallest power-of-two multiple of
/// the global quantisation unit (scene size / 2^21) that is `≥ c_k` (so `c_k ≤ C_k < 2 c_k`
/// while the grid is finer than the scene). Objects are visited in Morton order of their box
/// centres; every object not yet grouped at this level seeds a group:
/// 1. candidates: ungrouped objects in the seed's cell and its 26 neighbours (at most 32 from the
///    seed's cell and 8 from each neighbour, in Morton order), of which the 16 whose centres are
///    nearest to the seed's are kept;
/// 2. greedy growth: repeatedly add the candidate that minimises the *volume ratio*
///    `ρ_k(G) = V_k(box(G)) / Σ_{o ∈ G} V_k(box(o))` of the grown group, among the candidates
///    that keep `ρ_k ≤ 1` (the group's box is no bigger than its members' floored volumes put
///    together) and `size(box(G)) ≤ 2 c_k` (the group fits the next coarser level), until the
///    group has `max_children` members or no candidate qualifies (ties go to the nearer
///    candidate);
/// 3. a group of two or more objects becomes a cluster (its surfaces attached directly, its
///    clusters as children, box = union of the members' boxes, i.e. tight), which is an object
///    of level `min(k − 1, level(size))`; a seed left alone is passed to level `k − 1` as is.
///
/// `V_k(b)` is the *floored box volume* `Π_axis max(e_axis, φ c_k)` with `e` the box's edge
/// lengths and `φ = 1/4`: flat boxes (triangles) and points (coincident or zero-area surfaces)
/// get a volume instead of zero, so `ρ_k` is always finite and positive. A mesh's neighbouring
/// triangles have overlapping boxes and group with `ρ_k < 1`; objects much smaller than `c_k`
/// count as cubes of edge `φ c_k`, so two of them group once their distance is about
/// `2 φ c_k = c_k / 2`: isolated objects rise through the levels until the grid is coarse enough
/// for their neighbours. Once `φ c_k` exceeds the subset's size, every box counts as the same
/// cube, `ρ_k = 1/|G|`, so the coarse levels always merge and the loop ends.
///
/// Every cluster has at most `max_children` members in total (child clusters plus surfaces;
/// `max_children < 2` is treated as 2). The run is sequential over the grouping itself, which
/// makes it deterministic; sorting and per-object setup run in parallel with keys that are
/// unique, so the tree does not depend on the thread count.
///
/// A surface passed up alone for the second time skips the levels at which it cannot be
/// grouped at all: a group holding it and any other object contains both box centres, so its
/// size is at least the maximum-norm distance `D` from the surface's box centre to the nearest
/// other surface's box centre, while groups of level `j` have size `≤ 2 c_j`; the surface goes
/// straight to the finest level `j ≤ k − 1` with `2 c_j ≥ D` (`D` from a k-d tree over the
/// surface centres, built only when some surface needs it). Up to f32 rounding at the level
/// boundary, the skipped levels could not have grouped the surface anyway; the skip only
/// frees the candidate slots it would have taken there.
///
/// # Cost
/// Each level sorts its objects (O(m log m)) and visits every object once, with a bounded
/// number of candidates (hash lookups of 27 cells, at most 16 candidates, at most
/// `max_children` greedy rounds) and a path-compressed "next ungrouped" skip list. Every group
/// of ≥ 2 objects removes at least one object, and singletons move one level up (or skip as
/// above), so the total is O(n log n) expected when objects group within a bounded number of
/// levels of their own size, as surfaces of meshes do. Scenes of isolated surfaces much
/// smaller than their spacing cost O(n) per level between the two scales.
pub fn build(prims: &Prims, cfg: &ClusterConfig) -> BuildTree {
    let all: Vec<u32> = (0..prims.len() as u32).collect();
    let mut t = BuildTree::default();
    t.root = build_subset(prims, &all, cfg, &mut t);
    t
}

/// Cluster the surfaces `subset` bottom-up, adding the nodes to `out`; returns the id of the
/// subtree's root, whose box is tight around the subset. Used by `okdt-p` to re-cluster
/// over-full clusters locally.
///
/// The root is always the last node pushed to `out`, and every node pushed by this call
/// belongs to the subtree. An empty subset gives one empty node; a single surface gives one
/// node holding it.
pub fn build_subset(
    prims: &Prims,
    subset: &[u32],
    cfg: &ClusterConfig,
    out: &mut BuildTree,
) -> u32 {
    Builder::new(prims, subset, cfg, out).run()
}

/// What an object of a level stands for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Member {
    Surface(u32),
    Node(u32),
}

/// An object of a level: a surface or a cluster built at a finer level.
#[derive(Clone, Copy, Debug)]
struct Object {
    bbox: Aabb,
    /// Box centre.
    center: Vec3,
    /// Quantised centre on the global grid.
    q: [u32; 3],
    /// Morton code of `q`.
    code: u64,
    member: Member,
}

/// The global quantisation grid over the subset's bounding box.
#[derive(Clone, Copy, Debug)]
struct Grid {
    origin: Vec3,
    /// Edge of one quantisation cell.
    unit: f64,
}

impl Grid {
    fn quantize(&self, p: Vec3) -> [u32; 3] {
        let max = ((1u32 << GRID_BITS) - 1) as f64;
        let f = |x: f32, o: f32| -> u32 {
            let v = ((x as f64 - o as f64) / self.unit).floor();
            // NaN casts to 0; the clamp keeps out-of-range values on the grid.
            v.clamp(0.0, max) as u32
        };
        [
            f(p.x, self.origin.x),
            f(p.y, self.origin.y),
            f(p.z, self.origin.z),
        ]
    }
}

type CellMap = U64Map<(u32, u32)>;

/// Floored box volume `V_k(b)` (see [`build`]); `floor_len` is `φ · c_k`.
#[inline]
fn floored_volume(b: &Aabb, floor_len: f64) -> f64 {
    let e = b.extent();
    (e.x as f64).max(floor_len) * (e.y as f64).max(floor_len) * (e.z as f64).max(floor_len)
}

/// "Next ungrouped position" skip list with path halving.
struct NextFree(Vec<u32>);

impl NextFree {
    fn new(n: usize) -> Self {
        NextFree((0..=n as u32).collect())
    }

    /// Smallest ungrouped position `≥ i` (`n` when none).
    #[inline]
    fn find(&mut self, mut i: u32) -> u32 {
        let v = &mut self.0;
        while v[i as usize] != i {
            let next = v[v[i as usize] as usize];
            v[i as usize] = next;
            i = next;
        }
        i
    }

    /// Mark position `i` grouped.
    #[inline]
    fn take(&mut self, i: u32) {
        self.0[i as usize] = i + 1;
    }
}

struct Builder<'a> {
    prims: &'a Prims,
    subset: &'a [u32],
    max_children: usize,
    out: &'a mut BuildTree,
    objects: Vec<Object>,
    grid: Grid,
    /// Reference size `s_ref` (level 0 object size bound).
    s_ref: f64,
    /// Finest level.
    k_fine: i32,
    /// Per surface object: it was passed up alone at an earlier level.
    lonely: Vec<bool>,
    /// Nearest-neighbour search over the surface centres, built when first needed.
    centres: Option<PointTree>,
}

impl<'a> Builder<'a> {
    fn new(
        prims: &'a Prims,
        subset: &'a [u32],
        cfg: &ClusterConfig,
        out: &'a mut BuildTree,
    ) -> Self {
        let mut bounds = Aabb::EMPTY;
        let mut s_max = 0.0f64;
        let mut s_min = f64::INFINITY;
        for &s in subset {
            let b = &prims.bbox[s as usize];
            bounds.grow_box(b);
            let size = b.size() as f64;
            if size > 0.0 && size.is_finite() {
                s_max = s_max.max(size);
                s_min = s_min.min(size);
            }
        }
        let extent = bounds.size() as f64;
        let extent = if extent > 0.0 && extent.is_finite() {
            extent
        } else {
            1.0
        };
        let origin = if bounds.is_empty() || !bounds.min.is_finite() {
            Vec3::ZERO
        } else {
            bounds.min
        };
        let grid = Grid {
            origin,
            unit: extent / (1u64 << GRID_BITS) as f64,
        };
        let (s_ref, k_fine) = if s_max > 0.0 {
            let k = (s_max / s_min).log2().floor();
            (s_max, (k as i32).clamp(0, MAX_LEVEL))
        } else {
            (extent, 0)
        };
        Builder {
            prims,
            subset,
            max_children: cfg.max_children.max(2),
            out,
            objects: Vec::new(),
            grid,
            s_ref,
            k_fine,
            lonely: vec![false; subset.len()],
            centres: None,
        }
    }

    /// Level of an object of size `size`: `floor(log2(s_ref / size))` clamped to the levels.
    fn level_of(&self, size: f32) -> i32 {
        let size = size as f64;
        if !size.is_finite() || size <= 0.0 {
            return self.k_fine;
        }
        let k = (self.s_ref / size).log2().floor();
        if k.is_nan() {
            return self.k_fine;
        }
        (k.clamp(0.0, self.k_fine as f64)) as i32
    }

    /// First (finest) level at which a surface whose box centre is at Chebyshev distance `d`
    /// from every other surface's box centre can be grouped: a group holding it and another
    /// object contains both centres, so its size is at least `d`, and a group at level `j` has
    /// size at most `2 c_j`. Returns `i32::MAX` (no constraint) when `d` is 0 or not finite.
    fn jump_level(&self, d: f32) -> i32 {
        let d = d as f64;
        if !d.is_finite() || d <= 0.0 {
            return i32::MAX;
        }
        let j = (2.0 * self.s_ref / d).log2().floor();
        if j.is_nan() {
            i32::MAX
        } else {
            j.clamp(-1e6, 1e6) as i32
        }
    }

    fn make_object(&self, bbox: Aabb, member: Member) -> Object {
        let center = bbox.center();
        let q = self.grid.quantize(center);
        Object {
            bbox,
            center,
            q,
            code: morton(q),
            member,
        }
    }

    fn run(mut self) -> u32 {
        match self.subset.len() {
            0 => {
                return self.out.push(BuildNode::default());
            }
            1 => {
                let s = self.subset[0];
                return self.out.push(BuildNode {
                    bbox: self.prims.bbox[s as usize],
                    children: vec![],
                    surfaces: vec![s],
                });
            }
            _ => {}
        }
        // Surface objects, then size filtering into the levels 0..=k_fine.
        let this = &self;
        let surf: Vec<Object> = self
            .subset
            .par_iter()
            .map(|&s| this.make_object(this.prims.bbox[s as usize], Member::Surface(s)))
            .collect();
        let levels: Vec<i32> = surf
            .par_iter()
            .map(|o| this.level_of(o.bbox.size()))
            .collect();
        self.objects = surf;
        // Objects waiting for their level, finest level processed first.
        let mut pending: BTreeMap<i32, Vec<u32>> = BTreeMap::new();
        for (i, &k) in levels.iter().enumerate() {
            pending.entry(k).or_default().push(i as u32);
        }
        let mut alive = self.subset.len();
        while alive > 1 {
            let Some((k, objs)) = pending.pop_last() else {
                break;
            };
            // Safety net: the cells cover the whole subset long before this; if grouping
            // ever stalled, join what is left in Morton order.
            if k < -(GRID_BITS as i32) - 64 - 2 * MAX_LEVEL {
                let mut rest = objs;
                rest.extend(pending.into_values().flatten());
                return self.join_rest(rest);
            }
            alive -= self.group_level(k, objs, &mut pending);
        }
        let root = pending
            .values()
            .flatten()
            .next()
            .copied()
            .unwrap_or_default();
        match self.objects[root as usize].member {
            Member::Node(id) => id,
            Member::Surface(s) => self.out.push(BuildNode {
                bbox: self.prims.bbox[s as usize],
                children: vec![],
                surfaces: vec![s],
            }),
        }
    }

    /// Group the objects `objs` of level `k`; the resulting objects go to `pending`.
    /// Returns how many objects disappeared.
    fn group_level(
        &mut self,
        k: i32,
        mut objs: Vec<u32>,
        pending: &mut BTreeMap<i32, Vec<u32>>,
    ) -> usize {
        let c_k = self.s_ref * (-(k as f64)).exp2();
        let size_limit = (2.0 * c_k) as f32;
        let floor_len = VOLUME_FLOOR * c_k;
        let m = {
            let r = (c_k / self.grid.unit).log2().ceil();
            if r.is_nan() {
                0
            } else {
                r.clamp(0.0, GRID_BITS as f64) as u32
            }
        };
        let shift = 3 * m;
        let cells_per_axis: i64 = 1i64 << (GRID_BITS - m);

        let objects = &self.objects;
        let key = |&i: &u32| (objects[i as usize].code, i);
        if objs.len() >= PAR_SORT_MIN {
            objs.par_sort_unstable_by_key(key);
        } else {
            objs.sort_unstable_by_key(key);
        }
        let n = objs.len();
        // Cells are contiguous runs of the Morton order.
        let mut cells = CellMap::with_capacity_and_hasher(n / 2 + 1, Default::default());
        let mut start = 0usize;
        while start < n {
            let ck = objects[objs[start] as usize].code >> shift;
            let mut end = start + 1;
            while end < n && objects[objs[end] as usize].code >> shift == ck {
                end += 1;
            }
            cells.insert(ck, (start as u32, end as u32));
            start = end;
        }

        let mut free = NextFree::new(n);
        let mut cand: Vec<(f32, u32)> = Vec::with_capacity(27 * CELL_CANDIDATES);
        let mut used = Vec::with_capacity(MAX_CANDIDATES);
        let mut members: Vec<u32> = Vec::with_capacity(self.max_children);
        let mut results: Vec<(u32, i32)> = Vec::with_capacity(n);
        let mut new_nodes: Vec<BuildNode> = Vec::new();
        let mut merged = 0usize;
        // New clusters become objects `first_new_obj + index` once the level is done.
        let first_new_obj = objects.len() as u32;

        for p in 0..n as u32 {
            if free.find(p) != p {
                continue;
            }
            free.take(p);
            let seed = &objects[objs[p as usize] as usize];
            let cell = [
                (seed.q[0] >> m) as i64,
                (seed.q[1] >> m) as i64,
                (seed.q[2] >> m) as i64,
            ];
            cand.clear();
            // Own cell first, then the 26 neighbours in a fixed order.
            for (ni, d) in NEIGHBOURS.iter().enumerate() {
                let c = [cell[0] + d[0], cell[1] + d[1], cell[2] + d[2]];
                if c.iter().any(|&x| x < 0 || x >= cells_per_axis) {
                    continue;
                }
                let ck = morton([c[0] as u32, c[1] as u32, c[2] as u32]);
                let Some(&(s, e)) = cells.get(&ck) else {
                    continue;
                };
                let cap = if ni == 0 {
                    OWN_CELL_CANDIDATES
                } else {
                    CELL_CANDIDATES
                };
                let mut taken = 0;
                let mut j = free.find(s);
                while j < e && taken < cap {
                    let o = &objects[objs[j as usize] as usize];
                    cand.push((o.center.distance_squared(seed.center), j));
                    taken += 1;
                    j = free.find(j + 1);
                }
            }
            let mut group_box = seed.bbox;
            if !cand.is_empty() {
                let order =
                    |a: &(f32, u32), b: &(f32, u32)| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1));
                if cand.len() > MAX_CANDIDATES {
                    cand.select_nth_unstable_by(MAX_CANDIDATES - 1, order);
                    cand.truncate(MAX_CANDIDATES);
                }
                cand.sort_unstable_by(order);
                // Greedy growth minimising the floored volume ratio.
                used.clear();
                used.resize(cand.len(), false);
                members.clear();
                members.push(p);
                let mut sum_v = floored_volume(&seed.bbox, floor_len);
                while members.len() < self.max_children {
                    let mut best: Option<(f64, usize, Aabb, f64)> = None;
                    for (ci, &(_, j)) in cand.iter().enumerate() {
                        if used[ci] {
                            continue;
                        }
                        let o = &objects[objs[j as usize] as usize];
                        let u = group_box.union(&o.bbox);
                        // Written so that NaN sizes are rejected too.
                        let fits = u.size() <= size_limit;
                        if !fits {
                            continue;
                        }
                        let v_o = floored_volume(&o.bbox, floor_len);
                        let ratio = floored_volume(&u, floor_len) / (sum_v + v_o);
                        let dense = ratio <= MAX_RATIO;
                        if !dense {
                            continue;
                        }
                        if best.is_none_or(|b| ratio < b.0) {
                            best = Some((ratio, ci, u, v_o));
                        }
                    }
                    let Some((_, ci, u, v_o)) = best else {
                        break;
                    };
                    used[ci] = true;
                    let j = cand[ci].1;
                    free.take(j);
                    members.push(j);
                    group_box = u;
                    sum_v += v_o;
                }
            } else {
                members.clear();
                members.push(p);
            }
            if members.len() == 1 {
                results.push((objs[p as usize], k - 1));
                continue;
            }
            merged += members.len() - 1;
            let mut node = BuildNode {
                bbox: group_box,
                children: Vec::new(),
                surfaces: Vec::new(),
            };
            for &j in &members {
                match objects[objs[j as usize] as usize].member {
                    Member::Surface(s) => node.surfaces.push(s),
                    Member::Node(id) => node.children.push(id),
                }
            }
            let level = (k - 1).min(self.level_of(group_box.size()));
            results.push((first_new_obj + new_nodes.len() as u32, level));
            new_nodes.push(node);
        }

        // A surface passed up alone a second time jumps to the first level at which it can
        // group at all (see `jump_level`).
        let num_surf = self.subset.len() as u32;
        let again: Vec<usize> = results
            .iter()
            .enumerate()
            .filter(|(_, &(o, level))| {
                o < num_surf && level == k - 1 && {
                    let was = self.lonely[o as usize];
                    self.lonely[o as usize] = true;
                    was
                }
            })
            .map(|(i, _)| i)
            .collect();
        if !again.is_empty() {
            let objects = &self.objects;
            let tree = self.centres.get_or_insert_with(|| {
                PointTree::new(
                    objects[..num_surf as usize]
                        .iter()
                        .map(|o| o.center)
                        .collect(),
                )
            });
            let tree = &*tree;
            let dist: Vec<f32> = again
                .par_iter()
                .map(|&i| {
                    let o = results[i].0;
                    tree.nearest(objects[o as usize].center, o)
                })
                .collect();
            for (&i, d) in again.iter().zip(dist) {
                results[i].1 = results[i].1.min(self.jump_level(d));
            }
        }

        // Push the new clusters in creation order and hand everything to its next level.
        for node in new_nodes {
            let bbox = node.bbox;
            let id = self.out.push(node);
            let obj = self.make_object(bbox, Member::Node(id));
            self.objects.push(obj);
        }
        for (o, level) in results {
            pending.entry(level).or_default().push(o);
        }
        merged
    }

    /// Fallback: join `rest` in groups of `max_children` (Morton order) until one remains.
    fn join_rest(&mut self, mut rest: Vec<u32>) -> u32 {
        loop {
            let objects = &self.objects;
            rest.sort_unstable_by_key(|&i| (objects[i as usize].code, i));
            if rest.len() == 1 {
                break;
            }
            let mut next = Vec::with_capacity(rest.len() / self.max_children + 1);
            for chunk in rest.chunks(self.max_children) {
                if chunk.len() == 1 {
                    next.push(chunk[0]);
                    continue;
                }
                let mut node = BuildNode::default();
                for &o in chunk {
                    let obj = &self.objects[o as usize];
                    node.bbox.grow_box(&obj.bbox);
                    match obj.member {
                        Member::Surface(s) => node.surfaces.push(s),
                        Member::Node(id) => node.children.push(id),
                    }
                }
                let bbox = node.bbox;
                let id = self.out.push(node);
                let obj = self.make_object(bbox, Member::Node(id));
                self.objects.push(obj);
                next.push(self.objects.len() as u32 - 1);
            }
            rest = next;
        }
        match self.objects[rest[0] as usize].member {
            Member::Node(id) => id,
            Member::Surface(s) => self.out.push(BuildNode {
                bbox: self.prims.bbox[s as usize],
                children: vec![],
                surfaces: vec![s],
            }),
        }
    }
}

/// The seed's cell first, then its 26 neighbours.
const NEIGHBOURS: [[i64; 3]; 27] = {
    let mut a = [[0i64; 3]; 27];
    let mut i = 1;
    let mut dz = -1;
    while dz <= 1 {
        let mut dy = -1;
        while dy <= 1 {
            let mut dx = -1;
            while dx <= 1 {
                if !(dx == 0 && dy == 0 && dz == 0) {
                    a[i] = [dx, dy, dz];
                    i += 1;
                }
                dx += 1;
            }
            dy += 1;
        }
        dz += 1;
    }
    a
};

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn neighbours_are_the_27_offsets() {
        let mut v: Vec<[i64; 3]> = NEIGHBOURS.to_vec();
        assert_eq!(v[0], [0, 0, 0]);
        v.sort();
        v.dedup();
        assert_eq!(v.len(), 27);
    }

    #[test]
    fn floored_volume_of_flat_and_point_boxes() {
        let flat = Aabb::new(Vec3::ZERO, Vec3::new(1.0, 2.0, 0.0));
        assert!((floored_volume(&flat, 0.25) - 1.0 * 2.0 * 0.25).abs() < 1e-12);
        let point = Aabb::new(Vec3::ONE, Vec3::ONE);
        assert!((floored_volume(&point, 0.01) - 1e-6).abs() < 1e-18);
        let cube = Aabb::new(Vec3::ZERO, Vec3::splat(2.0));
        assert!((floored_volume(&cube, 0.5) - 8.0).abs() < 1e-12);
        assert!((floored_volume(&cube, 3.0) - 27.0).abs() < 1e-12);
    }

    #[test]
    fn next_free_skips_taken() {
        let mut f = NextFree::new(5);
        f.take(1);
        f.take(2);
        assert_eq!(f.find(0), 0);
        assert_eq!(f.find(1), 3);
        f.take(3);
        f.take(4);
        assert_eq!(f.find(1), 5);
    }
}
