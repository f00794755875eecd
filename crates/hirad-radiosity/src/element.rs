//! The element arena: surface elements (triangle quadtrees, split 1→4 at edge midpoints) and
//! cluster elements (one per [`ClusterTree`] node), addressed by `u32` ids.
//!
//! Layout: ids `0..num_clusters` are the cluster nodes (element id = node id, root 0);
//! then one root surface element per input triangle (front faces, id
//! `first_root + tri`); with two-sided surfaces the back faces follow (id
//! `first_root + num_tris + tri`): a back face is a separate element with reversed winding
//! and normal, its own radiosity and no emission (emitters emit from the front only).
//! Subdivided surface elements are appended as refinement creates them, four contiguous
//! children at a time. A cluster's children are its child clusters followed by the root
//! surface elements of the surfaces attached to it (both faces when two-sided), stored as a
//! range of [`Elements::cluster_kids`].

use glam::{DVec3, Vec3};
use hirad_accel::cluster::{ClusterTree, NONE};
use hirad_scene::Scene;

use crate::cluster_model::cluster_orientation;
pub use crate::cluster_model::{facing_weight, ClusterOrient};

/// Kind of an element.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kind {
    /// A triangle: an input triangle (a root) or a part of one.
    Surface,
    /// A node of the cluster tree.
    Cluster,
}

/// One element of the hierarchy.
#[derive(Clone, Debug)]
pub struct Element {
    /// Surface or cluster.
    pub kind: Kind,
    /// Back face of a two-sided surface.
    pub back: bool,
    /// Subdivision level below the root surface (0 for roots and clusters).
    pub level: u16,
    /// Parent element ([`NONE`] for the root cluster).
    pub parent: u32,
    /// Surfaces: id of the first of 4 contiguous children; clusters: offset into
    /// [`Elements::cluster_kids`]. Meaningless when `num_children == 0`.
    pub first_child: u32,
    /// Number of children (0: a leaf).
    pub num_children: u32,
    /// Surfaces: input triangle; clusters: cluster node id.
    pub tri: u32,
    /// Corners (surfaces, counter-clockwise around `normal`).
    pub verts: [Vec3; 3],
    /// Unit normal (surfaces).
    pub normal: Vec3,
    /// Area (surfaces) or total area of the root surfaces inside (clusters).
    pub area: f32,
    /// Centroid (surfaces) or area-weighted centroid of the contents (clusters).
    pub centroid: Vec3,
    /// Reflectance (surfaces) or area-weighted mean reflectance (clusters).
    pub rho: Vec3,
    /// Emitted exitance E = π·L_e (front faces of emitters; zero otherwise).
    pub emission: Vec3,
}

impl Element {
    /// True for cluster elements.
    #[inline]
    pub fn is_cluster(&self) -> bool {
        self.kind == Kind::Cluster
    }

    /// True when the element has no children yet.
    #[inline]
    pub fn is_leaf(&self) -> bool {
        self.num_children == 0
    }
}

/// The arena of elements with their radiosity state.
#[derive(Clone, Debug)]
pub struct Elements {
    /// The elements, indexed by id.
    pub elems: Vec<Element>,
    /// Children lists of clusters.
    pub cluster_kids: Vec<u32>,
    /// Number of cluster elements (ids `0..num_clusters`).
    pub num_clusters: u32,
    /// Id of the root surface element of triangle 0 (front face).
    pub first_root: u32,
    /// Number of input triangles.
    pub num_tris: u32,
    /// Back faces present (root ids `first_root + num_tris + tri`).
    pub two_sided: bool,
    /// Per input triangle: its back face takes part in the solve (all when the solve is
    /// two-sided; per material otherwise, [`Scene::has_back`]). The back root of a triangle
    /// without one exists only to keep the ids regular: no cluster holds it, no link reaches it
    /// and its radiosity stays 0, as for a one-sided surface ([`Elements::is_dead`]).
    pub has_back: Vec<bool>,
    /// Radiosity B per element (W/m², RGB).
    pub b: Vec<DVec3>,
    /// Irradiance gathered through the element's own links in the last gather.
    pub h: Vec<DVec3>,
    /// Direct irradiance from the sun and sky (surface elements; zero without them).
    pub direct: Vec<DVec3>,
    /// Share of the element's area that receives and emits: not under a coplanar triangle
    /// nor inside a solid ([`super::overlap::Covers`]); NaN until the solver has computed it
    /// (new children of a split element).
    pub open: Vec<f32>,
    /// Orientation summary per cluster (index = cluster id).
    pub orient: Vec<ClusterOrient>,
}

