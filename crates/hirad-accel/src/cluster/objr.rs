//! Strategy `objr` (object reconstruction, issue 23): a hierarchy that follows the objects of a
//! polygon soup (paper §6). Vertices closer than the weld tolerance ([`WELD_REL`] of the scene
//! diagonal, at most [`WELD_EDGE_FRACTION`] of the shortest incident edge) are welded; an
//! *object* is a connected component of the triangles over shared welded edges whose two
//! triangles have the same material; a *patch* is a part of an object joined over edges of
//! two triangles whose normals turn by at most [`CREASE_DEG`]. Clusters (`spec/clustering.md`):
//! - above the objects, PROXI's bottom-up proximity clusters, built by [`proxi::build_subset`]
//!   over one box per object (an object of a single triangle is attached as that surface);
//! - except where objects interleave: an object whose box holds more of other objects' leaf
//!   clusters than of its own (surface areas of the leaf boxes, the others' clipped to its box)
//!   does not stand as one cluster; its child clusters take its place, recursively (the
//!   branches of a tree among the others' leaves), and PROXI groups those;
//! - an object is one cluster, split top-down while it holds more than [`LEAF_SURFACES`]
//!   surfaces into [`WIDTH`] children by halving the largest part: a part spanning several
//!   patches between patches along the principal axis of their centroids, a part within one
//!   patch at the median of its triangles along their (area-weighted) principal axis. Boxes
//!   are tight; objects are built in parallel and appended in order (thread-count independent).
//!
//! Without vertex data ([`Prims::triangles`] empty) every surface is its own object.

use super::{proxi, BuildNode, BuildTree, ClusterConfig, Prims};
use glam::{DVec3, Vec3};
use hirad_core::geom::Aabb;
use hirad_scene::export::ColoredMesh;
use rayon::prelude::*;

/// Weld tolerance as a fraction of the scene's bounding-box diagonal.
pub const WELD_REL: f32 = 1e-5;
/// Cap of the weld tolerance as a fraction of the shortest edge at either vertex.
pub const WELD_EDGE_FRACTION: f32 = 0.1;
/// Largest angle (degrees) between the normals of two triangles of one patch across an edge.
pub const CREASE_DEG: f32 = 60.0;
/// Clusters inside an object with at most this many surfaces are leaves.
pub const LEAF_SURFACES: usize = 4;
/// Children of a cluster inside an object (successive halvings).
pub const WIDTH: usize = 4;

/// The objects and patches `objr` recovers from a soup.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Reconstruction {
    /// Welded vertex id of every entry of [`Prims::positions`] (dense, by first occurrence).
    pub vertex: Vec<u32>,
    /// Number of welded vertices among those the surfaces use.
    pub num_vertices: usize,
    /// Object id per surface, numbered by the object's first surface.
    pub object: Vec<u32>,
    /// Number of objects.
    pub num_objects: usize,
    /// Patch id per surface (patches never span objects), numbered by first surface.
    pub patch: Vec<u32>,
    /// Number of patches.
    pub num_patches: usize,
}

/// Union-find with path halving; roots are the smallest index of their set.
struct Dsu(Vec<u32>);

impl Dsu {
    fn new(n: usize) -> Self {
        Dsu((0..n as u32).collect())
    }

    fn find(&mut self, mut i: u32) -> u32 {
        while self.0[i as usize] != i {
            let g = self.0[self.0[i as usize] as usize];
            self.0[i as usize] = g;
            i = g;
        }
        i
    }

    fn union(&mut self, a: u32, b: u32) {
        let (a, b) = (self.find(a), self.find(b));
        if a != b {
            let (lo, hi) = (a.min(b), a.max(b));
            self.0[hi as usize] = lo;
        }
    }

    /// Dense labels in order of first appearance; returns (labels, count).
    fn labels(mut self) -> (Vec<u32>, usize) {
        let n = self.0.len();
        let mut label = vec![u32::MAX; n];
        let mut out = vec![0u32; n];
        let mut next = 0u32;
        for i in 0..n as u32 {
            let r = self.find(i) as usize;
            if label[r] == u32::MAX {
                label[r] = next;
                next += 1;
            }
            out[i as usize] = label[r];
        }
        (out, next as usize)
    }
}

