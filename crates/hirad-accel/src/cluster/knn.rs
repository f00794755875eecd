//! Nearest-neighbour distances in the maximum norm over a fixed set of points ([`PointTree`],
//! an implicit k-d tree); `proxi` uses it to let a lone surface skip the levels at which it
//! cannot be grouped.

use glam::Vec3;

/// Points in an implicit k-d tree (median splits, axes in turn) for nearest-neighbour
/// distances in the maximum norm.
pub(crate) struct PointTree {
    pts: Vec<Vec3>,
    idx: Vec<u32>,
}

/// Ranges of at most this many points are scanned linearly.
const KD_LEAF: usize = 8;

impl PointTree {
    pub(crate) fn new(pts: Vec<Vec3>) -> Self {
        let mut idx: Vec<u32> = (0..pts.len() as u32).collect();
        Self::split(&pts, &mut idx, 0);
        PointTree { pts, idx }
    }

    fn split(pts: &[Vec3], idx: &mut [u32], axis: usize) {
        if idx.len() <= KD_LEAF {
            return;
        }
        let mid = idx.len() / 2;
        idx.select_nth_unstable_by(mid, |&a, &b| {
            pts[a as usize][axis]
                .total_cmp(&pts[b as usize][axis])
                .then(a.cmp(&b))
        });
        let (lo, hi) = idx.split_at_mut(mid);
        let next = (axis + 1) % 3;
        if lo.len() + hi.len() >= 4 * 4096 {
            rayon::join(
                || Self::split(pts, lo, next),
                || Self::split(pts, &mut hi[1..], next),
            );
        } else {
            Self::split(pts, lo, next);
            Self::split(pts, &mut hi[1..], next);
        }
    }

    /// Smallest maximum-norm distance from `q` to a point other than point `skip`
    /// (infinity when there is none).
    pub(crate) fn nearest(&self, q: Vec3, skip: u32) -> f32 {
        let mut best = f32::INFINITY;
        self.search(&self.idx, 0, q, skip, &mut best);
        best
    }

    fn search(&self, idx: &[u32], axis: usize, q: Vec3, skip: u32, best: &mut f32) {
        let dist = |i: u32| (self.pts[i as usize] - q).abs().max_element();
        if idx.len() <= KD_LEAF {
            for &i in idx {
                if i != skip {
                    *best = best.min(dist(i));
                }
            }
            return;
        }
        let mid = idx.len() / 2;
        let m = idx[mid];
        if m != skip {
            *best = best.min(dist(m));
        }
        let diff = q[axis] - self.pts[m as usize][axis];
        let (near, far) = if diff < 0.0 {
            (&idx[..mid], &idx[mid + 1..])
        } else {
            (&idx[mid + 1..], &idx[..mid])
        };
        let next = (axis + 1) % 3;
        self.search(near, next, q, skip, best);
        // `!(a >= b)` form so that NaN coordinates search both sides.
        let prune = diff.abs() >= *best;
        if !prune {
            self.search(far, next, q, skip, best);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn point_tree_nearest_matches_brute_force() {
        let mut r = hirad_core::rng::SplitMix64::new(5);
        let mut pts: Vec<Vec3> = (0..2000)
            .map(|_| Vec3::new(r.next_f32(), r.next_f32(), r.next_f32() * 0.1))
            .collect();
        pts.push(pts[17]); // a duplicate
        let tree = PointTree::new(pts.clone());
        for (i, &q) in pts.iter().enumerate() {
            let brute = pts
                .iter()
                .enumerate()
                .filter(|&(j, _)| j != i)
                .map(|(_, &p)| (p - q).abs().max_element())
                .fold(f32::INFINITY, f32::min);
            assert_eq!(tree.nearest(q, i as u32), brute, "point {i}");
        }
        assert_eq!(tree.nearest(pts[17], 17), 0.0);
        assert_eq!(
            PointTree::new(vec![Vec3::ONE]).nearest(Vec3::ONE, 0),
            f32::INFINITY
        );
    }
}
