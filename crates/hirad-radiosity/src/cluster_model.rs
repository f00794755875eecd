//! The cluster model: how a cluster element emits and receives, with the formulas of the
//! isotropic (Sillion 1995, the paper's) and the directional (default) emission side by side.
//!
//! - Projected area towards `d` of a cluster of surfaces k (area `A_k`, normal `n_k`, total
//!   `A`, `N = Σ A_k n_k`, `M = Σ A_k n_k n_kᵀ`): isotropic `A/4`; directional the order-2
//!   spherical-harmonic expansion `A/4 + N·d/2 + (5/32)(3 dᵀMd − A)` of `Σ A_k max(0, n_k·d)`
//!   ([`ClusterOrient::projected_area`], within [`SH2_ERROR`]` · A`).
//! - Estimate `F̃` (`point_kernel`): the point-to-disk kernel of that projected area.
//! - Sampled kernel (`KernelCtx::sample_kernel`): isotropic, the estimate at the centre;
//!   directional, a surface k drawn with probability `A_k/A` gives `F(x → k) · A/A_k`, and the
//!   link keeps each sample's surface, whose own radiosity the gather takes.
//! - Hand-out weight ([`hand_out_weight`]): the share of a cluster's irradiance a surface gets:
//!   oriented reception `max(0, n·ŝ)` ([`facing_weight`] when directional), isotropic `1/4`.
//! - Error bound ([`KernelCtx::anisotropy`]): `g = max(0, P_max/P_m − 1)`, the transfer error
//!   per unit `F̃` of the model's projected area `P_m` against the true one.

use crate::config::{ClusterEmission, Reception};
use crate::element::{Element, Kind};
use crate::formfactor::analytic::{point_to_disk, point_to_polygon};
use crate::formfactor::kernel::{End, NO_MEMBER};
use crate::formfactor::near_field::end_sphere;
use crate::formfactor::KernelCtx;
use glam::{DVec3, Vec3};
use hirad_accel::cluster::NONE;
use smallvec::{smallvec, SmallVec};
use std::f64::consts::PI;

/// Largest error of the order-2 spherical-harmonic expansion of `max(0, t)` on [−1, 1]
/// (3/32, at t = 0), per unit area: the bound of [`ClusterOrient::projected_area`].
pub const SH2_ERROR: f64 = 3.0 / 32.0;

/// Orientation summary of the surfaces inside a cluster, used to bound the error of the
/// isotropic cluster model (a cluster's true projected area towards a direction `d` is
/// `Σ A_k max(0, n_k·d)`, which the model replaces by `Σ A_k / 4`).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ClusterOrient {
    /// Area-weighted normal sum `Σ A_k n_k` over the root surface elements inside.
    pub area_normal: Vec3,
    /// Cosine of the half-angle of the cone around `area_normal` that holds every normal
    /// inside (−1 when there is no such cone narrower than the sphere).
    pub cone_cos: f32,
    /// Second moment of the normals `M = Σ A_k n_k n_kᵀ` (xx, yy, zz, xy, xz, yz).
    pub moment: [f32; 6],
}

impl ClusterOrient {
    /// Projected area towards the unit direction `d` of a cluster of total area `area`, from
    /// the spherical-harmonic expansion of `Σ A_k max(0, n_k·d)` to order 2:
    /// `A/4 + N·d/2 + (5/32)(3 dᵀMd − A)`, clamped at zero. Order 0 alone is the isotropic
    /// model's `A/4`; the expansion is exact for the order-0 and order-1 parts (the total
    /// power and its balance between opposite directions), and within `0.094 A` (at grazing
    /// directions of a flat cluster) of the true projected area.
    #[inline]
    pub fn projected_area(&self, area: f64, d: DVec3) -> f64 {
        let m = self.moment.map(|v| v as f64);
        let dmd = m[0] * d.x * d.x
            + m[1] * d.y * d.y
            + m[2] * d.z * d.z
            + 2.0 * (m[3] * d.x * d.y + m[4] * d.x * d.z + m[5] * d.y * d.z);
        let p = 0.25 * area
            + 0.5 * self.area_normal.as_dvec3().dot(d)
            + (5.0 / 32.0) * (3.0 * dmd - area);
        p.max(0.0)
    }
}

