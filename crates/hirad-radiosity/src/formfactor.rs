//! Form factors: the point-to-disk estimate, the analytic point-to-polygon form factor
//! (Lambert's contour integral, as in Nusselt's analogy), stratified sampling of triangles and
//! boxes, and the sampled link kernels of the solver ([`KernelCtx`]).
//!
//! All kernels are expressed as form factors from the receiver to the source (dimensionless):
//! the irradiance a receiver gathers from a source of radiosity `B_j` is `K_ij · B_j`.
//!
//! Cluster sources ([`ClusterEmission`]):
//! - isotropic (Sillion 1995, the paper's model): a cluster of total area `A` shows the
//!   projected area `A/4` in every direction from its centre, so its kernel towards a point is
//!   the disk estimate with `cos θ_j = 1` and area `A/4`. In a closed scene every cluster lies on
//!   the enclosure and sends half of that to where no surface is: furnaces come out 20–40% dark.
//! - directional (default): each sample picks a surface k of the cluster with probability
//!   `A_k / A` and takes the analytic form factor to it times `A / A_k`, a Monte Carlo estimate
//!   of the form factor of the cluster's contents; the link keeps each sample's surface and
//!   share, so the gather takes the sampled surfaces' own radiosity
//!   ([`KernelEval::members`]). The oracle's estimate uses the order-2 spherical-harmonic
//!   projected area (`ClusterOrient::projected_area`).
//!
//! Surface pairs closer than the receiver's diameter integrate the unoccluded form factor on
//! a jittered grid (spacing about the gap, half of it for links the hierarchy cannot resolve),
//! on the source when it is the smaller end (reciprocity); points of a triangle that a
//! coplanar one covers ([`Covers`]) neither receive nor emit. A subdivided surface source whose
//! radiosity varies may keep the leaf under each sample, as directional clusters keep their
//! sampled surfaces.
//!
//! Cluster receivers: isotropic clusters (and isotropic reception) take the kernel at the
//! centre, facing the source (`spec/radiosity.md`); a directional cluster with oriented
//! reception samples its surfaces in proportion to their hand-out weights (see
//! [`KernelCtx::evaluate_with`]). Shadow rays of cluster ends start from points on their
//! surfaces and leave out only those surfaces (directional) or the whole cluster (isotropic).

use super::config::{ClusterEmission, Reception};
use super::element::{quad_path, ClusterOrient, Elements, Kind};
use super::link::Deposit;
use super::overlap::Covers;
use super::visibility::Visibility;
use glam::{DVec3, Vec3};
use hirad_accel::cluster::ClusterTree;
use hirad_accel::ray::volume::Endpoint;
use hirad_core::rng::SplitMix64;
use std::f64::consts::PI;

/// Largest error of the order-2 spherical-harmonic expansion of `max(0, t)` on [−1, 1]
/// (3/32, at t = 0), per unit area: the bound of [`ClusterOrient::projected_area`].
pub const SH2_ERROR: f64 = 3.0 / 32.0;

/// Point-to-disk estimate of the form factor from a differential area to a disk of area
/// `area` at squared distance `r2`: `A cos θ_r cos θ_s / (π r² + A)` (zero when either cosine
/// is not positive). Exact for a coaxial, parallel disk.
#[inline]
pub fn point_to_disk(r2: f64, cos_r: f64, cos_s: f64, area: f64) -> f64 {
    if cos_r <= 0.0 || cos_s <= 0.0 {
        return 0.0;
    }
    area * cos_r * cos_s / (PI * r2 + area)
}

/// Closed-form form factor from a differential area to a parallel disk of radius `radius` at
/// height `h`, the receiving point offset by `a` from the disk axis (both facing each other).
pub fn parallel_disk_exact(h: f64, a: f64, radius: f64) -> f64 {
    let (h2, a2, r2) = (h * h, a * a, radius * radius);
    let z = h2 + a2 + r2;
    0.5 * (1.0 - (z - 2.0 * r2) / (z * z - 4.0 * a2 * r2).sqrt())
}

