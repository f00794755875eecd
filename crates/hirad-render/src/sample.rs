//! Sampling shared by the path tracer and the final gather: emitting triangles chosen by power
//! (Walker's alias method), cosine-weighted directions, the power heuristic of multiple
//! importance sampling, and the offset of ray origins off a surface.

use glam::Vec3;
use hirad_scene::Scene;
use std::f32::consts::PI;

/// Emitting triangles and the power distribution over them, sampled in constant time with
/// Walker's alias method (Vose's construction).
pub(crate) struct Lights {
    /// The emitting triangles, in the columns' order (what a light sample reads of them).
    pub(crate) tris: Vec<LightTri>,
    /// Alias table: column `i` keeps `tris[i]` with probability `prob[i]`, else `tris[alias[i]]`.
    prob: Vec<f64>,
    alias: Vec<u32>,
    /// Probability density per unit area of choosing a point on each scene triangle
    /// (0 for non-emitters): `mean(L_e) / Σ A·mean(L_e)`.
    pub(crate) pdf_area: Vec<f32>,
}

/// What next-event estimation reads of an emitting triangle, in one record.
#[derive(Clone, Copy, Debug)]
pub(crate) struct LightTri {
    pub(crate) a: Vec3,
    pub(crate) b: Vec3,
    pub(crate) c: Vec3,
    pub(crate) normal: Vec3,
    pub(crate) emission: Vec3,
    /// Density per unit area of a point on this triangle (see `Lights::pdf_area`).
    pub(crate) pdf_area: f32,
    /// The scene triangle.
    pub(crate) tri: u32,
}

impl Lights {
    pub(crate) fn new(scene: &Scene) -> Lights {
        let ids = scene.emitters();
        let power: Vec<f64> = ids
            .iter()
            .map(|&t| {
                scene.areas[t as usize] as f64 * mean(scene.material_of(t as usize).emission) as f64
            })
            .collect();
        let total: f64 = power.iter().sum();
        let mut pdf_area = vec![0.0f32; scene.num_triangles()];
        if total.is_nan() || total <= 0.0 {
            return Lights {
                tris: Vec::new(),
                prob: Vec::new(),
                alias: Vec::new(),
                pdf_area,
            };
        }
        for &t in &ids {
            pdf_area[t as usize] =
                (mean(scene.material_of(t as usize).emission) as f64 / total) as f32;
        }
        let tris = ids
            .iter()
            .map(|&t| {
                let t = t as usize;
                let [a, b, c] = scene.tri_vertices(t);
                LightTri {
                    a,
                    b,
                    c,
                    normal: scene.normals[t],
                    emission: scene.material_of(t).emission,
                    pdf_area: pdf_area[t],
                    tri: t as u32,
                }
            })
            .collect();
        let (prob, alias) = alias_table(&power, total);
        Lights {
            tris,
            prob,
            alias,
            pdf_area,
        }
    }

    pub(crate) fn is_empty(&self) -> bool {
        self.tris.is_empty()
    }

    /// Choose an emitting triangle, with probability proportional to its power, from a
    /// uniform `u ∈ [0, 1)`: the integer part of `u·n` picks a column, the fraction decides
    /// between the column and its alias.
    #[inline]
    pub(crate) fn pick(&self, u: f64) -> &LightTri {
        &self.tris[alias_pick(&self.prob, &self.alias, u)]
    }
}

/// The column an alias table `(prob, alias)` (of [`alias_table`]) picks for a uniform
/// `u ∈ [0, 1)`: the integer part of `u·n` picks a column, the fraction decides between the
/// column and its alias.
#[inline]
pub(crate) fn alias_pick(prob: &[f64], alias: &[u32], u: f64) -> usize {
    let n = prob.len();
    let x = u * n as f64;
    let i = (x as usize).min(n - 1);
    if x - (i as f64) < prob[i] {
        i
    } else {
        alias[i] as usize
    }
}

