//! Near links: surface pairs closer than the receiver's diameter integrate the unoccluded
//! form factor on a jittered grid (spacing about the gap, half of it for links the hierarchy
//! cannot resolve), on the source when it is the smaller end (reciprocity); links with a
//! cluster end closer than its size are judged on a geometric bound of their kernel.

use super::kernel::{
    deposit_at, point_pair_kernel, solid_angle_pair_weight, End, KernelEval, Samples, CELL_SHARE,
    INLINE,
};
use super::sampling::{
    jittered_grid, sample_triangle_above_area, sample_triangle_solid_angle, stratified_2d,
};
use super::KernelCtx;
use crate::config::VisibilityMode;
use glam::{DVec3, Vec3};
use hirad_core::rng::SplitMix64;
use smallvec::SmallVec;
use std::f64::consts::PI;

impl KernelCtx<'_> {
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

    /// True when receiver `i` and source `j` are surfaces closer than the receiver's size, whose
    /// kernel `KernelCtx::near_field` integrates (it keeps no per-sample leaves).
    pub fn is_near_field(&self, i: u32, j: u32) -> bool {
        let n = self.n_rays.max(1);
        near_field_points(&self.end(i), &self.end(j), n, false) > n
    }

    /// Kernel of a surface receiver close to a surface source (closer than its own size): the
    /// unoccluded form factor varies over the receiver on the scale of the gap, so it is
    /// integrated over a jittered grid of `m` points (analytic point-to-polygon, no rays), and
    /// the `n` shadow rays start from points drawn among them in proportion to their form
    /// factor and end on the other end drawn by solid angle: the kernel is `F_u ×` the
    /// visible share of the form factor. When the source is
    /// the smaller end and no part of the receiver is covered, the grid lies on the source and
    /// `F_u = A_s/A_r · mean F(y → receiver)` (reciprocity): seen from a small source, a large
    /// receiver close to it fills a smooth part of the hemisphere, while seen from the
    /// receiver, the small source is a peak a grid resolves poorly.
    pub(super) fn near_field(
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
        let mut pts: SmallVec<[[f32; 2]; NEAR_FIELD_MAX]> = SmallVec::new();
        jittered_grid(k, rng, &mut pts);
        let xs: SmallVec<[Vec3; NEAR_FIELD_MAX]> =
            pts.iter().map(|u| self.point_on(&gv, u[0], u[1])).collect();
        let other = End::Surface {
            v: ov,
            n: on,
            c: (ov[0] + ov[1] + ov[2]) / 3.0,
            area: 0.0,
            tri: 0,
        };
        // Covered points are not part of their end (zero weight in the cdf below).
        let covered: SmallVec<[bool; NEAR_FIELD_MAX]> =
            xs.iter().map(|&x| self.covered(ge, gn, x)).collect();
        let open: SmallVec<[Vec3; NEAR_FIELD_MAX]> = (xs.iter().zip(&covered))
            .filter(|(_, &c)| !c)
            .map(|(&x, _)| x)
            .collect();
        let n_open = open.len();
        let mut f_open: SmallVec<[f64; NEAR_FIELD_MAX]> = SmallVec::from_elem(0.0, n_open);
        Self::point_kernels(&open, gn, &other, &mut f_open);
        let mut f_open = f_open.into_iter();
        let mut cdf: SmallVec<[f64; NEAR_FIELD_MAX]> = SmallVec::new();
        let (mut acc, mut fmin, mut fmax) = (0.0f64, f64::INFINITY, 0.0f64);
        for &c in &covered {
            let f = if c {
                0.0
            } else {
                f_open.next().expect("one kernel per open point")
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
        let mut sv = Samples::new();
        stratified_2d(n, rng, &mut sv);
        let (mut vis_sum, mut vmin, mut vmax) = (0.0f64, 1.0f64, 0.0f64);
        // Σ q: the visible share is Σ V·q / Σ q (see `evaluate_with`).
        let mut q_sum = 0.0f64;
        // The open rays' ends with their kernels over their density (the grid end drawn in
        // proportion to the form factor, the other end by solid angle from it).
        let mut seen: SmallVec<[(Vec3, Vec3, f64); INLINE]> = SmallVec::new();
        let mut recv: SmallVec<[(Vec3, bool); INLINE]> = SmallVec::new();
        let mut last = None;
        for (s, u) in sv.iter().enumerate() {
            // Stratified in the cumulative form factor: point x_k with probability f_k / Σ f.
            let target = (s as f64 + rng.next_f64()) / n as f64 * acc;
            let kx = cdf.partition_point(|&c| c <= target).min(m - 1);
            let x = xs[kx];
            let fk = cdf[kx] - if kx > 0 { cdf[kx - 1] } else { 0.0 };
            // The other end's point nearly in proportion to its point-to-point kernel from x
            // (solid angle times cos θ_x, density `p`): its visibility, weighed by
            // `q = cos θ_x / (π p F(x))` (mean 1), gives the visible share of F(x) as
            // `Σ V·q / Σ q`. Area-uniform points (where the solid angle cannot be taken, or
            // without shadow rays) weigh visibility evenly over the other end.
            let other_area = if reciprocal { ar } else { as_ };
            let drawn = (self.vis.mode() != VisibilityMode::None)
                .then(|| {
                    let m = self.vis.margin();
                    sample_triangle_solid_angle(x, gn, &ov, (u[0], u[1]), m, other_area)
                })
                .flatten();
            let (y, q, over, solid) = match drawn {
                Some((y, weight, over)) => (y, weight / fk.max(1e-300), over, true),
                None => {
                    let (y, over) = sample_triangle_above_area(
                        x,
                        gn,
                        &ov,
                        (u[0], u[1]),
                        self.vis.margin(),
                        other_area,
                    )
                    .unwrap_or_else(|| (self.point_on(&ov, u[0], u[1]), other_area));
                    (y, 1.0, over, false)
                }
            };
            let vis = if self.covered(oe, on, y) {
                0.0
            } else {
                self.vis.between(x, y, ge, oe, &mut last)
            };
            vis_sum += vis * q;
            q_sum += q;
            vmin = vmin.min(vis);
            vmax = vmax.max(vis);
            if vis > 0.0 {
                // (receiver point, source point, weight): the pair's kernel over the density
                // it was drawn with (x by its form factor, y by q), damped within a cell.
                let part = if reciprocal { as_ } else { over };
                let w = if solid {
                    vis * solid_angle_pair_weight(q, x, y, part)
                } else {
                    let cell = part * CELL_SHARE / PI;
                    vis * over * point_pair_kernel(x, Some(gn), y, on, cell) / fk.max(1e-300)
                };
                seen.push(if reciprocal { (y, x, w) } else { (x, y, w) });
            }
            recv.push((if reciprocal { y } else { x }, vis > 0.0));
        }
        let mixed = vmin < 1.0 && vmax > 0.0;
        let (deposit, draw) = deposit_at(Some(&vr), Some(&vs), &mut recv, &seen, rng);
        let mut fu = acc / n_open.max(1) as f64;
        if reciprocal {
            // The mean over the receiver: F_rs = A_s F_sr / A_r, where F_sr is the mean over
            // the source's open points (covered source points emit nothing).
            fu *= as_ * (n_open as f64 / m as f64) / ar;
            fmin *= as_ / ar;
            fmax *= as_ / ar;
        }
        KernelEval {
            k: fu * vis_sum / if q_sum > 0.0 { q_sum } else { n as f64 },
            ku: fu,
            est,
            kmin: fmin * vmin,
            kmax: fmax.max(est) * vmax,
            rays: n as u64,
            mixed,
            members: Vec::new(),
            deposit,
            draw,
            open_members: Vec::new(),
            hidden_child: false,
        }
    }
}

/// The point of triangle `v` nearest to `p` (Ericson, *Real-Time Collision Detection* 5.1.5).
pub(super) fn closest_on_triangle(v: &[Vec3; 3], p: Vec3) -> Vec3 {
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
pub(super) fn near_field_points(r: &End, s: &End, n: usize, fine: bool) -> usize {
    let (End::Surface { v: vr, .. }, End::Surface { v: vs, c: cs, .. }) = (*r, *s) else {
        return n;
    };
    let (cr, rr) = end_sphere(r);
    let diameter = 2.0 * rr;
    // Bounding spheres a diameter apart (with a margin for rounding, far above f32's): the
    // projections below would find the same, at more cost.
    let (cs_d, rs) = end_sphere(s);
    let d = cr.distance(cs_d);
    let margin = 1e-3 * (d + rr + rs) + 1e-5 * cr.abs().max(cs_d.abs()).max_element();
    if d - rr - rs - margin >= diameter {
        return n;
    }
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
pub(crate) fn end_sphere(e: &End) -> (DVec3, f64) {
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