impl Elements {
    /// Build the cluster and root surface elements of a scene and its tree.
    pub fn build(scene: &Scene, tree: &ClusterTree, two_sided: bool) -> Elements {
        let nc = tree.nodes.len() as u32;
        let nt = scene.num_triangles() as u32;
        let has_back: Vec<bool> = (0..nt as usize)
            .map(|t| scene.has_back(t, two_sided))
            .collect();
        let any_back = has_back.iter().any(|&b| b);
        let sides = if any_back { 2 } else { 1 };
        let total = nc as usize + (nt as usize) * sides;
        let mut elems = Vec::with_capacity(total + total / 2);
        for (id, node) in tree.nodes.iter().enumerate() {
            elems.push(Element {
                kind: Kind::Cluster,
                back: false,
                level: 0,
                parent: node.parent,
                first_child: 0,
                num_children: 0,
                tri: id as u32,
                verts: [Vec3::ZERO; 3],
                normal: Vec3::ZERO,
                area: 0.0,
                centroid: node.bbox.center(),
                rho: Vec3::ZERO,
                emission: Vec3::ZERO,
            });
        }
        for side in 0..sides {
            for (t, &back) in has_back.iter().enumerate() {
                let [a, b, c] = scene.tri_vertices(t);
                let m = scene.material_of(t);
                let (verts, normal, emission) = if side == 0 {
                    (
                        [a, b, c],
                        scene.normals[t],
                        m.emission * std::f32::consts::PI,
                    )
                } else {
                    ([a, c, b], -scene.normals[t], Vec3::ZERO)
                };
                let rho = if side == 0 || back { m.rho } else { Vec3::ZERO };
                elems.push(Element {
                    kind: Kind::Surface,
                    back: side == 1,
                    level: 0,
                    parent: tree.surface_node[t],
                    first_child: 0,
                    num_children: 0,
                    tri: t as u32,
                    verts,
                    normal,
                    area: scene.areas[t],
                    centroid: (a + b + c) / 3.0,
                    rho,
                    emission,
                });
            }
        }
        // Children lists of clusters.
        let mut cluster_kids = Vec::with_capacity(nc as usize + nt as usize * sides);
        for (id, node) in tree.nodes.iter().enumerate() {
            let start = cluster_kids.len() as u32;
            cluster_kids.extend(node.children());
            for &s in tree.node_surfaces(id as u32) {
                cluster_kids.push(nc + s);
                if sides == 2 && has_back[s as usize] {
                    cluster_kids.push(nc + nt + s);
                }
            }
            let e = &mut elems[id];
            e.first_child = start;
            e.num_children = cluster_kids.len() as u32 - start;
        }
        // Cluster area, centroid and reflectance, bottom-up (children have larger ids).
        let mut acc = vec![(0f64, DVec3::ZERO, DVec3::ZERO); nc as usize];
        for id in (0..nc as usize).rev() {
            let (mut a, mut c, mut r) = (0f64, DVec3::ZERO, DVec3::ZERO);
            let e = &elems[id];
            for &k in
                &cluster_kids[e.first_child as usize..(e.first_child + e.num_children) as usize]
            {
                if k < nc {
                    let (ka, kc, kr) = acc[k as usize];
                    a += ka;
                    c += kc;
                    r += kr;
                } else {
                    let s = &elems[k as usize];
                    let sa = s.area as f64;
                    a += sa;
                    c += s.centroid.as_dvec3() * sa;
                    r += s.rho.as_dvec3() * sa;
                }
            }
            acc[id] = (a, c, r);
            let e = &mut elems[id];
            e.area = a as f32;
            if a > 0.0 {
                e.centroid = (c / a).as_vec3();
                e.rho = (r / a).as_vec3();
            }
        }
        let orient = cluster_orientation(&elems, &cluster_kids, nc);
        let n = elems.len();
        Elements {
            elems,
            cluster_kids,
            num_clusters: nc,
            first_root: nc,
            num_tris: nt,
            two_sided: any_back,
            has_back,
            b: vec![DVec3::ZERO; n],
            h: vec![DVec3::ZERO; n],
            direct: vec![DVec3::ZERO; n],
            open: vec![1.0; n],
            orient,
        }
    }

