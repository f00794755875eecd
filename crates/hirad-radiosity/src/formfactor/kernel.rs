//! The sampled link kernel ([`KernelCtx`]): the unoccluded estimate `F̃`, its spread over a
//! surface receiver, and the full evaluation with stratified jittered shadow rays
//! ([`KernelEval`]).
//!
//! Cluster receivers: isotropic clusters (and isotropic reception) take the kernel at the
//! centre, facing the source (`spec/radiosity.md`); a directional cluster with oriented
//! reception samples its surfaces in proportion to their hand-out weights (see
//! [`KernelCtx::evaluate_with`]). Shadow rays of cluster ends start from points on their
//! surfaces and leave out only those surfaces (directional) or the whole cluster (isotropic).
//! A surface source's ray ends are drawn near its receiver in proportion to the point-to-point
//! kernel, so that visibility counts where the kernel does.
//! Points of a triangle that a coplanar one covers ([`Covers`]) neither receive nor emit.

use super::analytic::{point_to_disk, point_to_polygon, point_to_polygon_many};
use super::near_field::{closest_on_triangle, end_sphere, near_field_points};
use super::sampling::{
    sample_triangle_above, sample_triangle_above_area, sample_triangle_inset,
    sample_triangle_solid_angle, stratified_2d,
};
use crate::cluster_model::{self, ClusterOrient};
use crate::config::{ClusterEmission, Reception, VisibilityMode};
use crate::element::{quad_path, Elements, Kind};
use crate::link::Deposit;
use crate::overlap::Covers;
use crate::visibility::Visibility;
use glam::{DVec3, Vec3};
use hirad_accel::cluster::ClusterTree;
use hirad_accel::ray::volume::Endpoint;
use hirad_core::rng::SplitMix64;
use smallvec::SmallVec;

/// Samples and bounds of a link kernel.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct KernelEval {
    /// The kernel with visibility (form factor receiver → source).
    pub k: f64,
    /// The same samples' kernel without visibility.
    pub ku: f64,
    /// Unoccluded estimate `F̃` (the `bf` oracle's quantity, per unit source radiosity).
    pub est: f64,
    /// Lower kernel bound (with visibility bounds), for the `error` oracle.
    pub kmin: f64,
    /// Upper kernel bound (with visibility bounds), for the `error` oracle.
    pub kmax: f64,
    /// Shadow rays cast.
    pub rays: u64,
    /// Some samples with a positive kernel see the source and some do not.
    pub mixed: bool,
    /// Directional cluster sources, and subdivided surface sources asked for their leaves: per
    /// sample, the surface element its point lies on and its share of `k`, so that the
    /// transfer takes each sampled surface's own radiosity (`Σ w_s B_s`) instead of the
    /// source's average over parts the receiver does not see (the back faces of two-sided
    /// walls, a lamp behind a wall of the same cluster, a ceiling's bright band right above a
    /// lamp that hangs in front of it).
    pub members: Vec<(u32, f32)>,
    /// Surface receiver: sample points and whether their rays were open ([`Deposit`]).
    pub deposit: Deposit,
    /// Surface source: where the transfer leaves from ([`Deposit`]), up to four open samples
    /// drawn in proportion to their kernels (within a diameter of the source; evenly
    /// beyond).
    pub draw: Deposit,
    /// Directional cluster receiver whose rays disagree: the strata around the surfaces whose
    /// samples saw the source (a surface, or a cluster below the receiver), each with its
    /// irradiance per unit of the cluster's: the hand-out's power (`W = Σ A_s o_s w_s` times
    /// the cluster's irradiance, `o_s` the open share) shared in proportion to what their
    /// samples received, over a surface's open area, or over a cluster's `W` (its surfaces
    /// then get it times their `w_s`).
    pub open_members: Vec<(u32, f32)>,
    /// Directional cluster receiver whose rays all saw the source: a child that no sample
    /// landed on does not see it (`KernelCtx::probe_children`).
    pub hidden_child: bool,
}

/// What a link records of its samples ([`Deposit`]): on a surface receiver (vertices `vr`),
/// up to [`Deposit::POINTS`] of its counted sample points `recv` (point, ray open), drawn
/// evenly among them; on a surface source (`vs`), up to as many of the open pairs `seen`
/// (receiver point, source point, weight), drawn in proportion to their weights (each pair's
/// kernel over the density it was drawn with, or equal): where the transfer leaves from, so
/// that it takes the source's radiosity where the receiver sees it and its kernel is strong,
/// not the source's mean.
pub(super) fn deposit_at(
    vr: Option<&[Vec3; 3]>,
    vs: Option<&[Vec3; 3]>,
    recv: &mut [(Vec3, bool)],
    seen: &[(Vec3, Vec3, f64)],
    rng: &mut SplitMix64,
) -> (Deposit, Deposit) {
    let deposit = match vr {
        Some(v) if !recv.is_empty() => {
            let c = draw_first(recv, rng);
            let paths: SmallVec<[u32; Deposit::POINTS]> = recv[..c]
                .iter()
                .map(|s| quad_path(v, s.0, Deposit::LEVELS))
                .collect();
            let mask = (0..c).fold(0, |m, i| m | (recv[i].1 as u32) << i);
            Deposit::with_mask(&paths, mask)
        }
        _ => Deposit::default(),
    };
    let draw = match vs {
        Some(v) if !seen.is_empty() => {
            let paths: SmallVec<[u32; Deposit::POINTS]> = draw_weighted(seen, rng)
                .iter()
                .map(|&i| quad_path(v, seen[i].1, Deposit::LEVELS))
                .collect();
            Deposit::new(&paths)
        }
        _ => Deposit::default(),
    };
    (deposit, draw)
}

