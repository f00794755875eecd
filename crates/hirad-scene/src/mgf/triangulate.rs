//! Polygons to triangles: a planar polygon (MGF `f`, or `fh` with holes) is projected on the
//! axis plane its normal is closest to, holes are bridged to the outer contour (rightmost
//! first), and the result is ear-clipped, so concave polygons keep their shape.

use glam::{DVec2, DVec3};

/// Ear-clip a planar polygon with holes (`contours[0]` outer, the rest holes); triangle
/// corners index the concatenated contours and keep the outer contour's winding.
pub(super) fn triangulate(contours: &[Vec<DVec3>]) -> Vec<[usize; 3]> {
    let outer = &contours[0];
    let mut normal = DVec3::ZERO;
    for k in 0..outer.len() {
        let (a, b) = (outer[k], outer[(k + 1) % outer.len()]);
        normal += DVec3::new(
            (a.y - b.y) * (a.z + b.z),
            (a.z - b.z) * (a.x + b.x),
            (a.x - b.x) * (a.y + b.y),
        );
    }
    let ax = normal.abs();
    let k = if ax.x >= ax.y && ax.x >= ax.z {
        0
    } else if ax.y >= ax.z {
        1
    } else {
        2
    };
    if normal[k] == 0.0 || normal[k].is_nan() {
        return Vec::new();
    }
    let (u, v) = if normal[k] > 0.0 {
        ((k + 1) % 3, (k + 2) % 3)
    } else {
        ((k + 2) % 3, (k + 1) % 3)
    };
    let p2: Vec<DVec2> = contours
        .iter()
        .flatten()
        .map(|p| DVec2::new(p[u], p[v]))
        .collect();
    // Index lists per contour, dropping consecutive repeats (a closing vertex equal to the first).
    let mut start = 0;
    let mut rings: Vec<Vec<usize>> = Vec::new();
    for (ci, c) in contours.iter().enumerate() {
        let mut r: Vec<usize> = Vec::with_capacity(c.len());
        for j in start..start + c.len() {
            if r.last().is_none_or(|&l| p2[l] != p2[j]) {
                r.push(j);
            }
        }
        while r.len() > 1 && p2[r[0]] == p2[*r.last().expect("ring")] {
            r.pop();
        }
        start += c.len();
        if ci == 0 && r.len() < 3 {
            return Vec::new();
        }
        if r.len() >= 3 {
            rings.push(r);
        }
    }
    let mut poly = rings.remove(0);
    let area = |r: &[usize]| -> f64 {
        (0..r.len())
            .map(|i| p2[r[i]].perp_dot(p2[r[(i + 1) % r.len()]]))
            .sum::<f64>()
    };
    let (lo, hi) = p2.iter().fold(
        (DVec2::splat(f64::INFINITY), DVec2::splat(f64::NEG_INFINITY)),
        |(lo, hi), p| (lo.min(*p), hi.max(*p)),
    );
    let eps = 1e-12 * (hi - lo).length_squared();
    // Holes: clockwise, rightmost first, each bridged to the polygon built so far.
    for h in &mut rings {
        if area(h) > 0.0 {
            h.reverse();
        }
    }
    rings.sort_by(|a, b| {
        let mx = |r: &Vec<usize>| r.iter().map(|&i| p2[i].x).fold(f64::NEG_INFINITY, f64::max);
        mx(b).total_cmp(&mx(a))
    });
    for hi_ in 0..rings.len() {
        let hole = &rings[hi_];
        let mi = (0..hole.len())
            .max_by(|&a, &b| p2[hole[a]].x.total_cmp(&p2[hole[b]].x))
            .expect("hole");
        let m = p2[hole[mi]];
        let mut best: Option<(f64, usize)> = None;
        let mut fallback: Option<(f64, usize)> = None;
        for (pi, &pv) in poly.iter().enumerate() {
            let d = (p2[pv] - m).length_squared();
            if fallback.is_none_or(|(bd, _)| d < bd) {
                fallback = Some((d, pi));
            }
            if best.is_some_and(|(bd, _)| d >= bd) {
                continue;
            }
            let blocked = |r: &[usize]| {
                (0..r.len()).any(|e| crosses(p2[pv], m, p2[r[e]], p2[r[(e + 1) % r.len()]], eps))
            };
            if blocked(&poly) || rings[hi_..].iter().any(|r| blocked(r)) {
                continue;
            }
            best = Some((d, pi));
        }
        let Some((_, pi)) = best.or(fallback) else {
            continue;
        };
        let mut merged = Vec::with_capacity(poly.len() + hole.len() + 2);
        merged.extend_from_slice(&poly[..=pi]);
        merged.extend(hole[mi..].iter().chain(&hole[..=mi]));
        merged.extend_from_slice(&poly[pi..]);
        poly = merged;
    }
    let mut out = Vec::with_capacity(poly.len().saturating_sub(2));
    ear_clip(&p2, poly, eps, &mut out);
    out
}