/// Weld the vertices used by the surfaces; returns the welded id of every position (unused
/// positions keep ids of their own) and the number of welded vertices in use.
fn weld(prims: &Prims) -> (Vec<u32>, usize) {
    let pos = &prims.positions;
    let nv = pos.len();
    // Shortest positive edge at each used vertex; unused vertices stay at infinity.
    let mut emin = vec![f32::INFINITY; nv];
    let mut used = vec![false; nv];
    let mut bounds = Aabb::EMPTY;
    for t in &prims.triangles {
        for k in 0..3 {
            let (a, b) = (t[k] as usize, t[(k + 1) % 3] as usize);
            let l = pos[a].distance(pos[b]);
            if l > 0.0 {
                emin[a] = emin[a].min(l);
                emin[b] = emin[b].min(l);
            }
            if !used[a] {
                used[a] = true;
                bounds.grow(pos[a]);
            }
        }
    }
    let diag = if bounds.is_empty() {
        0.0
    } else {
        bounds.extent().length()
    };
    let tau = WELD_REL * diag;
    // Cells of edge 2τ: a point within τ (maximum norm) of p lies in p's cell or in the
    // neighbour on the side of the cell p is nearer to, per axis (8 cells).
    let cell = if tau > 0.0 && tau.is_finite() {
        2.0 * tau as f64
    } else {
        1.0
    };
    let origin = bounds.min;
    let q = |p: Vec3| -> [i64; 3] {
        let f = |x: f32, o: f32| (((x - o) as f64 / cell).floor()).clamp(0.0, 2e6) as i64;
        [f(p.x, origin.x), f(p.y, origin.y), f(p.z, origin.z)]
    };
    let key =
        |c: [i64; 3]| -> u64 { (c[0] as u64) | ((c[1] as u64) << 21) | ((c[2] as u64) << 42) };
    // Used vertices sorted by (cell, exact position, id): exact duplicates are adjacent.
    let mut order: Vec<(u64, [u32; 3], u32)> = (0..nv as u32)
        .into_par_iter()
        .filter(|&v| used[v as usize])
        .map(|v| {
            let p = pos[v as usize];
            (key(q(p)), p.to_array().map(f32::to_bits), v)
        })
        .collect();
    order.par_sort_unstable();
    let mut dsu = Dsu::new(nv);
    // Unique positions: (cell key, representative vertex, smallest edge of the group).
    let mut uniq: Vec<(u64, u32, f32)> = Vec::new();
    for w in 0..order.len() {
        let (k, bits, v) = order[w];
        match uniq.last_mut() {
            Some(u) if w > 0 && order[w - 1].0 == k && order[w - 1].1 == bits => {
                dsu.union(u.1, v);
                u.2 = u.2.min(emin[v as usize]);
            }
            _ => uniq.push((k, v, emin[v as usize])),
        }
    }
    if tau > 0.0 && tau.is_finite() {
        let keys: Vec<u64> = uniq.iter().map(|u| u.0).collect();
        let pairs: Vec<(u32, u32)> = (0..uniq.len())
            .into_par_iter()
            .flat_map_iter(|i| {
                let (_, v, e) = uniq[i];
                let p = pos[v as usize];
                let c = q(p);
                let mut side = [0i64; 3];
                for a in 0..3 {
                    let frac = (p[a] - origin[a]) as f64 / cell - c[a] as f64;
                    side[a] = if frac >= 0.5 { 1 } else { -1 };
                }
                let mut found = Vec::new();
                for m in 0..8 {
                    let mut nc = c;
                    for (a, s) in side.iter().enumerate() {
                        if m & (1 << a) != 0 {
                            nc[a] += s;
                        }
                    }
                    if nc.iter().any(|&x| x < 0) {
                        continue;
                    }
                    let k = key(nc);
                    let start = keys.partition_point(|&x| x < k);
                    for (j, u) in uniq.iter().enumerate().skip(start) {
                        if u.0 != k {
                            break;
                        }
                        if j <= i {
                            continue;
                        }
                        let tol = tau.min(WELD_EDGE_FRACTION * e.min(u.2));
                        if p.distance(pos[u.1 as usize]) <= tol {
                            found.push((v, u.1));
                        }
                    }
                }
                found
            })
            .collect();
        for (a, b) in pairs {
            dsu.union(a, b);
        }
    }
    let (mut labels, _) = dsu.labels();
    // Dense ids over the used vertices only, by first occurrence in position order.
    let mut remap = vec![u32::MAX; nv];
    let mut count = 0u32;
    for v in 0..nv {
        if used[v] {
            let l = labels[v] as usize;
            if remap[l] == u32::MAX {
                remap[l] = count;
                count += 1;
            }
        }
    }
    let mut extra = count;
    for v in 0..nv {
        labels[v] = if used[v] {
            remap[labels[v] as usize]
        } else {
            extra += 1;
            extra - 1
        };
    }
    (labels, count as usize)
}