/// Up to [`Deposit::POINTS`] indices of `items` drawn in proportion to their weights
/// (systematically: one random offset, equal steps through the cumulative weight), evenly when
/// no weight is positive.
pub(super) fn draw_weighted(
    items: &[(Vec3, Vec3, f64)],
    rng: &mut SplitMix64,
) -> SmallVec<[usize; Deposit::POINTS]> {
    let c = items.len().min(Deposit::POINTS);
    let total: f64 = items.iter().map(|s| s.2).sum();
    let mut out = SmallVec::new();
    let u = rng.next_f64();
    if total.is_nan() || total <= 0.0 {
        let step = items.len() as f64 / c as f64;
        out.extend((0..c).map(|k| (((k as f64 + u) * step) as usize).min(items.len() - 1)));
        return out;
    }
    let step = total / c as f64;
    let mut target = u * step;
    let mut acc = 0.0;
    for (i, s) in items.iter().enumerate() {
        acc += s.2;
        while out.len() < c && target < acc {
            out.push(i);
            target += step;
        }
    }
    // Rounding may leave the last step past the sum.
    while out.len() < c {
        out.push(items.len() - 1);
    }
    out
}

/// Moves up to [`Deposit::POINTS`] items drawn evenly from `items` to its front; their number.
fn draw_first<T>(items: &mut [T], rng: &mut SplitMix64) -> usize {
    let c = items.len().min(Deposit::POINTS);
    for i in 0..c {
        let j = i + (rng.next_u64() % (items.len() - i) as u64) as usize;
        items.swap(i, j);
    }
    c
}

/// `max(0, cos θx) max(0, cos θy) / (r² + R²)` between points `x` (normal `nx`, none:
/// facing `y`) and `y` (normal `ny`): the kernel per unit area, but for the factor `1/π`, of
/// a disk of radius `R` (`r2_cell` = R²) around `y` facing `x` (the coaxial point-to-disk form
/// factor over the disk's area). A link's draw reads the radiosity of cells of the source, and
/// near a cell the kernel of its points is that of the cell, not the point's `1/r²`.
pub(super) fn point_pair_kernel(x: Vec3, nx: Option<Vec3>, y: Vec3, ny: Vec3, r2_cell: f64) -> f64 {
    let d = (y - x).as_dvec3();
    let r2 = d.length_squared();
    if r2.is_nan() || r2 <= 0.0 {
        return 0.0;
    }
    let cx = nx.map_or(r2.sqrt(), |n| n.as_dvec3().dot(d).max(0.0));
    let cy = (-ny.as_dvec3().dot(d)).max(0.0);
    cx * cy / (r2 * (r2 + r2_cell))
}

/// Weight in a draw of a pair whose source point `y` was drawn by solid angle from `x`
/// ([`sample_triangle_solid_angle`]'s weight `cos θ_x / (π p)` over any density of `x`:
/// `weight`), damped within a cell of the source's part `over` as [`point_pair_kernel`] is.
pub(super) fn solid_angle_pair_weight(weight: f64, x: Vec3, y: Vec3, over: f64) -> f64 {
    let r2 = x.distance_squared(y) as f64;
    let cell = over * CELL_SHARE / std::f64::consts::PI;
    weight * std::f64::consts::PI * r2 / (r2 + cell)
}

/// Within this many of a surface source's radii of the receiver (from the receiver's
/// bounding sphere to the source's centre) the source's points are drawn by solid angle.
const SOLID_ANGLE_RADII: f64 = 4.0;

/// Share of a source's area in one cell of the deepest level a draw records
/// ([`Deposit::LEVELS`] of midpoint subdivision).
pub(super) const CELL_SHARE: f64 = 1.0 / (1 << (2 * Deposit::LEVELS)) as f64;

/// Everything needed to evaluate link kernels.
#[derive(Clone, Copy)]
pub struct KernelCtx<'a> {
    /// The element arena.
    pub elems: &'a Elements,
    /// The cluster tree of the elements.
    pub tree: &'a ClusterTree,
    /// Shadow rays.
    pub vis: &'a Visibility<'a>,
    /// Coplanar overlaps: covered points neither receive nor emit.
    pub covers: &'a Covers,
    /// Shadow rays per link.
    pub n_rays: usize,
    /// Seed of the run.
    pub seed: u64,
    /// Emission model of cluster sources.
    pub emission: ClusterEmission,
    /// How clusters hand received irradiance to their surfaces.
    pub reception: Reception,
    /// Shadow rays are cast; without, [`KernelCtx::evaluate_with`] gives the unoccluded
    /// kernel of its `n_rays` samples alone (`ku`; no rays, near-field grid, deposits or
    /// draws).
    pub occlusion: bool,
}

/// Geometry of one end of a link.
#[derive(Clone, Copy)]
pub(crate) enum End {
    Surface {
        v: [Vec3; 3],
        n: Vec3,
        c: Vec3,
        area: f64,
        tri: u32,
    },
    Cluster {
        lo: Vec3,
        hi: Vec3,
        c: Vec3,
        area: f64,
        node: u32,
        /// Orientation summary for the directional emission model (`None`: isotropic).
        orient: Option<ClusterOrient>,
        /// Normal of the surface at the sample point `c` (sampled kernels).
        sample_normal: Option<Vec3>,
    },
}