/// `atan2(y, x)` for `y ≥ 0` (an angle in [0, π]), to about 2 ulp: the Cephes rational
/// approximation of `atan` with its range reduction. The form factor kernel spends most of its
/// time here, and libm's correctly rounded `atan2` is several times slower.
#[inline]
pub fn angle_from(y: f64, x: f64) -> f64 {
    const P: [f64; 5] = [
        -8.750_608_600_031_904e-1,
        -1.615_753_718_733_365e1,
        -7.500_855_792_314_705e1,
        -1.228_866_684_490_136e2,
        -6.485_021_904_942_025e1,
    ];
    const Q: [f64; 5] = [
        2.485_846_490_142_306e1,
        1.650_270_098_316_988_5e2,
        4.328_810_604_912_903e2,
        4.853_903_996_359_137e2,
        1.945_506_571_482_614e2,
    ];
    const T3P8: f64 = 2.414_213_562_373_095; // tan(3π/8)
    const MOREBITS: f64 = 6.123_233_995_736_766e-17; // π/2 − fl(π/2)
    if y == 0.0 {
        return if x < 0.0 { PI } else { 0.0 };
    }
    if x == 0.0 {
        return PI / 2.0;
    }
    let r = y / x.abs();
    let (y0, z, more) = if r > T3P8 {
        (PI / 2.0, -1.0 / r, MOREBITS)
    } else if r <= 0.66 {
        (0.0, r, 0.0)
    } else {
        (PI / 4.0, (r - 1.0) / (r + 1.0), 0.5 * MOREBITS)
    };
    let zz = z * z;
    let p = (((P[0] * zz + P[1]) * zz + P[2]) * zz + P[3]) * zz + P[4];
    let q = ((((zz + Q[0]) * zz + Q[1]) * zz + Q[2]) * zz + Q[3]) * zz + Q[4];
    let t = y0 + (z * zz * p / q + more) + z;
    if x < 0.0 {
        PI - t
    } else {
        t
    }
}

/// Analytic form factor from a differential area at `x` with unit normal `n` to the planar
/// convex polygon `poly` (counter-clockwise around `poly_normal`, its emitting side).
///
/// The polygon is clipped to the hemisphere above `x`; zero when `x` lies behind the polygon
/// (one-sided emission) or the polygon is entirely below the receiver's horizon.
pub fn point_to_polygon(x: DVec3, n: DVec3, poly: &[DVec3], poly_normal: DVec3) -> f64 {
    if poly.len() < 3 || (x - poly[0]).dot(poly_normal) <= 0.0 {
        return 0.0;
    }
    let mut buf = [DVec3::ZERO; 16];
    // Clipped only when part of it lies below the horizon (the polygon as it is otherwise).
    let pts: &[DVec3] = if poly.iter().all(|&p| n.dot(p - x) >= 0.0) {
        poly
    } else {
        let m = clip_to_hemisphere(x, n, poly, &mut buf);
        if m < 3 {
            return 0.0;
        }
        &buf[..m]
    };
    let m = pts.len();
    let mut sum = 0.0;
    for e in 0..m {
        let a = pts[e] - x;
        let b = pts[(e + 1) % m] - x;
        let c = a.cross(b);
        let cl = c.length();
        if cl <= 0.0 {
            continue;
        }
        let theta = angle_from(cl, a.dot(b));
        sum += theta * c.dot(n) / cl;
    }
    (sum.abs() / (2.0 * PI)).min(1.0)
}

/// The part of the convex polygon `poly` above the plane through `x` with normal `n`
/// (Sutherland–Hodgman), written to `clipped`: the number of its corners (below 3: nothing is
/// above).
fn clip_to_hemisphere(x: DVec3, n: DVec3, poly: &[DVec3], clipped: &mut [DVec3; 16]) -> usize {
    let mut m = 0usize;
    let k = poly.len().min(15);
    for e in 0..k {
        let a = poly[e];
        let b = poly[(e + 1) % k];
        let da = n.dot(a - x);
        let db = n.dot(b - x);
        if da >= 0.0 {
            clipped[m] = a;
            m += 1;
        }
        if (da >= 0.0) != (db >= 0.0) && m < 16 {
            let t = da / (da - db);
            clipped[m] = a + (b - a) * t;
            m += 1;
        }
    }
    m
}

/// Area-uniform point, from two uniform numbers in [0, 1), of the part of triangle `v` that
/// lies above the plane through `x` with normal `n`; `None` when no part of it does. A shadow
/// ray from `x` is aimed at the part of the source that its kernel counts.
pub fn sample_triangle_above(x: Vec3, n: Vec3, v: &[Vec3; 3], u1: f32, u2: f32) -> Option<Vec3> {
    let xd = x.as_dvec3();
    let nd = n.as_dvec3();
    if v.iter().all(|p| nd.dot(p.as_dvec3() - xd) >= 0.0) {
        return Some(sample_triangle(v, u1, u2));
    }
    let mut c = [DVec3::ZERO; 16];
    let m = clip_to_hemisphere(xd, nd, &v.map(|p| p.as_dvec3()), &mut c);
    if m < 3 {
        return None;
    }
    // Pick a triangle of the fan (c0, ci, ci+1) by area, then a point on it.
    let areas: Vec<f64> = (1..m - 1)
        .map(|i| (c[i] - c[0]).cross(c[i + 1] - c[0]).length())
        .collect();
    let total: f64 = areas.iter().sum();
    if total <= 0.0 {
        return None;
    }
    let mut target = u1 as f64 * total;
    let mut i = 0;
    while i + 1 < areas.len() && target >= areas[i] {
        target -= areas[i];
        i += 1;
    }
    let u = (target / areas[i].max(1e-300)).clamp(0.0, 0.999_999_9) as f32;
    let t = [c[0], c[i + 1], c[i + 2]].map(|p| p.as_vec3());
    Some(sample_triangle(&t, u, u2))
}