/// Recover the objects and patches of a soup (see the module docs).
pub fn reconstruct(prims: &Prims) -> Reconstruction {
    let n = prims.len();
    if prims.triangles.len() != n || n == 0 {
        let ids: Vec<u32> = (0..n as u32).collect();
        return Reconstruction {
            vertex: Vec::new(),
            num_vertices: 0,
            object: ids.clone(),
            num_objects: n,
            patch: ids,
            num_patches: n,
        };
    }
    let (vertex, num_vertices) = weld(prims);
    let pos = &prims.positions;
    let mat = |t: usize| prims.material.get(t).copied().unwrap_or(0);
    let normal: Vec<Vec3> = prims
        .triangles
        .par_iter()
        .map(|t| {
            let [a, b, c] = t.map(|v| pos[v as usize]);
            (b - a).cross(c - a).normalize_or_zero()
        })
        .collect();
    // Welded edges: (min id, max id) key, triangle, and whether it runs min → max.
    let mut edges: Vec<(u64, u32, bool)> = prims
        .triangles
        .par_iter()
        .enumerate()
        .flat_map_iter(|(t, tri)| {
            let w = tri.map(|v| vertex[v as usize]);
            (0..3).filter_map(move |k| {
                let (a, b) = (w[k], w[(k + 1) % 3]);
                (a != b).then(|| {
                    let key = ((a.min(b) as u64) << 32) | a.max(b) as u64;
                    (key, t as u32, a < b)
                })
            })
        })
        .collect();
    edges.par_sort_unstable();
    let cos_crease = CREASE_DEG.to_radians().cos();
    let mut objects = Dsu::new(n);
    let mut patches = Dsu::new(n);
    let mut start = 0;
    while start < edges.len() {
        let mut end = start + 1;
        while end < edges.len() && edges[end].0 == edges[start].0 {
            end += 1;
        }
        let fan = &edges[start..end];
        for (i, &(_, ti, di)) in fan.iter().enumerate() {
            // Objects: join the first triangle of the fan with the same material.
            if let Some(&(_, tj, _)) = fan[..i]
                .iter()
                .find(|e| mat(e.1 as usize) == mat(ti as usize))
            {
                objects.union(ti, tj);
            }
            // Patches are manifold pieces: an edge of three or more triangles is a junction
            // (a wall meeting a floor) where the sheets on either side part.
            if fan.len() != 2 {
                continue;
            }
            for &(_, tj, dj) in &fan[..i] {
                if mat(tj as usize) != mat(ti as usize) {
                    continue;
                }
                // Consistent winding traverses the edge in opposite directions.
                let sign = if di != dj { 1.0 } else { -1.0 };
                let c = sign * normal[ti as usize].dot(normal[tj as usize]);
                if c >= cos_crease {
                    patches.union(ti, tj);
                }
            }
        }
        start = end;
    }
    let (object, num_objects) = objects.labels();
    let (patch, num_patches) = patches.labels();
    Reconstruction {
        vertex,
        num_vertices,
        object,
        num_objects,
        patch,
        num_patches,
    }
}

/// A distinct colour of object `k` (hues by the golden ratio, linear RGB in (0, 1)).
pub fn object_color(k: u32) -> Vec3 {
    let h = (k as f64 * 0.618_033_988_749_895).fract() * 6.0;
    let (s, v) = (0.65, if k.is_multiple_of(2) { 0.85 } else { 0.6 });
    let f = h.fract();
    let (p, q, t) = (v * (1.0 - s), v * (1.0 - s * f), v * (1.0 - s * (1.0 - f)));
    let (r, g, b) = match h as u32 {
        0 => (v, t, p),
        1 => (q, v, p),
        2 => (p, v, t),
        3 => (p, q, v),
        4 => (t, p, v),
        _ => (v, p, q),
    };
    // The sRGB transfer inverted, so that the picture shows these hues.
    let lin = |c: f64| c.powf(2.2) as f32;
    Vec3::new(lin(r), lin(g), lin(b))
}