/// True when segments ab and cd cross at a point interior to both (shared endpoints and
/// touching do not count).
fn crosses(a: DVec2, b: DVec2, c: DVec2, d: DVec2, eps: f64) -> bool {
    if a == c || a == d || b == c || b == d {
        return false;
    }
    let o = |p: DVec2, q: DVec2, r: DVec2| (q - p).perp_dot(r - p);
    let (d1, d2) = (o(a, b, c), o(a, b, d));
    let (d3, d4) = (o(c, d, a), o(c, d, b));
    ((d1 > eps && d2 < -eps) || (d1 < -eps && d2 > eps))
        && ((d3 > eps && d4 < -eps) || (d3 < -eps && d4 > eps))
}

/// Ear clipping of a counter-clockwise polygon (indices into `p`), n − 2 triangles.
fn ear_clip(p: &[DVec2], mut v: Vec<usize>, eps: f64, out: &mut Vec<[usize; 3]>) {
    while v.len() > 3 {
        let n = v.len();
        let corner = |k: usize| (v[(k + n - 1) % n], v[k], v[(k + 1) % n]);
        let turn = |k: usize| {
            let (a, b, c) = corner(k);
            (p[b] - p[a]).perp_dot(p[c] - p[b])
        };
        let is_ear = |k: usize| {
            let (a, b, c) = corner(k);
            if turn(k) <= eps {
                return false;
            }
            let (pa, pb, pc) = (p[a], p[b], p[c]);
            !v.iter().any(|&j| {
                let q = p[j];
                if q == pa || q == pb || q == pc {
                    return false;
                }
                let e = -eps;
                (pb - pa).perp_dot(q - pa) >= e
                    && (pc - pb).perp_dot(q - pb) >= e
                    && (pa - pc).perp_dot(q - pc) >= e
            })
        };
        let k = (0..n)
            .find(|&k| is_ear(k))
            .or_else(|| (0..n).find(|&k| turn(k).abs() <= eps))
            .unwrap_or_else(|| {
                (0..n)
                    .max_by(|&a, &b| turn(a).total_cmp(&turn(b)))
                    .expect("polygon")
            });
        let (a, b, c) = corner(k);
        out.push([a, b, c]);
        v.remove(k);
    }
    if v.len() == 3 {
        out.push([v[0], v[1], v[2]]);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn concave_polygon_ear_clipped() {
        // An L shape of area 3.
        let l = [(0., 0.), (2., 0.), (2., 1.), (1., 1.), (1., 2.), (0., 2.)]
            .map(|(x, y)| DVec3::new(x, y, 0.0))
            .to_vec();
        let t = triangulate(std::slice::from_ref(&l));
        assert_eq!(t.len(), 4);
        let area: f64 = t
            .iter()
            .map(|t| 0.5 * (l[t[1]] - l[t[0]]).cross(l[t[2]] - l[t[0]]).z)
            .sum();
        assert!((area - 3.0).abs() < 1e-12, "{area}");
    }
}