/// Vose's alias table of the weights `w` (sum `total` > 0): `(prob, alias)` such that choosing
/// column `i` uniformly, then `i` with probability `prob[i]` and `alias[i]` otherwise, picks `j`
/// with probability `w[j] / total`.
pub(crate) fn alias_table(w: &[f64], total: f64) -> (Vec<f64>, Vec<u32>) {
    let n = w.len();
    let mut prob: Vec<f64> = w.iter().map(|&x| x * n as f64 / total).collect();
    let mut alias: Vec<u32> = (0..n as u32).collect();
    let (mut small, mut large): (Vec<u32>, Vec<u32>) =
        (0..n as u32).partition(|&i| prob[i as usize] < 1.0);
    while let (Some(&s), Some(&l)) = (small.last(), large.last()) {
        small.pop();
        alias[s as usize] = l;
        prob[l as usize] -= 1.0 - prob[s as usize];
        if prob[l as usize] < 1.0 {
            large.pop();
            small.push(l);
        }
    }
    // What remains is 1 up to rounding.
    for i in small.into_iter().chain(large) {
        prob[i as usize] = 1.0;
    }
    (prob, alias)
}

#[inline]
fn mean(v: Vec3) -> f32 {
    (v.x + v.y + v.z) / 3.0
}

/// Power heuristic (β = 2) weight of a sample of density `a` against one of density `b`.
#[inline]
pub(crate) fn power_heuristic(a: f32, b: f32) -> f32 {
    let (a2, b2) = (a * a, b * b);
    if a2 + b2 > 0.0 {
        a2 / (a2 + b2)
    } else {
        0.0
    }
}

/// Orthonormal basis around unit `n` (Duff et al. 2017).
#[inline]
fn basis(n: Vec3) -> (Vec3, Vec3) {
    let sign = 1.0f32.copysign(n.z);
    let a = -1.0 / (sign + n.z);
    let b = n.x * n.y * a;
    (
        Vec3::new(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x),
        Vec3::new(b, sign + n.y * n.y * a, -n.y),
    )
}

/// `(sin 2πu, cos 2πu)` for `u ∈ [0, 1]`, within 4e-7 of the exact values: the angle is reduced
/// to the nearest quarter turn `k` and the remainder `r ∈ [−π/4, π/4]` goes through the Taylor
/// polynomials of sin (degree 9) and cos (degree 10); the quarter turn swaps and negates them
/// with bit operations (no branch: `k` is random). Cheaper than the libm call, which was a
/// visible share of the path tracer's non-ray time.
#[inline]
fn sin_cos_turn(u: f32) -> (f32, f32) {
    let x = u * 4.0;
    let k = (x + 0.5) as u32; // round half up, x ≥ 0
    let r = (x - k as f32) * (PI / 2.0);
    let r2 = r * r;
    let s =
        r * (1.0 + r2 * (-1.0 / 6.0 + r2 * (1.0 / 120.0 + r2 * (-1.0 / 5040.0 + r2 / 362_880.0))));
    let c = 1.0
        + r2 * (-0.5
            + r2 * (1.0 / 24.0 + r2 * (-1.0 / 720.0 + r2 * (1.0 / 40_320.0 - r2 / 3_628_800.0))));
    // Odd quarter turns swap sin and cos; sin is negated in quarters 2, 3 and cos in 1, 2.
    let swap = 0u32.wrapping_sub(k & 1);
    let (sb, cb) = (s.to_bits(), c.to_bits());
    let a = (sb & !swap) | (cb & swap);
    let b = (cb & !swap) | (sb & swap);
    (
        f32::from_bits(a ^ ((k & 2) << 30)),
        f32::from_bits(b ^ ((k.wrapping_add(1) & 2) << 30)),
    )
}

/// Cosine-weighted direction around unit `n`; returns (direction, cos θ).
#[inline]
pub(crate) fn cosine_sample(n: Vec3, u1: f32, u2: f32) -> (Vec3, f32) {
    let r = u1.sqrt();
    let (sin, cos_phi) = sin_cos_turn(u2);
    let (t, b) = basis(n);
    let cos = (1.0 - u1).max(0.0).sqrt();
    (
        (t * (r * cos_phi) + b * (r * sin) + n * cos).normalize(),
        cos,
    )
}