/// The surfaces coloured by the object `rec` found them in ([`object_color`]), every
/// triangle with vertices of its own (`hirad clusters --objects`).
pub fn object_mesh(prims: &Prims, rec: &Reconstruction) -> ColoredMesh {
    let mut m = ColoredMesh {
        positions: Vec::with_capacity(3 * prims.triangles.len()),
        triangles: Vec::with_capacity(prims.triangles.len()),
        colors: Vec::with_capacity(3 * prims.triangles.len()),
    };
    for (t, tri) in prims.triangles.iter().enumerate() {
        let base = m.positions.len() as u32;
        let c = object_color(rec.object[t]);
        for &v in tri {
            m.positions.push(prims.positions[v as usize]);
            m.colors.push(c);
        }
        m.triangles.push([base, base + 1, base + 2]);
    }
    m
}

/// One surface inside an object's top-down build.
#[derive(Clone, Copy, Debug)]
struct Item {
    id: u32,
    patch: u32,
    c: Vec3,
    w: f64,
    bbox: Aabb,
}

/// Principal axis of weighted points (power iteration on the covariance); falls back to the
/// longest axis of their box when the spread is zero.
fn principal_axis(pts: impl Iterator<Item = (Vec3, f64)> + Clone) -> DVec3 {
    let (mut sw, mut mean) = (0.0f64, DVec3::ZERO);
    let (mut lo, mut hi) = (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY));
    for (p, w) in pts.clone() {
        let p = p.as_dvec3();
        sw += w;
        mean += p * w;
        lo = lo.min(p);
        hi = hi.max(p);
    }
    let ext = hi - lo;
    let fallback = if ext.x >= ext.y && ext.x >= ext.z {
        DVec3::X
    } else if ext.y >= ext.z {
        DVec3::Y
    } else {
        DVec3::Z
    };
    if sw.is_nan() || sw <= 0.0 {
        return fallback;
    }
    mean /= sw;
    let mut m = [[0.0f64; 3]; 3];
    for (p, w) in pts {
        let d = p.as_dvec3() - mean;
        for (r, row) in m.iter_mut().enumerate() {
            for (c, x) in row.iter_mut().enumerate() {
                *x += w * d[r] * d[c];
            }
        }
    }
    let mul = |v: DVec3| {
        DVec3::new(
            m[0][0] * v.x + m[0][1] * v.y + m[0][2] * v.z,
            m[1][0] * v.x + m[1][1] * v.y + m[1][2] * v.z,
            m[2][0] * v.x + m[2][1] * v.y + m[2][2] * v.z,
        )
    };
    let mut v = fallback;
    for _ in 0..32 {
        let next = mul(v);
        let len = next.length();
        if len.is_nan() || len <= 1e-300 || !len.is_finite() {
            return fallback;
        }
        v = next / len;
    }
    v
}

fn leaf_box(items: &[Item]) -> Aabb {
    let mut b = Aabb::EMPTY;
    for it in items {
        b.grow_box(&it.bbox);
    }
    b
}

/// Build the subtree of an object's items into `out` (children before parents); returns the
/// root id.
fn build_object(
    items: &mut [Item],
    depth: usize,
    max_depth: usize,
    out: &mut Vec<BuildNode>,
) -> u32 {
    let bbox = leaf_box(items);
    if items.len() <= LEAF_SURFACES || depth >= max_depth {
        out.push(BuildNode {
            bbox,
            children: Vec::new(),
            surfaces: items.iter().map(|it| it.id).collect(),
        });
        return (out.len() - 1) as u32;
    }
    // Halve the items, then the largest part while it is above the leaf size, up to `WIDTH`
    // parts: one child cluster per part.
    let mut parts: Vec<(usize, usize)> = vec![(0, items.len())];
    while parts.len() < WIDTH {
        let mut k = 0;
        for (i, &(s, e)) in parts.iter().enumerate() {
            if e - s > parts[k].1 - parts[k].0 {
                k = i;
            }
        }
        let (s, e) = parts[k];
        if e - s <= LEAF_SURFACES {
            break;
        }
        let mid = s + split(&mut items[s..e]);
        parts.splice(k..=k, [(s, mid), (mid, e)]);
    }
    let children = parts
        .into_iter()
        .map(|(s, e)| build_object(&mut items[s..e], depth + 1, max_depth, out))
        .collect();
    out.push(BuildNode {
        bbox,
        children,
        surfaces: Vec::new(),
    });
    (out.len() - 1) as u32
}