    /// Element `id` is the back root of a triangle without a back face ([`Elements::has_back`]).
    #[inline]
    pub fn is_dead(&self, id: u32) -> bool {
        let e = &self.elems[id as usize];
        e.back && !self.has_back[e.tri as usize]
    }

    /// Number of elements.
    #[inline]
    pub fn len(&self) -> usize {
        self.elems.len()
    }

    /// True when there are no elements (never for a built arena).
    #[inline]
    pub fn is_empty(&self) -> bool {
        self.elems.is_empty()
    }

    /// Number of root surface elements (triangles × faces).
    #[inline]
    pub fn num_roots(&self) -> u32 {
        self.num_tris * if self.two_sided { 2 } else { 1 }
    }

    /// [`Elements::open`] of element `id`, taken as 1 while unknown.
    #[inline]
    pub fn open_share(&self, id: u32) -> f64 {
        let o = self.open[id as usize];
        if o.is_nan() {
            1.0
        } else {
            o as f64
        }
    }

    /// Ids of the root surface elements.
    #[inline]
    pub fn roots(&self) -> std::ops::Range<u32> {
        self.first_root..self.first_root + self.num_roots()
    }

    /// Children of an element (cluster kids, or the 4 sub-triangles of a split surface).
    #[inline]
    pub fn children(&self, id: u32) -> ChildIter<'_> {
        let e = &self.elems[id as usize];
        match e.kind {
            Kind::Cluster => ChildIter::Slice(
                self.cluster_kids
                    [e.first_child as usize..(e.first_child + e.num_children) as usize]
                    .iter(),
            ),
            Kind::Surface => ChildIter::Range(e.first_child..e.first_child + e.num_children),
        }
    }

    /// Split surface element `id` into 4 children (midpoint subdivision) unless it already
    /// has them. The children start with the parent's radiosity.
    pub fn subdivide(&mut self, id: u32) {
        let e = &self.elems[id as usize];
        if e.kind != Kind::Surface || e.num_children > 0 {
            return;
        }
        let [a, b, c] = e.verts;
        let ab = (a + b) * 0.5;
        let bc = (b + c) * 0.5;
        let ca = (c + a) * 0.5;
        let tris = [[a, ab, ca], [ab, b, bc], [ca, bc, c], [ab, bc, ca]];
        let first = self.elems.len() as u32;
        let proto = e.clone();
        let bparent = self.b[id as usize];
        for v in tris {
            self.elems.push(Element {
                level: proto.level + 1,
                parent: id,
                first_child: 0,
                num_children: 0,
                verts: v,
                area: proto.area * 0.25,
                centroid: (v[0] + v[1] + v[2]) / 3.0,
                ..proto.clone()
            });
            self.b.push(bparent);
            self.h.push(DVec3::ZERO);
            self.direct.push(DVec3::ZERO);
            self.open.push(f32::NAN);
        }
        let e = &mut self.elems[id as usize];
        e.first_child = first;
        e.num_children = 4;
    }

    /// The leaf below surface element `id` whose triangle holds point `p` (a point of `id`'s
    /// triangle): barycentric descent through the midpoint subdivision of [`subdivide`].
    ///
    /// [`subdivide`]: Self::subdivide
    pub fn leaf_at(&self, id: u32, p: Vec3) -> u32 {
        let Some(mut uvw) = barycentric(&self.elems[id as usize].verts, p) else {
            return id;
        };
        let mut id = id;
        loop {
            let e = &self.elems[id as usize];
            if e.num_children == 0 || e.kind != Kind::Surface {
                return id;
            }
            let (k, next) = child_step(uvw);
            id = e.first_child + k;
            uvw = next;
        }
    }

    /// Bytes used by the arena (elements, state arrays, cluster lists).
    pub fn memory_bytes(&self) -> usize {
        self.elems.capacity() * std::mem::size_of::<Element>()
            + (self.b.capacity() + self.h.capacity() + self.direct.capacity())
                * std::mem::size_of::<DVec3>()
            + self.open.capacity() * 4
            + self.cluster_kids.capacity() * 4
            + self.orient.capacity() * std::mem::size_of::<ClusterOrient>()
    }

    /// Bytes one more element costs.
    pub const BYTES_PER_ELEMENT: usize =
        std::mem::size_of::<Element>() + 3 * std::mem::size_of::<DVec3>() + 4;

    /// True when `a` is an ancestor of `b` (or equal).
    pub fn is_ancestor(&self, a: u32, b: u32) -> bool {
        let mut x = b;
        while x != NONE {
            if x == a {
                return true;
            }
            x = self.elems[x as usize].parent;
        }
        false
    }

    /// Leaf surface elements below `id` (depth-first, children in order).
    pub fn leaves_of(&self, id: u32, out: &mut Vec<u32>) {
        let e = &self.elems[id as usize];
        if e.num_children == 0 {
            if e.kind == Kind::Surface {
                out.push(id);
            }
            return;
        }
        for c in self.children(id) {
            self.leaves_of(c, out);
        }
    }
}