/// Offset of ray origins off a surface (scene units): relative to the scene's extent and its
/// distance from the origin, so that f32 positions far from the origin still leave it.
pub(crate) fn surface_eps(scene: &Scene) -> f32 {
    let diag = scene.bbox.extent().length();
    let scale = diag
        .max(scene.bbox.min.abs().max_element())
        .max(scene.bbox.max.abs().max_element());
    (scale * 2e-6).max(1e-7)
}

#[cfg(test)]
mod tests {
    use super::*;
    use hirad_core::rng::SplitMix64;

    #[test]
    fn cosine_samples_are_on_the_hemisphere() {
        let mut rng = SplitMix64::new(3);
        for n in [Vec3::Z, Vec3::NEG_Z, Vec3::new(0.3, -0.5, 0.8).normalize()] {
            let mut mean_cos = 0.0f64;
            for _ in 0..20000 {
                let (d, c) = cosine_sample(n, rng.next_f32(), rng.next_f32());
                assert!((d.length() - 1.0).abs() < 1e-5);
                assert!((d.dot(n) - c).abs() < 1e-4);
                mean_cos += c as f64;
            }
            // E[cos θ] under the cosine density is 2/3.
            assert!((mean_cos / 20000.0 - 2.0 / 3.0).abs() < 0.01);
        }
    }

    #[test]
    fn alias_table_reproduces_the_weights() {
        let w = [3.0, 0.5, 0.0, 1e-9, 7.25, 1.0, 1.0, 0.125];
        let total: f64 = w.iter().sum();
        let (prob, alias) = alias_table(&w, total);
        // Exact probability of each outcome: Σ over columns (1/n)·(prob or 1 − prob).
        let n = w.len() as f64;
        let mut got = vec![0.0f64; w.len()];
        for i in 0..w.len() {
            assert!((0.0..=1.0).contains(&prob[i]));
            got[i] += prob[i] / n;
            got[alias[i] as usize] += (1.0 - prob[i]) / n;
        }
        for (g, x) in got.iter().zip(w) {
            assert!((g - x / total).abs() < 1e-12, "{g} vs {}", x / total);
        }
        // `Lights::pick` on a fine uniform grid of u reproduces the weights too.
        let rec = |i: u32| LightTri {
            a: Vec3::splat(i as f32),
            b: Vec3::ZERO,
            c: Vec3::ZERO,
            normal: Vec3::Z,
            emission: Vec3::ONE,
            pdf_area: 1.0,
            tri: i,
        };
        let lights = Lights {
            tris: (10..10 + w.len() as u32).map(rec).collect(),
            prob,
            alias,
            pdf_area: Vec::new(),
        };
        let m = 1 << 20;
        let mut count = vec![0u32; w.len()];
        for k in 0..m {
            count[(lights.pick((k as f64 + 0.5) / m as f64).a.x as usize) - 10] += 1;
        }
        for (c, x) in count.iter().zip(w) {
            assert!((*c as f64 / m as f64 - x / total).abs() < 1e-5);
        }
        // A single weight: always that one.
        let (p1, a1) = alias_table(&[2.0], 2.0);
        assert_eq!((p1, a1), (vec![1.0], vec![0]));
    }

    #[test]
    fn sin_cos_turn_matches_libm() {
        let n = 1 << 20;
        let mut worst = 0.0f64;
        for k in 0..=n {
            let u = k as f32 / n as f32;
            let (s, c) = sin_cos_turn(u);
            let (es, ec) = (2.0 * std::f64::consts::PI * u as f64).sin_cos();
            worst = worst.max((s as f64 - es).abs()).max((c as f64 - ec).abs());
        }
        assert!(worst < 4e-7, "{worst}");
        assert_eq!(sin_cos_turn(0.0), (0.0, 1.0));
    }

    #[test]
    fn power_heuristic_sums_to_one() {
        for (a, b) in [(1.0, 2.0), (0.3, 0.0), (5.0, 5.0)] {
            assert!((power_heuristic(a, b) + power_heuristic(b, a) - 1.0).abs() < 1e-6);
        }
        assert_eq!(power_heuristic(0.0, 0.0), 0.0);
    }
}