/// Reorder `items` into two non-empty groups (see the module docs); returns the size of the
/// first.
fn split(items: &mut [Item]) -> usize {
    if items.iter().any(|it| it.patch != items[0].patch) {
        return split_patches(items);
    }
    let axis = principal_axis(items.iter().map(|it| (it.c, it.w)));
    let mid = items.len() / 2;
    let proj = |it: &Item| it.c.as_dvec3().dot(axis);
    items.select_nth_unstable_by(mid, |a, b| {
        proj(a).total_cmp(&proj(b)).then(a.id.cmp(&b.id))
    });
    mid
}

/// Reorder items spanning several patches into two groups of whole patches; returns the size
/// of the first. Patches are ordered along the principal axis of their centroids and cut where
/// half the triangles are reached; a patch holding half the triangles or more is cut off alone.
fn split_patches(items: &mut [Item]) -> usize {
    items.sort_unstable_by_key(|it| (it.patch, it.id));
    // (centroid, weight, start, end) per patch.
    let mut groups: Vec<(Vec3, f64, usize, usize)> = Vec::new();
    let mut s = 0;
    while s < items.len() {
        let mut e = s + 1;
        while e < items.len() && items[e].patch == items[s].patch {
            e += 1;
        }
        let (mut c, mut w) = (DVec3::ZERO, 0.0);
        for it in &items[s..e] {
            c += it.c.as_dvec3() * it.w;
            w += it.w;
        }
        let c = if w > 0.0 {
            (c / w).as_vec3()
        } else {
            leaf_box(&items[s..e]).center()
        };
        groups.push((c, w, s, e));
        s = e;
    }
    let n = items.len();
    let order: Vec<usize> = if let Some(big) = groups.iter().position(|g| 2 * (g.3 - g.2) >= n) {
        std::iter::once(big)
            .chain((0..groups.len()).filter(|&g| g != big))
            .collect()
    } else {
        let axis = principal_axis(groups.iter().map(|g| (g.0, g.1.max(1e-30))));
        let mut o: Vec<usize> = (0..groups.len()).collect();
        let proj = |g: usize| groups[g].0.as_dvec3().dot(axis);
        o.sort_by(|&a, &b| proj(a).total_cmp(&proj(b)).then(a.cmp(&b)));
        o
    };
    let mut cut = 0;
    let mut first = 0;
    for (k, &g) in order.iter().enumerate() {
        cut += groups[g].3 - groups[g].2;
        first = k + 1;
        if 2 * cut >= n {
            break;
        }
    }
    let first = first.min(groups.len() - 1).max(1);
    let mut reordered = Vec::with_capacity(n);
    let mut size = 0;
    for (k, &g) in order.iter().enumerate() {
        reordered.extend_from_slice(&items[groups[g].2..groups[g].3]);
        if k + 1 == first {
            size = reordered.len();
        }
    }
    items.copy_from_slice(&reordered);
    size
}