/// Orientation summaries of the clusters `0..nc`: area-weighted normal sums bottom-up, then
/// the widest angle between each cluster's mean normal and the normal of any root surface
/// inside (every root surface walks up its cluster ancestors).
pub(crate) fn cluster_orientation(elems: &[Element], kids: &[u32], nc: u32) -> Vec<ClusterOrient> {
    let mut sum = vec![DVec3::ZERO; nc as usize];
    let mut mom = vec![[0f64; 6]; nc as usize];
    for id in (0..nc as usize).rev() {
        let e = &elems[id];
        let mut acc = DVec3::ZERO;
        let mut m = [0f64; 6];
        for &k in &kids[e.first_child as usize..(e.first_child + e.num_children) as usize] {
            if k < nc {
                acc += sum[k as usize];
                for (a, b) in m.iter_mut().zip(&mom[k as usize]) {
                    *a += b;
                }
            } else {
                let s = &elems[k as usize];
                let a = s.area as f64;
                let n = s.normal.as_dvec3();
                acc += n * a;
                let t = [
                    n.x * n.x,
                    n.y * n.y,
                    n.z * n.z,
                    n.x * n.y,
                    n.x * n.z,
                    n.y * n.z,
                ];
                for (mm, v) in m.iter_mut().zip(t) {
                    *mm += a * v;
                }
            }
        }
        sum[id] = acc;
        mom[id] = m;
    }
    let axis: Vec<DVec3> = (0..nc as usize)
        .map(|id| {
            let a = elems[id].area as f64;
            let l = sum[id].length();
            if a > 0.0 && l > 1e-6 * a {
                sum[id] / l
            } else {
                DVec3::ZERO
            }
        })
        .collect();
    let mut cos_min = vec![1.0f64; nc as usize];
    for s in &elems[nc as usize..] {
        if s.kind != Kind::Surface || s.level != 0 {
            continue;
        }
        let n = s.normal.as_dvec3();
        let mut c = s.parent;
        while c != NONE && c < nc {
            let ax = axis[c as usize];
            let v = if ax == DVec3::ZERO { -1.0 } else { n.dot(ax) };
            cos_min[c as usize] = cos_min[c as usize].min(v);
            c = elems[c as usize].parent;
        }
    }
    (0..nc as usize)
        .map(|id| ClusterOrient {
            area_normal: sum[id].as_vec3(),
            // Rounding margin, so that the cone holds its normals in f32.
            cone_cos: (cos_min[id] - 1e-5).max(-1.0) as f32,
            moment: mom[id].map(|v| v as f32),
        })
        .collect()
}

/// Share `max(0, n·ŝ)` of a cluster's received irradiance that a surface (centroid, normal)
/// gets from a source at `src_centroid` under the directional cluster model: `ŝ` points from
/// the surface's centroid to the source's, and nothing reaches a surface from behind a surface
/// source (`src_normal`: the source's normal, zero for a cluster source), which keeps the back
/// faces of two-sided surfaces from receiving what their front faces get.
#[inline(always)]
pub fn facing_weight(centroid: Vec3, normal: Vec3, src_centroid: Vec3, src_normal: Vec3) -> f64 {
    let to = src_centroid - centroid;
    let c = normal.dot(to);
    if src_normal.dot(to) > 0.0 || c <= 0.0 {
        return 0.0;
    }
    (c / to.length()) as f64
}

impl Element {
    /// Share of a cluster's received irradiance that this surface gets from source `src`
    /// under the directional cluster model ([`facing_weight`]).
    #[inline]
    pub fn facing_weight(&self, src: &Element) -> f64 {
        facing_weight(
            self.centroid,
            self.normal,
            src.centroid,
            src.facing_normal(),
        )
    }

    /// The normal for [`facing_weight`]: a surface's own, zero for a cluster.
    #[inline]
    pub fn facing_normal(&self) -> Vec3 {
        match self.kind {
            Kind::Surface => self.normal,
            Kind::Cluster => Vec3::ZERO,
        }
    }
}