/// Iterator over the children of an element.
pub enum ChildIter<'a> {
    /// A cluster's children, from [`Elements::cluster_kids`].
    Slice(std::slice::Iter<'a, u32>),
    /// A split surface's 4 contiguous children.
    Range(std::ops::Range<u32>),
}

impl Iterator for ChildIter<'_> {
    type Item = u32;
    #[inline]
    fn next(&mut self) -> Option<u32> {
        match self {
            ChildIter::Slice(s) => s.next().copied(),
            ChildIter::Range(r) => r.next(),
        }
    }
}

/// Barycentric coordinates of `p` (a point of the triangle's plane) in triangle `v`; `None`
/// for a degenerate triangle.
fn barycentric(v: &[Vec3; 3], p: Vec3) -> Option<(f64, f64, f64)> {
    let [a, b, c] = v.map(|v| v.as_dvec3());
    let (e1, e2, q) = (b - a, c - a, p.as_dvec3() - a);
    let (d11, d12, d22) = (e1.dot(e1), e1.dot(e2), e2.dot(e2));
    let (q1, q2) = (q.dot(e1), q.dot(e2));
    let den = d11 * d22 - d12 * d12;
    if den <= 0.0 {
        return None;
    }
    let v = (d22 * q1 - d12 * q2) / den;
    let w = (d11 * q2 - d12 * q1) / den;
    Some((1.0 - v - w, v, w))
}

/// The child of the midpoint subdivision ([`Elements::subdivide`]: children [a, ab, ca],
/// [ab, b, bc], [ca, bc, c], [ab, bc, ca]) that holds the point with barycentric coordinates
/// `(u, v, w)`, and the point's coordinates in that child.
fn child_step((u, v, w): (f64, f64, f64)) -> (u32, (f64, f64, f64)) {
    if u >= 0.5 {
        (0, (2.0 * u - 1.0, 2.0 * v, 2.0 * w))
    } else if v >= 0.5 {
        (1, (2.0 * u, 2.0 * v - 1.0, 2.0 * w))
    } else if w >= 0.5 {
        (2, (2.0 * u, 2.0 * v, 2.0 * w - 1.0))
    } else {
        (3, (1.0 - 2.0 * w, 1.0 - 2.0 * u, 1.0 - 2.0 * v))
    }
}

/// The path of point `p` down `levels` levels of the midpoint subdivision of triangle `v`:
/// the child index at level `i` in bits `2i..2i+2`.
pub fn quad_path(v: &[Vec3; 3], p: Vec3, levels: u32) -> u32 {
    let Some(mut uvw) = barycentric(v, p) else {
        return 0;
    };
    let mut path = 0;
    for i in 0..levels {
        let (k, next) = child_step(uvw);
        path |= k << (2 * i);
        uvw = next;
    }
    path
}