/// Point of a triangle from two uniform numbers in [0, 1) (area-uniform warp).
#[inline]
pub fn sample_triangle(v: &[Vec3; 3], u1: f32, u2: f32) -> Vec3 {
    let s = u1.sqrt();
    let b0 = 1.0 - s;
    let b1 = s * (1.0 - u2);
    let b2 = s * u2;
    v[0] * b0 + v[1] * b1 + v[2] * b2
}

/// `n` stratified (Latin hypercube) jittered 2-D samples in [0, 1)².
pub fn stratified_2d(n: usize, rng: &mut SplitMix64, out: &mut Vec<[f32; 2]>) {
    out.clear();
    let mut perm: Vec<usize> = (0..n).collect();
    for i in (1..n).rev() {
        let j = (rng.next_u64() % (i as u64 + 1)) as usize;
        perm.swap(i, j);
    }
    let inv = 1.0 / n as f32;
    for (k, &p) in perm.iter().enumerate() {
        let u = ((k as f32 + rng.next_f32()) * inv).min(0.999_999_9);
        let v = ((p as f32 + rng.next_f32()) * inv).min(0.999_999_9);
        out.push([u, v]);
    }
}

/// `k × k` jittered 2-D samples in [0, 1)², one per cell of a regular grid: stratified in
/// both dimensions together, unlike [`stratified_2d`], whose error on a function peaked in a
/// small region (a receiver close above a source) is that of plain Monte Carlo.
pub fn jittered_grid(k: usize, rng: &mut SplitMix64, out: &mut Vec<[f32; 2]>) {
    out.clear();
    let inv = 1.0 / k as f32;
    for i in 0..k {
        for j in 0..k {
            let u = ((i as f32 + rng.next_f32()) * inv).min(0.999_999_9);
            let v = ((j as f32 + rng.next_f32()) * inv).min(0.999_999_9);
            out.push([u, v]);
        }
    }
}

/// Samples and bounds of a link kernel.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct KernelEval {
    /// The kernel with visibility (form factor receiver → source).
    pub k: f64,
    /// Unoccluded estimate `F̃` (the `bf` oracle's quantity, per unit source radiosity).
    pub est: f64,
    /// Lower and upper kernel bounds (with visibility bounds), for the `error` oracle.
    pub kmin: f64,
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
    /// Surface receiver whose rays disagree: where the transfer lands ([`Deposit`]).
    pub deposit: Deposit,
    /// Surface source whose rays disagree: where the transfer leaves from ([`Deposit`]).
    pub draw: Deposit,
}

/// Where a mixed link's transfer lands on a surface receiver (vertices `vr`) and where a
/// surface source (`vs`) sends it from: up to [`Deposit::POINTS`] of the sample pairs
/// (receiver point, source point) whose rays were open, drawn evenly among them.
fn deposit_at(
    vr: Option<&[Vec3; 3]>,
    vs: Option<&[Vec3; 3]>,
    seen: &mut [(Vec3, Vec3)],
    rng: &mut SplitMix64,
) -> (Deposit, Deposit) {
    let c = seen.len().min(Deposit::POINTS);
    for i in 0..c {
        let j = i + (rng.next_u64() % (seen.len() - i) as u64) as usize;
        seen.swap(i, j);
    }
    let paths = |v: Option<&[Vec3; 3]>, end: fn(&(Vec3, Vec3)) -> Vec3| -> Deposit {
        v.map_or(Deposit::default(), |v| {
            let p: Vec<u32> = seen[..c]
                .iter()
                .map(|s| quad_path(v, end(s), Deposit::LEVELS))
                .collect();
            Deposit::new(&p)
        })
    };
    (paths(vr, |s| s.0), paths(vs, |s| s.1))
}

/// Everything needed to evaluate link kernels.
#[derive(Clone, Copy)]
pub struct KernelCtx<'a> {
    pub elems: &'a Elements,
    pub tree: &'a ClusterTree,
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
}