/// Share of a cluster's received irradiance `H` that its surface (centroid, normal `n`) gets
/// from one link's source (unit direction `d` from the cluster's centroid to the source's,
/// source centroid `sc` and [`Element::facing_normal`] `sn`).
#[inline(always)]
pub fn hand_out_weight(
    reception: Reception,
    emission: ClusterEmission,
    (centroid, n): (Vec3, Vec3),
    d: Vec3,
    (sc, sn): (Vec3, Vec3),
) -> f64 {
    match (reception, emission) {
        (Reception::Oriented, ClusterEmission::Directional) => facing_weight(centroid, n, sc, sn),
        (Reception::Oriented, ClusterEmission::Isotropic) => n.dot(d).max(0.0) as f64,
        (Reception::Isotropic, _) => 0.25,
    }
}

/// Unoccluded kernel at receiver point `x` (normal `n`, `None` for a cluster receiver, which
/// faces the source) of a cluster source with centre `c` and total area `area`: the
/// point-to-disk kernel of its projected area towards `x` (`orient`: directional model;
/// `sample_normal`: the normal of the surface at a sampled point `c`).
pub(crate) fn point_kernel(
    xd: DVec3,
    n: Option<Vec3>,
    c: Vec3,
    area: f64,
    orient: Option<ClusterOrient>,
    sample_normal: Option<Vec3>,
) -> f64 {
    let d = c.as_dvec3() - xd;
    let r2 = d.length_squared();
    let proj = match (sample_normal, orient) {
        (Some(ny), Some(_)) if r2 > 0.0 => area * (-ny.as_dvec3().dot(d) / r2.sqrt()).max(0.0),
        (_, Some(o)) if r2 > 0.0 => o.projected_area(area, -d / r2.sqrt()),
        _ => area * 0.25,
    };
    let cos_r = match n {
        Some(n) => {
            if r2 <= 0.0 {
                return 0.0;
            }
            n.as_dvec3().dot(d) / r2.sqrt()
        }
        None => 1.0,
    };
    point_to_disk(r2, cos_r, 1.0, proj)
}