/// Build the tree (see the module docs).
pub fn build(prims: &Prims, cfg: &ClusterConfig) -> BuildTree {
    let rec = reconstruct(prims);
    let n = prims.len();
    // Surfaces grouped by object, in id order within each.
    let mut first = vec![0usize; rec.num_objects + 1];
    for &o in &rec.object {
        first[o as usize + 1] += 1;
    }
    for i in 0..rec.num_objects {
        first[i + 1] += first[i];
    }
    let mut fill = first.clone();
    let mut by_object = vec![0u32; n];
    for (s, &o) in rec.object.iter().enumerate() {
        by_object[fill[o as usize]] = s as u32;
        fill[o as usize] += 1;
    }
    let max_depth = cfg.max_depth.max(1);
    let subtrees: Vec<(Vec<BuildNode>, u32, Aabb, f32)> = (0..rec.num_objects)
        .into_par_iter()
        .map(|o| {
            let surf = &by_object[first[o]..first[o + 1]];
            let mut items: Vec<Item> = surf
                .iter()
                .map(|&s| Item {
                    id: s,
                    patch: rec.patch[s as usize],
                    c: prims.centroid[s as usize],
                    w: (prims.area[s as usize] as f64).max(0.0) + 1e-30,
                    bbox: prims.bbox[s as usize],
                })
                .collect();
            let area: f32 = surf.iter().map(|&s| prims.area[s as usize]).sum();
            if items.len() == 1 {
                return (Vec::new(), u32::MAX, items[0].bbox, area);
            }
            let mut out = Vec::new();
            let root = build_object(&mut items, 0, max_depth, &mut out);
            let bbox = out[root as usize].bbox;
            (out, root, bbox, area)
        })
        .collect();
    let mut t = BuildTree::default();
    let mut object_root = Vec::with_capacity(subtrees.len());
    let mut object_box = Vec::with_capacity(subtrees.len());
    let mut object_area = Vec::with_capacity(subtrees.len());
    for (nodes, root, bbox, area) in subtrees {
        let base = t.nodes.len() as u32;
        for mut node in nodes {
            for c in &mut node.children {
                *c += base;
            }
            t.nodes.push(node);
        }
        object_root.push(if root == u32::MAX {
            u32::MAX
        } else {
            root + base
        });
        object_box.push(bbox);
        object_area.push(area);
    }
    // An object whose box holds more of other objects' leaf clusters than of its own (it
    // interleaves with them) is replaced by its child clusters, and so on down, before the
    // upper hierarchy.
    let mut area_of = vec![0f32; t.nodes.len()];
    // Summed surface area of the leaf clusters' boxes below each cluster.
    let mut leaf_sa = vec![0f64; t.nodes.len()];
    for i in 0..t.nodes.len() {
        let n = &t.nodes[i];
        area_of[i] = n
            .surfaces
            .iter()
            .map(|&s| prims.area[s as usize])
            .sum::<f32>()
            + n.children.iter().map(|&c| area_of[c as usize]).sum::<f32>();
        leaf_sa[i] = if n.children.is_empty() {
            n.bbox.surface_area() as f64
        } else {
            n.children.iter().map(|&c| leaf_sa[c as usize]).sum()
        };
    }
    let (leaf_box, leaf_obj) = leaves_by_object(&t, &object_root, &object_box);
    let crowd = Crowd::new(&leaf_box, &leaf_obj);
    // Units: (object root or MAX, object, box, area).
    let units: Vec<(u32, usize, Aabb, f32)> = (0..rec.num_objects)
        .into_par_iter()
        .flat_map_iter(|o| {
            let mut out = Vec::new();
            if object_root[o] == u32::MAX {
                out.push((u32::MAX, o, object_box[o], object_area[o]));
                return out;
            }
            let mut stack = vec![object_root[o]];
            while let Some(u) = stack.pop() {
                let n = &t.nodes[u as usize];
                if !n.children.is_empty() && crowd.crowded(&n.bbox, o, leaf_sa[u as usize]) {
                    stack.extend(n.children.iter().rev().copied());
                } else {
                    out.push((u, o, n.bbox, area_of[u as usize]));
                }
            }
            out
        })
        .collect();
    let object_root: Vec<u32> = units.iter().map(|u| u.0).collect();
    let unit_object: Vec<usize> = units.iter().map(|u| u.1).collect();
    let obj_prims = box_prims(
        units.iter().map(|u| u.2).collect(),
        units.iter().map(|u| u.3).collect(),
    );
    // Upper hierarchy: PROXI over one box per object.
    let all: Vec<u32> = (0..units.len() as u32).collect();
    let mut upper = BuildTree::default();
    let upper_root = proxi::build_subset(&obj_prims, &all, cfg, &mut upper);
    let base = t.nodes.len() as u32;
    for node in upper.nodes {
        let mut mapped = BuildNode {
            bbox: node.bbox,
            children: node.children.iter().map(|&c| c + base).collect(),
            surfaces: Vec::new(),
        };
        for o in node.surfaces {
            match object_root[o as usize] {
                u32::MAX => mapped
                    .surfaces
                    .push(by_object[first[unit_object[o as usize]]]),
                r => mapped.children.push(r),
            }
        }
        t.nodes.push(mapped);
    }
    t.root = upper_root + base;
    // A lone object gives a chain root → object root; start at the object.
    let r = &t.nodes[t.root as usize];
    if r.surfaces.is_empty() && r.children.len() == 1 {
        t.root = r.children[0];
    }
    let mut sizes: Vec<usize> = (0..rec.num_objects)
        .map(|o| first[o + 1] - first[o])
        .collect();
    sizes.sort_unstable_by(|a, b| b.cmp(a));
    let lone = sizes.iter().filter(|&&x| x == 1).count();
    let top: Vec<String> = sizes.iter().take(8).map(|x| x.to_string()).collect();
    t.notes.push(format!(
        "objr: {} objects (surfaces of the largest: {}; {lone} of one surface), {} patches, {} welded vertices",
        rec.num_objects,
        top.join(", "),
        rec.num_patches,
        rec.num_vertices
    ));
    t
}