impl End {
    pub(super) fn endpoint(&self) -> Endpoint {
        match *self {
            End::Surface { tri, .. } => Endpoint::Surface(tri),
            End::Cluster { node, .. } => Endpoint::Cluster(node),
        }
    }
}

/// Signed distances of the box corners to a plane: true when the whole box is behind or on it.
fn box_behind(lo: Vec3, hi: Vec3, p: Vec3, n: Vec3, tol: f32) -> bool {
    // The corner farthest along n.
    let far = Vec3::new(
        if n.x >= 0.0 { hi.x } else { lo.x },
        if n.y >= 0.0 { hi.y } else { lo.y },
        if n.z >= 0.0 { hi.z } else { lo.z },
    );
    n.dot(far - p) <= tol
}

fn tri_behind(v: &[Vec3; 3], p: Vec3, n: Vec3, tol: f32) -> bool {
    v.iter().all(|&q| n.dot(q - p) <= tol)
}

impl KernelCtx<'_> {
    pub(crate) fn end(&self, id: u32) -> End {
        let e = &self.elems.elems[id as usize];
        match e.kind {
            Kind::Surface => End::Surface {
                v: e.verts,
                n: e.normal,
                c: e.centroid,
                area: e.area as f64,
                tri: e.tri,
            },
            Kind::Cluster => {
                let b = self.tree.nodes[e.tri as usize].bbox;
                End::Cluster {
                    lo: b.min,
                    hi: b.max,
                    c: e.centroid,
                    area: e.area as f64,
                    node: e.tri,
                    orient: (self.emission == ClusterEmission::Directional)
                        .then(|| self.elems.orient[id as usize]),
                    sample_normal: None,
                }
            }
        }
    }

    /// True when the kernel between receiver `i` and source `j` is identically zero by
    /// geometry (one behind the other's plane, coplanar surfaces).
    pub fn is_zero(&self, i: u32, j: u32) -> bool {
        let (ri, sj) = (self.end(i), self.end(j));
        let tol = |a: Vec3, b: Vec3| 1e-6 * (a.abs().max_element() + b.abs().max_element() + 1e-3);
        match (ri, sj) {
            (End::Surface { v: vi, n: ni, .. }, End::Surface { v: vj, n: nj, .. }) => {
                tri_behind(&vj, vi[0], ni, tol(vi[0], vj[0]))
                    || tri_behind(&vi, vj[0], nj, tol(vi[0], vj[0]))
            }
            (End::Surface { v, n, .. }, End::Cluster { lo, hi, .. }) => {
                box_behind(lo, hi, v[0], n, tol(v[0], hi))
            }
            (End::Cluster { lo, hi, .. }, End::Surface { v, n, .. }) => {
                box_behind(lo, hi, v[0], n, tol(v[0], hi))
            }
            (End::Cluster { .. }, End::Cluster { .. }) => false,
        }
    }

    /// Unoccluded kernel at receiver point `x` (normal `n`, `None` for a cluster receiver,
    /// which faces the source).
    pub(crate) fn point_kernel(x: Vec3, n: Option<Vec3>, src: &End) -> f64 {
        let xd = x.as_dvec3();
        match *src {
            End::Surface {
                v, n: nj, c, area, ..
            } => {
                let nn = match n {
                    Some(n) => n.as_dvec3(),
                    None => {
                        let d = c.as_dvec3() - xd;
                        let l = d.length();
                        if l <= 0.0 {
                            return 0.0;
                        }
                        d / l
                    }
                };
                let poly = v.map(|p| p.as_dvec3());
                let f = point_to_polygon(xd, nn, &poly, nj.as_dvec3());
                // A receiver facing the source cannot see more than a disk of the same area
                // would give at this distance: guards the cluster-centre case.
                if n.is_none() {
                    let r2 = (c.as_dvec3() - xd).length_squared();
                    let cs = nj.as_dvec3().dot((xd - c.as_dvec3()).normalize_or_zero());
                    f.max(point_to_disk(r2, 1.0, cs, area)).min(1.0)
                } else {
                    f
                }
            }
            End::Cluster {
                c,
                area,
                orient,
                sample_normal,
                ..
            } => cluster_model::point_kernel(xd, n, c, area, orient, sample_normal),
        }
    }

    /// Cheap unoccluded estimate `F̃` (no rays): the maximum of the point kernel at the
    /// receiver's centroid and (slightly inset) corners.
    pub fn estimate(&self, i: u32, j: u32) -> f64 {
        match self.end(i) {
            End::Surface { .. } => self.spread(i, j).1,
            End::Cluster { c, .. } => Self::point_kernel(c, None, &self.end(j)),
        }
    }

    /// Range `(min, max)` of the unoccluded kernel over a surface receiver `i` (its centroid,
    /// slightly inset corners and the point nearest the source), no rays; `(0, 0)` for a
    /// cluster receiver.
    pub fn spread(&self, i: u32, j: u32) -> (f64, f64) {
        let (ri, sj) = (self.end(i), self.end(j));
        let End::Surface { v, n, c, .. } = ri else {
            return (0.0, 0.0);
        };
        // The receiver's point nearest the source: a large receiver beside a small, bright
        // source (a ceiling over a lamp 8 cm below it) sees it strongly there and weakly at its
        // centre and corners.
        let near = closest_on_triangle(&v, end_sphere(&sj).0.as_vec3());
        let mut xs = [c; 5];
        for (x, p) in xs[1..].iter_mut().zip(v.into_iter().chain([near])) {
            *x = p + (c - p) * 0.05;
        }
        let mut f = [0.0; 5];
        Self::point_kernels(&xs, n, &sj, &mut f);
        f[1..]
            .iter()
            .fold((f[0], f[0]), |(lo, hi), &f| (lo.min(f), hi.max(f)))
    }

    /// [`KernelCtx::point_kernel`] at each of the points `xs` of a surface receiver with
    /// normal `n`, written to `out`: the same values, a surface source's computed together
    /// ([`point_to_polygon_many`]).
    pub(crate) fn point_kernels(xs: &[Vec3], n: Vec3, src: &End, out: &mut [f64]) {
        match *src {
            End::Surface { v, n: nj, .. } => {
                let poly = v.map(|p| p.as_dvec3());
                let mut xd = [DVec3::ZERO; 8];
                for (xs, out) in xs.chunks(xd.len()).zip(out.chunks_mut(xd.len())) {
                    for (d, x) in xd.iter_mut().zip(xs) {
                        *d = x.as_dvec3();
                    }
                    let xd = &xd[..xs.len()];
                    point_to_polygon_many(xd, n.as_dvec3(), &poly, nj.as_dvec3(), out);
                }
            }
            End::Cluster { .. } => {
                for (o, &x) in out.iter_mut().zip(xs) {
                    *o = Self::point_kernel(x, Some(n), src);
                }
            }
        }
    }

    /// Full kernel evaluation of the link (receiver `i`, source `j`) with `n_rays` stratified
    /// jittered shadow rays. `bounds`: also sample the kernel bounds for the `error` oracle.
    pub fn evaluate(&self, i: u32, j: u32, bounds: bool) -> KernelEval {
        self.evaluate_with(i, j, bounds, None, false, false)
    }

    /// [`evaluate`](Self::evaluate) reusing an estimate `F̃` already computed for the link;
    /// `fine`: the link stays unresolved (the oracle would refine it, neither end can be
    /// split), so a near-field kernel integrates at twice the density; `leaves`: a subdivided
    /// surface source keeps, per sample, the leaf its point lies on
    /// ([`KernelEval::members`]), so that the gather takes the radiosity where the samples
    /// see the source instead of its mean.
    pub fn evaluate_with(
        &self,
        i: u32,
        j: u32,
        bounds: bool,
        est: Option<f64>,
        fine: bool,
        leaves: bool,
    ) -> KernelEval {
        let (ri, sj) = (self.end(i), self.end(j));
        let n = self.n_rays.max(1);
        let mut rng =
            SplitMix64::for_item(self.seed ^ 0x005E_ED0F_114C, ((i as u64) << 32) | j as u64);
        let mut su = Samples::new();
        let mut sv = Samples::new();
        stratified_2d(n, &mut rng, &mut su);
        stratified_2d(n, &mut rng, &mut sv);
        let est = est.unwrap_or_else(|| self.estimate(i, j));
        if let (End::Surface { .. }, End::Surface { .. }) = (ri, sj) {
            let m = near_field_points(&ri, &sj, n, fine);
            if m > n && self.occlusion {
                return self.near_field(&ri, &sj, m, n, est, &mut rng);
            }
        }
        // Σ fx·V·q, Σ fx and Σ fx·q over the samples that count (`q` below).
        let (mut sum, mut sum_u, mut sum_q) = (0.0, 0.0, 0.0);
        // Centre distance, receiver radius and source radius, for a surface source.
        let spheres = match sj {
            End::Surface { .. } if self.occlusion => {
                let ((cr, rr), (cs, rs)) = (end_sphere(&ri), end_sphere(&sj));
                Some((cr.distance(cs), rr, rs))
            }
            _ => None,
        };
        // Within a diameter of a surface source its kernel varies across it by more than
        // `(1.5 / 0.5)²`: the draw weighs its open samples by their kernels there, evenly
        // beyond.
        let weigh_draw = spheres.is_some_and(|(d, _, rs)| d < 2.0 * rs);
        // A surface source's visibility is weighed by the kernel (`q` below) where there is
        // visibility to weigh. Within a few of its radii of the receiver its point-to-point
        // kernel varies across it by more than `(5 / 3)²`: its points are drawn by solid angle
        // there (bounded weights where the kernel peaks), area-uniform and weighed by the
        // kernel beyond.
        let weigh_vis = self.occlusion && self.vis.mode() != VisibilityMode::None;
        let solid_draw =
            weigh_vis && spheres.is_some_and(|(d, rr, rs)| d - rr < SOLID_ANGLE_RADII * rs);
        let mut rays = 0u64;
        let (mut vmin, mut vmax) = (1.0f64, 0.0f64);
        let (mut fmin, mut fmax) = (f64::INFINITY, 0.0f64);
        // Some samples that count see the source and some do not.
        let (mut open, mut blocked) = (false, false);
        let source_leaves = leaves && matches!(sj, End::Surface { .. });
        let per_member = source_leaves
            || matches!(
                sj,
                End::Cluster {
                    orient: Some(_),
                    ..
                }
            );
        let mut members = Vec::new();
        // Directional cluster receiver: the surfaces of the samples that saw the source and
        // what they received.
        let mut recv_open: SmallVec<[(u32, f64); INLINE]> = SmallVec::new();
        // Directional cluster receiver with oriented reception: its surfaces k with their
        // hand-out weights w_k (`facing_weight`) as a cumulative distribution of A_k·w_k; a
        // surface drawn from it contributes E(x)/w_k, whose mean is Σ A_k E_k / Σ A_k w_k, the
        // irradiance that the hand-out `H·w_k` must carry to deliver the received power.
        let recv_cdf = match ri {
            End::Cluster { node, .. } if self.hands_out_by_surface() => {
                Some(self.hand_out_cdf(node, j))
            }
            _ => None,
        };
        // The centre kernel of a cluster receiver without a hand-out distribution, computed
        // once when the source is the same for every sample (all but directional clusters).
        let centre_k = match (ri, &recv_cdf, sj) {
            (
                End::Cluster { .. },
                _,
                End::Cluster {
                    orient: Some(_), ..
                },
            ) => None,
            (End::Cluster { c, .. }, None, _) => Some(Self::point_kernel(c, None, &sj)),
            _ => None,
        };
        if recv_cdf.as_ref().is_some_and(|c| c.is_empty()) {
            // No surface of the receiver faces the source: the hand-out delivers nothing.
            return KernelEval {
                est,
                ..Default::default()
            };
        }
        // Between two surfaces, the receiver's sample points and their kernels, computed
        // together ([`KernelCtx::point_kernels`]).
        let mut surface_pts: SmallVec<[(Vec3, f64); INLINE]> = SmallVec::new();
        if let (End::Surface { v, n: nr, .. }, End::Surface { .. }) = (ri, sj) {
            let xs: SmallVec<[Vec3; INLINE]> = (0..n)
                .map(|s| self.point_on(&v, su[s][0], su[s][1]))
                .collect();
            let mut f: SmallVec<[f64; INLINE]> = SmallVec::from_elem(0.0, n);
            Self::point_kernels(&xs, nr, &sj, &mut f);
            surface_pts.extend(xs.into_iter().zip(f));
        }
        let mut n_open = 0usize;
        // The triangle that blocked the last blocked ray (`Visibility::between`).
        let mut last = None;
        // (receiver point, source point, weight in the draw) of the samples whose rays were
        // open.
        let mut seen: SmallVec<[(Vec3, Vec3, f64); INLINE]> = SmallVec::new();
        // Receiver points of the samples that count, and whether their rays were open.
        let mut recv: SmallVec<[(Vec3, bool); INLINE]> = SmallVec::new();
        // Directional cluster receiver: the surfaces its samples landed on, and the source
        // end of the first open ray (for `KernelCtx::probe_children`).
        let mut sampled: SmallVec<[u32; INLINE]> = SmallVec::new();
        let mut probe_src = None;
        // A receiver whose points all came out covered says nothing of its open part, over
        // which the kernel is the mean: its points are drawn again (keeping 0 would darken a
        // partly covered receiver by the chance that all of its points fall under the cover,
        // which grows as the rays per link fall).
        // A surface receiver that push-pull found entirely covered has no open part to find.
        let may_open = match ri {
            End::Surface { .. } => self.elems.open_share(i) > 0.0,
            End::Cluster { .. } => true,
        };
        for round in 0..COVER_POINTS.div_ceil(n) {
            if round > 0 {
                if n_open > 0 || !may_open {
                    break;
                }
                members.clear();
                surface_pts.clear();
                su.clear();
                sv.clear();
                stratified_2d(n, &mut rng, &mut su);
                stratified_2d(n, &mut rng, &mut sv);
                // A surface receiver's round whose points are all covered costs no kernels.
                if let End::Surface { v, n: nr, .. } = ri {
                    let e = ri.endpoint();
                    if su
                        .iter()
                        .all(|u| self.covered(e, nr, self.point_on(&v, u[0], u[1])))
                    {
                        continue;
                    }
                }
            }
            for s in 0..n {
                // Source sample point. A directional cluster source is the projected area of the
                // sampled surface (its own normal) at that point, so that the kernel converges to
                // the form factor of the cluster's contents; an isotropic one stays at its centre.
                let mut member = NO_MEMBER;
                let (y, ny) = match sj {
                    End::Surface { v, n, .. } => (self.point_on(&v, sv[s][0], sv[s][1]), n),
                    End::Cluster { node, .. } => {
                        let (y, n, k) = self.sample_cluster(node, sv[s][0], sv[s][1]);
                        member = k;
                        (y, n)
                    }
                };
                let mut src = sj;
                if let End::Cluster {
                    c,
                    sample_normal,
                    orient: Some(_),
                    ..
                } = &mut src
                {
                    *c = y;
                    *sample_normal = Some(ny);
                }
                // Receiver sample point and its unoccluded kernel: on a surface receiver; on a
                // surface of a directional cluster drawn by hand-out weight (irradiance there over
                // the weight); or on a surface of an isotropic cluster, whose kernel is taken at its
                // centre, facing the source.
                // What the shadow ray leaves out at each end: the surface its point lies on when
                // a directional cluster is sampled surface by surface (its other surfaces occlude
                // like any other), a whole cluster when the isotropic model stands for it (whose
                // point emitter or receiver has no inside, as in Sillion's model).
                let mut ex = ri.endpoint();
                let mut recv_member = NO_MEMBER;
                let ey = match sj {
                    End::Cluster {
                        orient: Some(_), ..
                    } if member != NO_MEMBER => {
                        Endpoint::Surface(self.elems.elems[member as usize].tri)
                    }
                    _ => sj.endpoint(),
                };
                // `f0`: the unoccluded point kernel at x (`fx` is it over the hand-out weight
                // on a directional cluster receiver).
                let (x, fx, nx, f0) = match (ri, recv_cdf.as_deref()) {
                    (End::Surface { v, n: nr, .. }, _) => match surface_pts.get(s) {
                        Some(&(x, f)) => (x, f, Some(nr), f),
                        None => {
                            let x = self.point_on(&v, su[s][0], su[s][1]);
                            let f = self.sample_kernel(x, nr, &src, member);
                            (x, f, Some(nr), f)
                        }
                    },
                    (End::Cluster { .. }, Some(cdf)) => {
                        let total = cdf[cdf.len() - 1].1;
                        let target = su[s][0] as f64 * total;
                        let i = cdf
                            .partition_point(|&(_, c, _)| c <= target)
                            .min(cdf.len() - 1);
                        let lo = if i > 0 { cdf[i - 1].1 } else { 0.0 };
                        let (id, hi, w) = cdf[i];
                        let u = ((target - lo) / (hi - lo).max(1e-300)).clamp(0.0, 0.999_999_9);
                        let e = &self.elems.elems[id as usize];
                        let x = self.point_on(&e.verts, u as f32, su[s][1]);
                        let f0 = self.sample_kernel(x, e.normal, &src, member);
                        ex = Endpoint::Surface(e.tri);
                        recv_member = id;
                        (x, f0 / w, Some(e.normal), f0)
                    }
                    (End::Cluster { node, c, .. }, None) => {
                        let (x, _, _) = self.sample_cluster(node, su[s][0], su[s][1]);
                        if bounds {
                            // The kernel's spread over the receiving cluster.
                            let fb = Self::point_kernel(x, None, &src);
                            fmin = fmin.min(fb);
                            fmax = fmax.max(fb);
                        }
                        let k = centre_k.unwrap_or_else(|| Self::point_kernel(c, None, &src));
                        (x, k, None, k)
                    }
                };
                // A surface source's kernel at x counts the part of it above x's plane: aim the
                // shadow ray there (a ray to a point behind x could pass where the counted part is
                // hidden, e.g. from inside a thin slab to a desk the slab stands on).
                // `over`: the area of that part. Without occlusion no ray is aimed.
                let mut over = 0.0;
                // A surface source's visibility at x weighs `q`, the point-to-point kernel
                // over its mean `F(x)` at the drawn point (mean 1), so that the kernel is the
                // visible share of `F(x)`: `cos θ_x / (π p F(x))` for a point drawn by solid
                // angle with density `p` ([`sample_triangle_solid_angle`]; `solid`),
                // `f(x, y)·A / F(x)` for one drawn uniformly over the part's area A.
                let mut q = None;
                let mut solid = false;
                let y = match (sj, nx) {
                    _ if !self.occlusion => y,
                    (End::Surface { v, area, .. }, Some(nr)) => {
                        let uv = (sv[s][0], sv[s][1]);
                        let m = self.vis.margin();
                        let drawn = (solid_draw && f0 > 0.0)
                            .then(|| sample_triangle_solid_angle(x, nr, &v, uv, m, area))
                            .flatten();
                        match drawn {
                            Some((p, w, a)) => {
                                over = a;
                                q = Some(w / f0);
                                solid = true;
                                p
                            }
                            None => match sample_triangle_above_area(x, nr, &v, uv, m, area) {
                                Some((p, a)) => {
                                    over = a;
                                    if weigh_vis && f0 > 0.0 {
                                        // Either face of the source (f0 says it is seen).
                                        let d = (p - x).as_dvec3();
                                        let r2 = d.length_squared();
                                        let f = nr.as_dvec3().dot(d).max(0.0)
                                            * ny.as_dvec3().dot(d).abs()
                                            / (r2 * r2).max(1e-300);
                                        q = Some(f * a / (std::f64::consts::PI * f0));
                                    }
                                    p
                                }
                                None => y,
                            },
                        }
                    }
                    (
                        End::Cluster {
                            orient: Some(_), ..
                        },
                        Some(nr),
                    ) if member != NO_MEMBER => {
                        let v = self.elems.elems[member as usize].verts;
                        sample_triangle_above(x, nr, &v, (sv[s][1], sv[s][0]), self.vis.margin())
                            .unwrap_or(y)
                    }
                    _ => y,
                };
                if source_leaves {
                    member = self.elems.leaf_at(j, y);
                }
                // A covered receiver point is not part of the receiver: the kernel is the mean
                // over its open points. A covered source point emits nothing.
                if self.covered(ex, nx.unwrap_or(Vec3::ZERO), x) {
                    if per_member {
                        members.push((NO_MEMBER, 0.0));
                    }
                    continue;
                }
                n_open += 1;
                let vis = if !self.occlusion {
                    1.0
                } else if fx > 0.0 || bounds {
                    rays += 1;
                    if self.covered(ey, ny, y) {
                        0.0
                    } else {
                        self.vis.between(x, y, ex, ey, &mut last)
                    }
                } else {
                    0.0
                };
                if fx > 0.0 {
                    open |= vis > 0.0;
                    blocked |= vis < 1.0;
                    if vis > 0.0 {
                        // Each pair's point-to-point kernel over the density of its source
                        // point: `cos θ_x / (π p)` drawn by solid angle, the kernel times the
                        // area of the part above x's plane drawn uniformly.
                        let w = match q {
                            _ if !weigh_draw => 1.0,
                            Some(q) if solid => solid_angle_pair_weight(q * f0, x, y, over),
                            _ => {
                                let cell = over * CELL_SHARE / std::f64::consts::PI;
                                over * point_pair_kernel(x, nx, y, ny, cell)
                            }
                        };
                        seen.push((x, y, vis * w));
                        if probe_src.is_none() {
                            probe_src = Some((y, ey));
                        }
                    }
                    recv.push((x, vis > 0.0));
                }
                if recv_member != NO_MEMBER {
                    sampled.push(recv_member);
                }
                vmin = vmin.min(vis);
                vmax = vmax.max(vis);
                fmin = fmin.min(fx);
                fmax = fmax.max(fx);
                let got = fx * vis * q.unwrap_or(1.0);
                sum += got;
                sum_u += fx;
                sum_q += fx * q.unwrap_or(1.0);
                if per_member {
                    members.push((member, got as f32));
                }
                if recv_member != NO_MEMBER && got > 0.0 {
                    recv_open.push((recv_member, got));
                }
            }
        }
        if bounds {
            // Corner points of a surface receiver widen the kernel range (no rays).
            if let End::Surface { v, n: nr, c, .. } = ri {
                let mut f = [0.0; 3];
                Self::point_kernels(&v.map(|p| p + (c - p) * 0.02), nr, &sj, &mut f);
                for f in f {
                    fmin = fmin.min(f);
                    fmax = fmax.max(f);
                }
            }
        }
        // The weights `q` as a ratio: Σ fx·V·q / Σ fx·q times the mean of fx, so that a link
        // whose rays all see the source (or none does) keeps the mean unoccluded kernel of its
        // points (or 0) exactly, and one ray's kernel is its point's kernel or 0: the draw's
        // density, near the kernel's, removes most of the bias, the ratio the rest as rays
        // grow, without the weights' spread (kernels above their points' would give leaves
        // gains above one).
        let ratio = if sum_q > 0.0 { sum_u / sum_q } else { 1.0 };
        let n_open = n_open.max(1) as f64;
        for m in &mut members {
            m.1 = (m.1 as f64 * ratio / n_open) as f32;
        }
        let mut k = sum * ratio / n_open;
        let mut ku = sum_u / n_open;
        if recv_cdf.is_some() && k > 1.0 {
            ku /= k;
            // A surface handed `k·max(0, n_k·d)` cannot get more than a form factor of 1.
            for m in &mut members {
                m.1 /= k as f32;
            }
            k = 1.0;
        }
        if !fmin.is_finite() {
            fmin = 0.0;
        }
        if !self.occlusion {
            return KernelEval {
                k,
                ku,
                est,
                ..Default::default()
            };
        }
        let vr = match ri {
            End::Surface { v, .. } => Some(v),
            _ => None,
        };
        // A source read through its leaves takes each sample's own radiosity already.
        let vs = match sj {
            End::Surface { v, .. } if !source_leaves => Some(v),
            _ => None,
        };
        let (deposit, draw) = deposit_at(vr.as_ref(), vs.as_ref(), &mut recv, &seen, &mut rng);
        // Every ray open into a directional cluster: the hand-out would light all of its
        // children, also those no sample landed on; one ray from each of those tests it.
        let mut hidden_child = false;
        if let (Some(cdf), Some(src), false) = (recv_cdf.as_deref(), probe_src, blocked) {
            let (r, hidden) = self.probe_children(i, j, cdf, &sampled, src);
            rays += r;
            if hidden {
                blocked = true;
                vmin = 0.0;
                hidden_child = true;
            }
        }
        let mixed = open && blocked;
        // The hand-out delivers `k·B·W` over the receiver's open parts (`W = Σ A_s o_s w_s`,
        // `o_s` the open share), of which each of its counted points stands for `W / n`: a
        // surface whose sample saw the source shares its part of the light with the surfaces
        // around it up to that weight (its stratum, [`KernelCtx::hand_out_stratum`]), handed
        // out by weight as a cluster would; its share alone over its area could pour a whole
        // cluster's light on a speck.
        let mut open_members = Vec::new();
        if let (true, Some(cdf)) = (mixed, recv_cdf.as_deref()) {
            let mut lo = 0.0;
            let total_w: f64 = cdf
                .iter()
                .map(|&(id, hi, _)| {
                    let aw = hi - lo;
                    lo = hi;
                    aw * self.elems.open_share(id)
                })
                .sum();
            let received: f64 = recv_open.iter().map(|m| m.1).sum();
            let target = total_w / n_open;
            recv_open.sort_unstable_by_key(|m| m.0);
            let mut strata: SmallVec<[(u32, f64); INLINE]> = SmallVec::new();
            for m in recv_open.chunk_by(|a, b| a.0 == b.0) {
                let id = m[0].0;
                let share = m.iter().map(|m| m.1).sum::<f64>() / received;
                let (at, w) = self.hand_out_stratum(i, id, j, target);
                // A surface takes its irradiance over its open area.
                let per = if at == id {
                    self.elems.elems[id as usize].area as f64 * self.elems.open_share(id)
                } else {
                    w
                };
                // Push-pull delivers nothing to a part it found covered.
                if per > 0.0 {
                    strata.push((at, total_w * share / per));
                }
            }
            strata.sort_unstable_by_key(|m| m.0);
            for m in strata.chunk_by(|a, b| a.0 == b.0) {
                open_members.push((m[0].0, m.iter().map(|m| m.1).sum::<f64>() as f32));
            }
        }
        KernelEval {
            k,
            ku,
            est,
            kmin: fmin * vmin,
            kmax: fmax.max(est) * vmax,
            rays,
            mixed,
            members,
            deposit,
            draw,
            open_members,
            hidden_child,
        }
    }

    /// Area-uniform point on the surfaces inside cluster `node` from two numbers in [0, 1):
    /// `u` picks a surface by descending the hierarchy with area-weighted choices (rescaled at
    /// each level, so stratification of `u` carries over), `(u, v)` then place the point on it.
    fn sample_cluster(&self, node: u32, u: f32, v: f32) -> (Vec3, Vec3, u32) {
        let el = self.elems;
        let mut id = node;
        let mut u = u as f64;
        loop {
            let e = &el.elems[id as usize];
            if e.kind == Kind::Surface || e.num_children == 0 {
                return if e.kind == Kind::Surface {
                    (self.point_on(&e.verts, u as f32, v), e.normal, id)
                } else {
                    (e.centroid, Vec3::ZERO, NO_MEMBER)
                };
            }
            let target = u * e.area as f64;
            let mut acc = 0.0f64;
            let mut pick = (id, 0.0f64, 0.0f64);
            for c in el.children(id) {
                let a = el.elems[c as usize].area as f64;
                if a <= 0.0 {
                    continue;
                }
                pick = (c, acc, a);
                if acc + a > target {
                    break;
                }
                acc += a;
            }
            if pick.0 == id {
                return (e.centroid, Vec3::ZERO, NO_MEMBER);
            }
            u = ((target - pick.1) / pick.2).clamp(0.0, 0.999_999_9);
            id = pick.0;
        }
    }

    /// A cluster receiver's samples land on its surfaces, drawn by hand-out weight, and name
    /// those that saw the source (directional emission with oriented reception).
    pub fn hands_out_by_surface(&self) -> bool {
        self.emission == ClusterEmission::Directional && self.reception == Reception::Oriented
    }

    /// Point `p` of a surface end (its side facing `n`) is covered ([`Covers`]).
    #[inline]
    pub(super) fn covered(&self, end: Endpoint, n: Vec3, p: Vec3) -> bool {
        match end {
            Endpoint::Surface(tri) => self.covers.covered(tri, n, p),
            _ => false,
        }
    }

    /// A sample point of triangle `v` from two numbers in [0, 1), away from its edges by
    /// the visibility's [`Visibility::margin`].
    #[inline]
    pub(super) fn point_on(&self, v: &[Vec3; 3], u1: f32, u2: f32) -> Vec3 {
        sample_triangle_inset(v, u1, u2, self.vis.margin())
    }

    /// For a link from `j` into directional cluster `i` whose rays all saw the source: one
    /// shadow ray from each child of `i` that holds no sampled surface (`sampled`) and has a
    /// positive hand-out weight (its surfaces form one run of `cdf`, drawn from by weight) to
    /// the source end `src` of an open ray. Returns the rays cast and whether one was blocked
    /// (the hand-out would then light a child the source does not see).
    fn probe_children(
        &self,
        i: u32,
        j: u32,
        cdf: &[(u32, f64, f64)],
        sampled: &[u32],
        (y, ey): (Vec3, Endpoint),
    ) -> (u64, bool) {
        let el = self.elems;
        // The child of `i` that surface element `e` lies in.
        let child = |mut e: u32| {
            while el.elems[e as usize].parent != i {
                e = el.elems[e as usize].parent;
            }
            e
        };
        let seen: SmallVec<[u32; INLINE]> = sampled.iter().map(|&e| child(e)).collect();
        let mut rng = SplitMix64::for_item(
            self.seed ^ 0x0C41_D9B0_BE5E_ED00,
            ((i as u64) << 32) | j as u64,
        );
        let mut last = None;
        let (mut rays, mut start) = (0, 0);
        while start < cdf.len() {
            let c = child(cdf[start].0);
            let mut end = start + 1;
            while end < cdf.len() && child(cdf[end].0) == c {
                end += 1;
            }
            if !seen.contains(&c) {
                let lo = if start > 0 { cdf[start - 1].1 } else { 0.0 };
                let target = lo + rng.next_f64() * (cdf[end - 1].1 - lo);
                let k = start + cdf[start..end].partition_point(|&(_, cum, _)| cum <= target);
                let e = &el.elems[cdf[k.min(end - 1)].0 as usize];
                let x = self.point_on(&e.verts, rng.next_f32(), rng.next_f32());
                rays += 1;
                if self
                    .vis
                    .between(x, y, Endpoint::Surface(e.tri), ey, &mut last)
                    <= 0.0
                {
                    return (rays, true);
                }
            }
            start = end;
        }
        (rays, false)
    }
}

/// Per-link sample lists held inline (no allocation) up to this many samples.
pub(super) const INLINE: usize = 16;

/// A link's 2-D sample numbers.
pub(super) type Samples = SmallVec<[[f32; 2]; INLINE]>;

/// Receiver points drawn at most, round by round, for a link whose points all came out
/// covered (a receiver whose open part is a fraction `f` of it is missed with probability
/// `(1 − f)^COVER_POINTS`, whatever the rays per link).
const COVER_POINTS: usize = 64;

/// [`KernelCtx::sample_cluster`] found no surface.
pub(crate) const NO_MEMBER: u32 = crate::link::NO_MEMBER;