impl KernelCtx<'_> {
    /// Bound `g` on the under-estimate of the cluster emission model of source `j` as seen
    /// from receiver `i`: the projected area of a cluster towards a direction `d` is
    /// `P(d) = Σ A_k max(0, n_k·d)`, the model uses `P_m` (`ΣA/4` isotropic, the order-2
    /// expansion towards the receiver's centre when directional), so its transfer error is at
    /// most `g · F̃` with `g = max(0, P_max / P_m − 1)`, `P_max` an upper bound of `P(d)` over
    /// the directions from the source's bounding sphere to the receiver's. `P_max` is the
    /// smaller of `(ΣA + |N| cos⁺(θ − δ)) / 2` (because `Σ A_k |n_k·d| ≤ ΣA`, `N = Σ A_k n_k`)
    /// and the normal-cone bound `ΣA cos⁺(θ − α − δ)` (θ: angle between `N` and the direction,
    /// α: cone half-angle, δ: half-angle of the direction cone). Isotropic: a flat cluster
    /// facing the receiver gives `g = 3` (it shows 4× the isotropic area), a cloud of random
    /// normals `g ≤ 1`. Directional: large only when the direction cone is wide (near
    /// clusters) or the centre direction grazes the cluster. Zero for surface sources.
    pub fn anisotropy(&self, i: u32, j: u32) -> f64 {
        let e = &self.elems.elems[j as usize];
        if e.kind != Kind::Cluster || e.area <= 0.0 {
            return 0.0;
        }
        let o = self.elems.orient[j as usize];
        let (cs, rs) = end_sphere(&self.end(j));
        let (cr, rr) = end_sphere(&self.end(i));
        let d = cr - cs;
        let dist = d.length();
        let delta = if dist > rs + rr {
            ((rs + rr) / dist).asin()
        } else {
            PI / 2.0
        };
        let a = e.area as f64;
        let nv = o.area_normal.as_dvec3();
        let nl = nv.length();
        let theta = if nl > 0.0 && dist > 0.0 {
            (nv.dot(d) / (nl * dist)).clamp(-1.0, 1.0).acos()
        } else {
            PI / 2.0
        };
        let mut p = 0.5 * (a + nl * (theta - delta).max(0.0).cos());
        if o.cone_cos > -1.0 {
            let alpha = (o.cone_cos as f64).acos();
            let t = (theta - alpha - delta).max(0.0);
            p = p.min(if t < PI / 2.0 { a * t.cos() } else { 0.0 });
        }
        let model = match self.emission {
            ClusterEmission::Isotropic => 0.25 * a,
            ClusterEmission::Directional if dist > 0.0 => o.projected_area(a, d / dist),
            ClusterEmission::Directional => 0.25 * a,
        };
        (p / model.max(1e-9 * a) - 1.0).max(0.0)
    }

    /// Unoccluded kernel sample at receiver point `x` (normal `n`) for source `src` whose
    /// sample point lies on surface element `member`. For a directional cluster source the
    /// member is drawn with probability `A_k / A`, so `F(x → k) · A / A_k` with the analytic
    /// point-to-polygon form factor is an unbiased estimate of the form factor of the
    /// cluster's contents.
    pub(crate) fn sample_kernel(&self, x: Vec3, n: Vec3, src: &End, member: u32) -> f64 {
        match *src {
            End::Cluster {
                area,
                orient: Some(_),
                ..
            } if member != NO_MEMBER => {
                let e = &self.elems.elems[member as usize];
                let ak = e.area as f64;
                if ak <= 0.0 {
                    return 0.0;
                }
                let poly = e.verts.map(|p| p.as_dvec3());
                point_to_polygon(x.as_dvec3(), n.as_dvec3(), &poly, e.normal.as_dvec3()) * area / ak
            }
            _ => Self::point_kernel(x, Some(n), src),
        }
    }

    /// The surfaces inside cluster `node` with a positive hand-out weight `w_k` towards source
    /// element `src` ([`Element::facing_weight`]): `(surface, running sum of A_k·w_k, w_k)`.
    ///
    /// [`Element::facing_weight`]: super::element::Element::facing_weight
    pub(crate) fn hand_out_cdf(&self, node: u32, src: u32) -> Vec<(u32, f64, f64)> {
        let el = self.elems;
        let se = &el.elems[src as usize];
        let mut out = Vec::new();
        let mut stack: SmallVec<[u32; 64]> = smallvec![node];
        let mut acc = 0.0f64;
        while let Some(id) = stack.pop() {
            for c in el.children(id) {
                let e = &el.elems[c as usize];
                match e.kind {
                    Kind::Cluster => stack.push(c),
                    Kind::Surface => {
                        let w = e.facing_weight(se);
                        if w > 0.0 {
                            acc += e.area as f64 * w;
                            out.push((c, acc, w));
                        }
                    }
                }
            }
        }
        out
    }

    /// The part of directional cluster receiver `recv` that one sample on its surface `member`
    /// stands for when it alone saw source `src`: the lowest of `member` and its ancestors
    /// below `recv` whose open hand-out weight `W = Σ A_k o_k w_k` (`o_k` the open share)
    /// reaches `target` (the receiver's `W` over its samples), or the child of `recv` above
    /// `member` when none does. Returns it with its `W`.
    pub fn hand_out_stratum(&self, recv: u32, member: u32, src: u32, target: f64) -> (u32, f64) {
        let el = self.elems;
        let se = &el.elems[src as usize];
        let (mut at, mut w) = (member, self.open_weight(member, se));
        while w < target {
            let p = el.elems[at as usize].parent;
            if p == recv || p == NONE {
                break;
            }
            for c in el.children(p) {
                if c != at {
                    w += self.hand_out_total(c, se);
                }
            }
            at = p;
        }
        (at, w)
    }

    /// `Σ A_k o_k w_k` over the surfaces at or below cluster-tree element `id` towards `src`.
    fn hand_out_total(&self, id: u32, src: &Element) -> f64 {
        let el = self.elems;
        let mut w = 0.0;
        let mut stack: SmallVec<[u32; 64]> = smallvec![id];
        while let Some(id) = stack.pop() {
            match el.elems[id as usize].kind {
                Kind::Cluster => stack.extend(el.children(id)),
                Kind::Surface => w += self.open_weight(id, src),
            }
        }
        w
    }

    /// `A_k o_k w_k` of surface `id` towards `src`: its open area times its hand-out weight.
    pub(crate) fn open_weight(&self, id: u32, src: &Element) -> f64 {
        let e = &self.elems.elems[id as usize];
        e.area as f64 * self.elems.open_share(id) * e.facing_weight(src)
    }
}