/// Builder inputs of boxes standing for surfaces of area `area` (centroids at the boxes'
/// centres, no vertex data).
fn box_prims(bbox: Vec<Aabb>, area: Vec<f32>) -> Prims {
    Prims {
        centroid: bbox.iter().map(|b| b.center()).collect(),
        object: vec![0; bbox.len()],
        bbox,
        area,
        positions: Vec::new(),
        triangles: Vec::new(),
        material: Vec::new(),
    }
}

/// The leaf clusters of every object (an object of one surface: its box), with their object.
fn leaves_by_object(
    t: &BuildTree,
    object_root: &[u32],
    object_box: &[Aabb],
) -> (Vec<Aabb>, Vec<usize>) {
    let (mut boxes, mut objs) = (Vec::new(), Vec::new());
    for (o, &r) in object_root.iter().enumerate() {
        if r == u32::MAX {
            boxes.push(object_box[o]);
            objs.push(o);
            continue;
        }
        let mut stack = vec![r];
        while let Some(n) = stack.pop() {
            let node = &t.nodes[n as usize];
            if node.children.is_empty() {
                boxes.push(node.bbox);
                objs.push(o);
            }
            stack.extend(node.children.iter().copied());
        }
    }
    (boxes, objs)
}

/// The leaf clusters of all objects in a [`super::sah`] tree, to measure how much of other
/// objects lies in a box.
struct Crowd<'a> {
    boxes: &'a [Aabb],
    object: &'a [usize],
    tree: BuildTree,
}

impl<'a> Crowd<'a> {
    fn new(boxes: &'a [Aabb], object: &'a [usize]) -> Self {
        let tree = if boxes.is_empty() {
            BuildTree::default()
        } else {
            let area = boxes.iter().map(|b| b.surface_area()).collect();
            super::sah::build(&box_prims(boxes.to_vec(), area), &ClusterConfig::default())
        };
        Crowd {
            boxes,
            object,
            tree,
        }
    }