/// Geometry of one end of a link.
#[derive(Clone, Copy)]
enum End {
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
    fn endpoint(&self) -> Endpoint {
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

impl<'a> KernelCtx<'a> {
    fn end(&self, id: u32) -> End {
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
    fn point_kernel(x: Vec3, n: Option<Vec3>, src: &End) -> f64 {
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
            } => {
                let d = c.as_dvec3() - xd;
                let r2 = d.length_squared();
                let proj = match (sample_normal, orient) {
                    (Some(ny), Some(_)) if r2 > 0.0 => {
                        area * (-ny.as_dvec3().dot(d) / r2.sqrt()).max(0.0)
                    }
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
        }
    }

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

    /// Upper bound of the unoccluded kernel of a link with a cluster end whose bounding
    /// spheres (centres `d` apart, radii `r_i`, `r_j`) are closer than the larger radius,
    /// where the centroid estimate is a far-field approximation that misses members next to
    /// the other end; zero otherwise, and for two surfaces (whose estimate already takes the
    /// receiver's point nearest the source). From any receiving point, the form factor to surfaces of
    /// total area `A_j` at least `g = d − r_i − r_j` away is at most `A_j / (π g²)`, and to
    /// anything inside a sphere of radius `r_j` whose centre is `D ≥ d − r_i` away at most
    /// `r_j² / D²` (the sphere's projected disk).
    pub fn near_bound(&self, i: u32, j: u32) -> f64 {
        let (ri, sj) = (self.end(i), self.end(j));
        if matches!((ri, sj), (End::Surface { .. }, End::Surface { .. })) {
            return 0.0;
        }
        let (ci, r_i) = end_sphere(&ri);
        let (cj, r_j) = end_sphere(&sj);
        let d = ci.distance(cj);
        let g = d - r_i - r_j;
        if g >= r_i.max(r_j) {
            return 0.0;
        }
        let a_j = self.elems.elems[j as usize].area as f64;
        let mut bound = 1.0f64;
        if g > 0.0 {
            bound = bound.min(a_j / (PI * g * g));
        }
        let dd = d - r_i;
        if dd > r_j {
            bound = bound.min(r_j * r_j / (dd * dd));
        }
        bound
    }

    /// Cheap unoccluded estimate `F̃` (no rays): the maximum of the point kernel at the
    /// receiver's centroid and (slightly inset) corners.
    pub fn estimate(&self, i: u32, j: u32) -> f64 {
        match self.end(i) {
            End::Surface { .. } => self.spread(i, j).1,
            End::Cluster { c, .. } => Self::point_kernel(c, None, &self.end(j)),
        }
    }

    /// True when receiver `i` and source `j` are surfaces closer than the receiver's size, whose
    /// kernel [`KernelCtx::near_field`] integrates (it keeps no per-sample leaves).
    pub fn is_near_field(&self, i: u32, j: u32) -> bool {
        let n = self.n_rays.max(1);
        near_field_points(&self.end(i), &self.end(j), n, false) > n
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
        let mut lo = Self::point_kernel(c, Some(n), &sj);
        let mut hi = lo;
        for p in v.into_iter().chain([near]) {
            let f = Self::point_kernel(p + (c - p) * 0.05, Some(n), &sj);
            lo = lo.min(f);
            hi = hi.max(f);
        }
        (lo, hi)
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
        let mut su = Vec::with_capacity(n);
        let mut sv = Vec::with_capacity(n);
        stratified_2d(n, &mut rng, &mut su);
        stratified_2d(n, &mut rng, &mut sv);
        let est = est.unwrap_or_else(|| self.estimate(i, j));
        if let (End::Surface { .. }, End::Surface { .. }) = (ri, sj) {
            let m = near_field_points(&ri, &sj, n, fine);
            if m > n {
                return self.near_field(&ri, &sj, m, n, est, &mut rng);
            }
        }
        let mut sum = 0.0;
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
        // Directional cluster receiver with oriented reception: its surfaces k with their
        // hand-out weights w_k (`facing_weight`) as a cumulative distribution of A_k·w_k; a
        // surface drawn from it contributes E(x)/w_k, whose mean is Σ A_k E_k / Σ A_k w_k, the
        // irradiance that the hand-out `H·w_k` must carry to deliver the received power.
        let recv_cdf = match ri {
            End::Cluster { node, .. }
                if self.emission == ClusterEmission::Directional
                    && self.reception == Reception::Oriented =>
            {
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
        let mut n_open = 0usize;
        // (receiver point, source point) of the samples whose rays were open.
        let mut seen = Vec::new();
        for s in 0..n {
            // Source sample point. A directional cluster source is the projected area of the
            // sampled surface (its own normal) at that point, so that the kernel converges to
            // the form factor of the cluster's contents; an isotropic one stays at its centre.
            let mut member = NO_MEMBER;
            let (y, ny) = match sj {
                End::Surface { v, n, .. } => (sample_triangle(&v, sv[s][0], sv[s][1]), n),
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
            let ey = match sj {
                End::Cluster {
                    orient: Some(_), ..
                } if member != NO_MEMBER => {
                    Endpoint::Surface(self.elems.elems[member as usize].tri)
                }
                _ => sj.endpoint(),
            };
            let (x, fx, nx) = match (ri, recv_cdf.as_deref()) {
                (End::Surface { v, n: nr, .. }, _) => {
                    let x = sample_triangle(&v, su[s][0], su[s][1]);
                    (x, self.sample_kernel(x, nr, &src, member), Some(nr))
                }
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
                    let x = sample_triangle(&e.verts, u as f32, su[s][1]);
                    let fx = self.sample_kernel(x, e.normal, &src, member) / w;
                    ex = Endpoint::Surface(e.tri);
                    (x, fx, Some(e.normal))
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
                    (x, k, None)
                }
            };
            // A surface source's kernel at x counts the part of it above x's plane: aim the
            // shadow ray there (a ray to a point behind x could pass where the counted part is
            // hidden, e.g. from inside a thin slab to a desk the slab stands on).
            let y = match (sj, nx) {
                (End::Surface { v, .. }, Some(nr)) => {
                    sample_triangle_above(x, nr, &v, sv[s][0], sv[s][1]).unwrap_or(y)
                }
                (
                    End::Cluster {
                        orient: Some(_), ..
                    },
                    Some(nr),
                ) if member != NO_MEMBER => {
                    let v = self.elems.elems[member as usize].verts;
                    sample_triangle_above(x, nr, &v, sv[s][1], sv[s][0]).unwrap_or(y)
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
            let vis = if fx > 0.0 || bounds {
                rays += 1;
                if self.covered(ey, ny, y) {
                    0.0
                } else {
                    self.segment(x, ex, y, ey)
                }
            } else {
                0.0
            };
            if fx > 0.0 {
                open |= vis > 0.0;
                blocked |= vis < 1.0;
                if vis > 0.0 {
                    seen.push((x, y));
                }
            }
            vmin = vmin.min(vis);
            vmax = vmax.max(vis);
            fmin = fmin.min(fx);
            fmax = fmax.max(fx);
            sum += fx * vis;
            if per_member {
                members.push((member, (fx * vis) as f32));
            }
        }
        if bounds {
            // Corner points of a surface receiver widen the kernel range (no rays).
            if let End::Surface { v, n: nr, c, .. } = ri {
                for p in v {
                    let f = Self::point_kernel(p + (c - p) * 0.02, Some(nr), &sj);
                    fmin = fmin.min(f);
                    fmax = fmax.max(f);
                }
            }
        }
        let n_open = n_open.max(1) as f64;
        for m in &mut members {
            m.1 = (m.1 as f64 / n_open) as f32;
        }
        let mut k = sum / n_open;
        if recv_cdf.is_some() && k > 1.0 {
            // A surface handed `k·max(0, n_k·d)` cannot get more than a form factor of 1.
            for m in &mut members {
                m.1 /= k as f32;
            }
            k = 1.0;
        }
        if !fmin.is_finite() {
            fmin = 0.0;
        }
        let (deposit, draw) = if open && blocked {
            let vr = match ri {
                End::Surface { v, .. } => Some(v),
                _ => None,
            };
            // A source read through its leaves takes each sample's own radiosity already.
            let vs = match sj {
                End::Surface { v, .. } if !source_leaves => Some(v),
                _ => None,
            };
            deposit_at(vr.as_ref(), vs.as_ref(), &mut seen, &mut rng)
        } else {
            Default::default()
        };
        KernelEval {
            k,
            est,
            kmin: fmin * vmin,
            kmax: fmax.max(est) * vmax,
            rays,
            mixed: open && blocked,
            members,
            deposit,
            draw,
        }
    }

    /// Kernel of a surface receiver close to a surface source (closer than its own size): the
    /// unoccluded form factor varies over the receiver on the scale of the gap, so it is
    /// integrated over a jittered grid of `m` points (analytic point-to-polygon, no rays), and
    /// the `n` shadow rays start from points drawn among them in proportion to their form
    /// factor: the kernel is `F_u ×` the visible share of the form factor. When the source is
    /// the smaller end and no part of the receiver is covered, the grid lies on the source and
    /// `F_u = A_s/A_r · mean F(y → receiver)` (reciprocity): seen from a small source, a large
    /// receiver close to it fills a smooth part of the hemisphere, while seen from the
    /// receiver, the small source is a peak a grid resolves poorly.
    fn near_field(
        &self,
        ri: &End,
        sj: &End,
        m: usize,
        n: usize,
        est: f64,
        rng: &mut SplitMix64,
    ) -> KernelEval {
        let (
            End::Surface {
                v: vr,
                n: nr,
                area: ar,
                tri: tr,
                ..
            },
            End::Surface {
                v: vs,
                n: ns,
                area: as_,
                ..
            },
        ) = (*ri, *sj)
        else {
            unreachable!("near_field takes two surfaces")
        };
        let reciprocal = as_ < ar && self.covers.all_open(tr);
        // Grid end (`g`) and the other end (`o`) with their endpoints for the rays.
        let (gv, gn, ge, ov, on, oe) = if reciprocal {
            (vs, ns, sj.endpoint(), vr, nr, ri.endpoint())
        } else {
            (vr, nr, ri.endpoint(), vs, ns, sj.endpoint())
        };
        let k = (m as f64).sqrt().ceil() as usize;
        let m = k * k;
        let mut pts = Vec::with_capacity(m);
        jittered_grid(k, rng, &mut pts);
        let xs: Vec<Vec3> = pts
            .iter()
            .map(|u| sample_triangle(&gv, u[0], u[1]))
            .collect();
        let other = End::Surface {
            v: ov,
            n: on,
            c: (ov[0] + ov[1] + ov[2]) / 3.0,
            area: 0.0,
            tri: 0,
        };
        let mut cdf = Vec::with_capacity(m);
        let (mut acc, mut fmin, mut fmax) = (0.0f64, f64::INFINITY, 0.0f64);
        let mut n_open = 0usize;
        for &x in &xs {
            // Covered points are not part of their end (zero weight in the cdf below).
            let f = if self.covered(ge, gn, x) {
                0.0
            } else {
                n_open += 1;
                Self::point_kernel(x, Some(gn), &other)
            };
            fmin = fmin.min(f);
            fmax = fmax.max(f);
            acc += f;
            cdf.push(acc);
        }
        if acc <= 0.0 {
            return KernelEval {
                est,
                ..Default::default()
            };
        }
        let mut sv = Vec::with_capacity(n);
        stratified_2d(n, rng, &mut sv);
        let (mut vis_sum, mut vmin, mut vmax) = (0.0f64, 1.0f64, 0.0f64);
        // The open rays' ends, each taken to carry an equal share (the grid end drawn in
        // proportion to the form factor, the other end uniform over its part in front).
        let mut seen = Vec::new();
        for (s, u) in sv.iter().enumerate() {
            // Stratified in the cumulative form factor: point x_k with probability f_k / Σ f.
            let target = (s as f64 + rng.next_f64()) / n as f64 * acc;
            let x = xs[cdf.partition_point(|&c| c <= target).min(m - 1)];
            let y = sample_triangle_above(x, gn, &ov, u[0], u[1])
                .unwrap_or_else(|| sample_triangle(&ov, u[0], u[1]));
            let vis = if self.covered(oe, on, y) {
                0.0
            } else {
                self.segment(x, ge, y, oe)
            };
            vis_sum += vis;
            vmin = vmin.min(vis);
            vmax = vmax.max(vis);
            if vis > 0.0 {
                // (receiver point, source point)
                seen.push(if reciprocal { (y, x) } else { (x, y) });
            }
        }
        let mixed = vmin < 1.0 && vmax > 0.0;
        let (deposit, draw) = if mixed {
            deposit_at(Some(&vr), Some(&vs), &mut seen, rng)
        } else {
            Default::default()
        };
        let mut fu = acc / n_open.max(1) as f64;
        if reciprocal {
            // The mean over the receiver: F_rs = A_s F_sr / A_r, where F_sr is the mean over
            // the source's open points (covered source points emit nothing).
            fu *= as_ * (n_open as f64 / m as f64) / ar;
            fmin *= as_ / ar;
            fmax *= as_ / ar;
        }
        KernelEval {
            k: fu * vis_sum / n as f64,
            est,
            kmin: fmin * vmin,
            kmax: fmax.max(est) * vmax,
            rays: n as u64,
            mixed,
            members: Vec::new(),
            deposit,
            draw,
        }
    }

    /// Unoccluded kernel sample at receiver point `x` (normal `n`) for source `src` whose
    /// sample point lies on surface element `member`. For a directional cluster source the
    /// member is drawn with probability `A_k / A`, so `F(x → k) · A / A_k` with the analytic
    /// point-to-polygon form factor is an unbiased estimate of the form factor of the
    /// cluster's contents (a disk of the whole cluster's area at the sample point, the
    /// previous estimate, under-counts near clusters several times: `A / (π r² + A)`).
    fn sample_kernel(&self, x: Vec3, n: Vec3, src: &End, member: u32) -> f64 {
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
    fn hand_out_cdf(&self, node: u32, src: u32) -> Vec<(u32, f64, f64)> {
        let el = self.elems;
        let se = &el.elems[src as usize];
        let mut out = Vec::new();
        let mut stack = vec![node];
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
                    (sample_triangle(&e.verts, u as f32, v), e.normal, id)
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

    /// Point `p` of a surface end (its side facing `n`) is covered ([`Covers`]).
    #[inline]
    fn covered(&self, end: Endpoint, n: Vec3, p: Vec3) -> bool {
        match end {
            Endpoint::Surface(tri) => self.covers.covered(tri, n, p),
            _ => false,
        }
    }

    /// Visibility of the segment x → y: every surface but the ends `a` and `b` can occlude.
    fn segment(&self, x: Vec3, a: Endpoint, y: Vec3, b: Endpoint) -> f64 {
        self.vis.transmittance(x, y, SEG_EPS, 1.0 - SEG_EPS, a, b)
    }
}

/// [`KernelCtx::sample_cluster`] found no surface.
const NO_MEMBER: u32 = super::link::NO_MEMBER;

/// Shadow segments start and end this fraction of their length from their end points: the
/// ends' own surfaces are left out by id, so this only absorbs rounding of the sample points.
const SEG_EPS: f32 = 1e-6;

/// The point of triangle `v` nearest to `p` (Ericson, *Real-Time Collision Detection* 5.1.5).
fn closest_on_triangle(v: &[Vec3; 3], p: Vec3) -> Vec3 {
    let [a, b, c] = *v;
    let (ab, ac, ap) = (b - a, c - a, p - a);
    let (d1, d2) = (ab.dot(ap), ac.dot(ap));
    if d1 <= 0.0 && d2 <= 0.0 {
        return a;
    }
    let bp = p - b;
    let (d3, d4) = (ab.dot(bp), ac.dot(bp));
    if d3 >= 0.0 && d4 <= d3 {
        return b;
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        return a + ab * (d1 / (d1 - d3));
    }
    let cp = p - c;
    let (d5, d6) = (ab.dot(cp), ac.dot(cp));
    if d6 >= 0.0 && d5 <= d6 {
        return c;
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        return a + ac * (d2 / (d2 - d6));
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        return b + (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6)));
    }
    let denom = 1.0 / (va + vb + vc);
    a + ab * (vb * denom) + ac * (vc * denom)
}

/// Most points of a near-field kernel ([`KernelCtx::near_field`]); a fine one may have 4×.
const NEAR_FIELD_MAX: usize = 64;

/// Points for the unoccluded kernel of surface receiver `r` from surface source `s`: `n` when
/// the gap between them is at least the receiver's diameter, else enough for a spacing of
/// about the gap (`(diameter / gap)²`, at most [`NEAR_FIELD_MAX`]), or half of it when `fine`
/// (4× the points, at most 4 × [`NEAR_FIELD_MAX`]). The gap is found by
/// alternating closest-point projections between the two triangles (it converges to their
/// distance from above; two rounds are close for the pairs that matter).
fn near_field_points(r: &End, s: &End, n: usize, fine: bool) -> usize {
    let (End::Surface { v: vr, .. }, End::Surface { v: vs, c: cs, .. }) = (*r, *s) else {
        return n;
    };
    let diameter = 2.0 * end_sphere(r).1;
    let mut p = closest_on_triangle(&vr, cs);
    let mut q = closest_on_triangle(&vs, p);
    for _ in 0..2 {
        p = closest_on_triangle(&vr, q);
        q = closest_on_triangle(&vs, p);
    }
    let gap = p.distance(q) as f64;
    if gap >= diameter {
        return n;
    }
    let (density, max) = if fine {
        (2.0, 4 * NEAR_FIELD_MAX)
    } else {
        (1.0, NEAR_FIELD_MAX)
    };
    let q = density * diameter / gap.max(1e-12);
    ((q * q).ceil().min(max as f64) as usize).max(n)
}

/// Bounding sphere of a link end around its centroid: (centre, radius).
fn end_sphere(e: &End) -> (DVec3, f64) {
    match *e {
        End::Surface { v, c, .. } => {
            let r = v.iter().map(|p| p.distance(c)).fold(0.0f32, f32::max);
            (c.as_dvec3(), r as f64)
        }
        End::Cluster { lo, hi, c, .. } => {
            let r = (hi - c).max(c - lo).max(Vec3::ZERO).length();
            (c.as_dvec3(), r as f64)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn square(z: f64, up: bool) -> Vec<DVec3> {
        let mut p = vec![
            DVec3::new(0.0, 0.0, z),
            DVec3::new(1.0, 0.0, z),
            DVec3::new(1.0, 1.0, z),
            DVec3::new(0.0, 1.0, z),
        ];
        if !up {
            p.reverse();
        }
        p
    }

    #[test]
    fn disk_estimate_matches_coaxial_closed_form() {
        for (h, r) in [(1.0, 0.5), (0.3, 1.0), (5.0, 0.1)] {
            let exact = parallel_disk_exact(h, 0.0, r);
            let est = point_to_disk(h * h, 1.0, 1.0, PI * r * r);
            assert!((exact - est).abs() < 1e-12, "{exact} {est}");
        }
        // Off axis, far away the estimate with the true cosines converges to the closed form.
        let (h, a, r) = (10.0, 3.0, 0.2);
        let exact = parallel_disk_exact(h, a, r);
        let d2 = h * h + a * a;
        let c = h / d2.sqrt();
        let est = point_to_disk(d2, c, c, PI * r * r);
        assert!(((exact - est) / exact).abs() < 1e-3, "{exact} {est}");
    }

    #[test]
    fn polygon_form_factor_analytic_values() {
        // Point under the corner of a unit square at height 1: F = 0.13853 (tables).
        let sq = square(1.0, false);
        let f = point_to_polygon(DVec3::ZERO, DVec3::Z, &sq, -DVec3::Z);
        let a = 1.0 / 2f64.sqrt();
        let exact = (1.0 / (2.0 * PI)) * 2.0 * (a * (1.0f64 / 2f64.sqrt()).atan());
        assert!((f - exact).abs() < 1e-9, "{f} {exact}");
        assert!((f - 0.138_53).abs() < 1e-4);
        // Behind the emitting side: zero; a huge polygon fills the hemisphere: 1.
        assert_eq!(
            point_to_polygon(DVec3::ZERO, DVec3::Z, &square(1.0, true), DVec3::Z),
            0.0
        );
        let big = [
            DVec3::new(-1e4, -1e4, 1.0),
            DVec3::new(-1e4, 1e4, 1.0),
            DVec3::new(1e4, 1e4, 1.0),
            DVec3::new(1e4, -1e4, 1.0),
        ];
        let f = point_to_polygon(DVec3::ZERO, DVec3::Z, &big, -DVec3::Z);
        assert!((f - 1.0).abs() < 1e-3, "{f}");
        // A tilted receiver sees part of the polygon clipped by its horizon.
        let f = point_to_polygon(DVec3::ZERO, DVec3::X, &big, -DVec3::Z);
        assert!((f - 0.5).abs() < 1e-3, "{f}");
    }

    #[test]
    fn angle_from_matches_atan2() {
        let mut rng = SplitMix64::new(7);
        let mut worst = 0.0f64;
        for i in 0..200_000 {
            // Magnitudes over many decades, both signs of x, and the exact axes.
            let s = 10f64.powf(rng.next_f64() * 12.0 - 6.0);
            let y = rng.next_f64() * s;
            let x = (rng.next_f64() * 2.0 - 1.0) * 10f64.powf(rng.next_f64() * 12.0 - 6.0);
            let (y, x) = match i % 1000 {
                0 => (0.0, x),
                1 => (y, 0.0),
                2 => (y, y),
                3 => (y, -y),
                _ => (y, x),
            };
            let want = y.atan2(x);
            let got = angle_from(y, x);
            let err = (got - want).abs() / want.abs().max(f64::MIN_POSITIVE);
            worst = worst.max(if want == 0.0 { got.abs() } else { err });
        }
        assert!(worst < 1e-15, "worst relative error {worst:e}");
    }

    #[test]
    fn closest_on_triangle_matches_a_dense_search() {
        let v = [
            Vec3::new(0.0, 0.0, 0.0),
            Vec3::new(2.0, 0.0, 0.0),
            Vec3::new(0.5, 1.5, 0.0),
        ];
        let mut rng = SplitMix64::new(5);
        let grid: Vec<Vec3> = (0..=200)
            .flat_map(|i| (0..=200 - i).map(move |j| (i, j)))
            .map(|(i, j)| {
                let (a, b) = (i as f32 / 200.0, j as f32 / 200.0);
                v[0] * (1.0 - a - b) + v[1] * a + v[2] * b
            })
            .collect();
        for _ in 0..200 {
            // Points in every Voronoi region: around, beside and above the triangle.
            let p = Vec3::new(
                rng.next_f32() * 5.0 - 1.5,
                rng.next_f32() * 4.0 - 1.5,
                rng.next_f32() * 2.0 - 1.0,
            );
            let q = closest_on_triangle(&v, p);
            let best = grid
                .iter()
                .map(|g| g.distance(p))
                .fold(f32::INFINITY, f32::min);
            assert!(
                q.distance(p) <= best + 1e-5,
                "{p:?}: {q:?} at {} > {best}",
                q.distance(p)
            );
            assert!(
                q.distance(p) >= best - 0.02,
                "{p:?}: {q:?} not on the triangle"
            );
        }
    }

    #[test]
    fn stratified_samples_cover_strata() {
        let mut rng = SplitMix64::new(3);
        let mut s = Vec::new();
        stratified_2d(8, &mut rng, &mut s);
        let mut cu = [0; 8];
        let mut cv = [0; 8];
        for p in &s {
            cu[(p[0] * 8.0) as usize] += 1;
            cv[(p[1] * 8.0) as usize] += 1;
        }
        assert_eq!(cu, [1; 8]);
        assert_eq!(cv, [1; 8]);
    }
}