    /// Whether the intersections of `b` with the leaf boxes of objects other than `o` have more
    /// surface area than `own` (the leaf boxes of what `b` bounds).
    fn crowded(&self, b: &Aabb, o: usize, own: f64) -> bool {
        if self.tree.nodes.is_empty() {
            return false;
        }
        let overlaps = |a: &Aabb, b: &Aabb| !a.intersection(b).is_empty();
        let mut sum = 0f64;
        let mut stack = vec![self.tree.root];
        while let Some(n) = stack.pop() {
            let node = &self.tree.nodes[n as usize];
            if !overlaps(&node.bbox, b) {
                continue;
            }
            stack.extend(node.children.iter().copied());
            for &j in &node.surfaces {
                let l = &self.boxes[j as usize];
                if self.object[j as usize] != o && overlaps(l, b) {
                    sum += b.intersection(l).surface_area() as f64;
                    if sum > own {
                        return true;
                    }
                }
            }
        }
        false
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn principal_axis_of_a_line() {
        let pts: Vec<(Vec3, f64)> = (0..10)
            .map(|i| (Vec3::new(1.0, 2.0, 3.0) * i as f32, 1.0))
            .collect();
        let a = principal_axis(pts.iter().copied());
        let e = DVec3::new(1.0, 2.0, 3.0).normalize();
        assert!((a.dot(e).abs() - 1.0).abs() < 1e-9, "{a}");
    }

    #[test]
    fn dsu_labels_by_first_index() {
        let mut d = Dsu::new(5);
        d.union(4, 1);
        d.union(3, 2);
        assert_eq!(d.labels(), (vec![0, 1, 2, 2, 1], 3));
    }

    #[test]
    fn split_soup_quads_weld_and_crease() {
        // Two unit squares folded along x = 1 by 90°, each triangle with its own vertices,
        // the second square nudged by 1e-7 (within the weld tolerance).
        let v = Vec3::new;
        let e = 1e-7;
        let tris = [
            [v(0., 0., 0.), v(1., 0., 0.), v(1., 1., 0.)],
            [v(0., 0., 0.), v(1., 1., 0.), v(0., 1., 0.)],
            [v(1. + e, 0., 0.), v(1., 0., 1.), v(1., 1., 1.)],
            [v(1., 0., 0.), v(1., 1., 1.), v(1., 1. + e, 0.)],
        ];
        let p = Prims::from_triangles(&tris);
        let r = reconstruct(&p);
        assert_eq!(r.num_vertices, 6);
        assert_eq!(r.num_objects, 1);
        assert_eq!(r.num_patches, 2);
        assert_eq!(r.patch, vec![0, 0, 1, 1]);
        // A different material on the second square makes two objects.
        let mut p2 = p.clone();
        p2.material = vec![0, 0, 1, 1];
        assert_eq!(reconstruct(&p2).num_objects, 2);
        // A T-junction: a wall standing on the shared edge of two coplanar floor squares
        // joins one object, but three patches (no patch continues across the junction).
        let t = [
            [v(-1., 0., 0.), v(0., 0., 0.), v(0., 1., 0.)],
            [v(0., 0., 0.), v(1., 0., 0.), v(0., 1., 0.)],
            [v(0., 1., 0.), v(0., 0., 0.), v(0., 0., 1.)],
        ];
        let r = reconstruct(&Prims::from_triangles(&t));
        assert_eq!((r.num_objects, r.num_patches), (1, 3));
    }

    fn cube(lo: Vec3, s: f32) -> Aabb {
        Aabb::new(lo, lo + Vec3::splat(s))
    }

    #[test]
    fn a_box_is_crowded_by_other_objects_leaves_only() {
        // A 10 × 1 × 1 box of an object whose own leaf boxes sum to 40 in surface area; the
        // other object's leaves: unit cubes (area 6 each).
        let big = Aabb::new(Vec3::ZERO, Vec3::new(10.0, 1.0, 1.0));
        let inside: Vec<Aabb> = (0..10)
            .map(|i| cube(Vec3::new(i as f32, 0.0, 0.0), 1.0))
            .collect();
        let far: Vec<Aabb> = (0..10)
            .map(|i| cube(Vec3::new(20.0 + i as f32, 0.0, 0.0), 1.0))
            .collect();
        // Ten inside its box: 60 > 40.
        let c = Crowd::new(&inside, &[1; 10]);
        assert!(c.crowded(&big, 0, 40.0));
        // Not when it holds more of its own.
        assert!(!c.crowded(&big, 0, 60.0));
        // The same leaves as its own object's: not counted.
        let c = Crowd::new(&inside, &[0; 10]);
        assert!(!c.crowded(&big, 0, 40.0));
        // Far away: nothing inside.
        let c = Crowd::new(&far, &[1; 10]);
        assert!(!c.crowded(&big, 0, 40.0));
        // Six cubes inside (36): not crowded; seven (42): crowded.
        let c = Crowd::new(&inside[..6], &[1; 6]);
        assert!(!c.crowded(&big, 0, 40.0));
        let c = Crowd::new(&inside[..7], &[1; 7]);
        assert!(c.crowded(&big, 0, 40.0));
        // Clipped to the box: cubes half outside count their part inside (area 4 of 6).
        let shifted: Vec<Aabb> = (0..10)
            .map(|i| cube(Vec3::new(i as f32, 0.5, 0.0), 1.0))
            .collect();
        let c = Crowd::new(&shifted, &[1; 10]);
        assert!(c.crowded(&big, 0, 39.0) && !c.crowded(&big, 0, 40.0));
    }
}
