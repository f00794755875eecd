//! Random segments of the paper's ray-casting test, drawn exactly as `experiments.md` §2
//! defines them so that other programs draw bit-identical segments:
//!
//! - SplitMix64 ([`hirad_core::rng::SplitMix64`]) seeded with `seed`, uniforms `(next() >> 11)·2⁻⁵³`;
//! - triangles in scene order (file order, polygons fan-triangulated at load), area in f64 from
//!   the f32 corners, cumulative table summed in order, total = last entry; zero-area triangles
//!   have probability 0;
//! - per pair, six uniforms `uA, u1A, u2A, uB, u1B, u2B`; triangle = first `i` with
//!   `cum[i] > u·total` (clamped to the last); point `a·p0 + b·p1 + c·p2` in f64 with
//!   `s = √u1, a = 1 − s, b = s(1 − u2), c = s·u2`;
//! - segment origin `f32(P)`, direction `f32(Q − P)` (difference in f64), `t ∈ [1e-4, 1 − 1e-4]`.

use super::Segment;
use glam::DVec3;
use hirad_core::geom::triangle_area_f64;
use hirad_core::rng::SplitMix64;
use hirad_scene::Scene;

/// Area-weighted sampler of points on the surfaces of a scene.
#[derive(Clone, Debug)]
pub struct SurfaceSampler {
    /// Corners of every triangle in f64 (converted exactly from f32).
    tris: Vec<[DVec3; 3]>,
    /// Cumulative areas (f64, summed in triangle order).
    cum: Vec<f64>,
}

/// A sampled surface point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SurfacePoint {
    /// Triangle id.
    pub tri: u32,
    /// Position in f64.
    pub p: DVec3,
}

impl SurfaceSampler {
    /// Cumulative area table of the scene's triangles.
    pub fn new(scene: &Scene) -> SurfaceSampler {
        let n = scene.num_triangles();
        let mut tris = Vec::with_capacity(n);
        let mut cum = Vec::with_capacity(n);
        let mut acc = 0.0f64;
        for i in 0..n {
            let [a, b, c] = scene.tri_vertices(i);
            acc += triangle_area_f64(a, b, c);
            cum.push(acc);
            tris.push([a.as_dvec3(), b.as_dvec3(), c.as_dvec3()]);
        }
        SurfaceSampler { tris, cum }
    }

    /// Total area (the last cumulative entry; 0 for an empty scene).
    pub fn total(&self) -> f64 {
        self.cum.last().copied().unwrap_or(0.0)
    }

    /// Triangle selected by the uniform `u`: first index with `cum[i] > u·total`, clamped to the
    /// last triangle.
    pub fn pick(&self, u: f64) -> usize {
        let x = u * self.total();
        self.cum
            .partition_point(|&c| c <= x)
            .min(self.cum.len().saturating_sub(1))
    }

    /// The point of the three uniforms `(u, u1, u2)`; `None` for a scene without triangles.
    pub fn point(&self, u: f64, u1: f64, u2: f64) -> Option<SurfacePoint> {
        if self.tris.is_empty() {
            return None;
        }
        let i = self.pick(u);
        let [p0, p1, p2] = self.tris[i];
        let s = u1.sqrt();
        let a = 1.0 - s;
        let b = s * (1.0 - u2);
        let c = s * u2;
        let p = DVec3::new(
            a * p0.x + b * p1.x + c * p2.x,
            a * p0.y + b * p1.y + c * p2.y,
            a * p0.z + b * p1.z + c * p2.z,
        );
        Some(SurfacePoint { tri: i as u32, p })
    }

    /// Draw the next point from `rng` (three uniforms).
    pub fn draw(&self, rng: &mut SplitMix64) -> Option<SurfacePoint> {
        let u = rng.next_f64();
        let u1 = rng.next_f64();
        let u2 = rng.next_f64();
        self.point(u, u1, u2)
    }
}

/// A sampled pair of surface points and its segment.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SamplePair {
    /// First point (the segment's origin).
    pub a: SurfacePoint,
    /// Second point (the segment's end).
    pub b: SurfacePoint,
    /// The segment from `a` to `b` (direction `b − a` computed in f64), `t ∈ [1e-4, 1 − 1e-4]`.
    pub segment: Segment,
}

/// The first `n` pairs of the ray-casting test for `seed`, with their end points.
pub fn sample_pairs(scene: &Scene, n: usize, seed: u64) -> Vec<SamplePair> {
    let sampler = SurfaceSampler::new(scene);
    let mut rng = SplitMix64::new(seed);
    let mut out = Vec::with_capacity(n);
    for _ in 0..n {
        let (Some(a), Some(b)) = (sampler.draw(&mut rng), sampler.draw(&mut rng)) else {
            break;
        };
        let segment = Segment {
            origin: a.p.as_vec3(),
            dir: (b.p - a.p).as_vec3(),
            tmin: Segment::SPEC_TMIN,
            tmax: Segment::SPEC_TMAX,
        };
        out.push(SamplePair { a, b, segment });
    }
    out
}

/// The first `n` segments of the ray-casting test for `seed`.
pub fn sample_segments(scene: &Scene, n: usize, seed: u64) -> Vec<Segment> {
    sample_pairs(scene, n, seed)
        .into_iter()
        .map(|p| p.segment)
        .collect()
}

/// Write the scene's triangles and `segs` in the raw exchange format of `hirad raybench
/// --export`, so that another program (e.g. `benches/embree/`) casts the same segments through
/// the same triangles. Little-endian: `u32` triangle count, then per triangle its three corners
/// as 9 `f32` (scene order); `u32` segment count, then per segment 8 `f32`: origin, direction,
/// `tmin`, `tmax`. Written atomically.
pub fn export_segments(
    path: &std::path::Path,
    scene: &Scene,
    segs: &[Segment],
) -> hirad_core::Result<()> {
    hirad_core::io::write_atomic(path, |w| {
        w.write_all(&(scene.num_triangles() as u32).to_le_bytes())?;
        for i in 0..scene.num_triangles() {
            for c in scene.tri_vertices(i) {
                for x in c.to_array() {
                    w.write_all(&x.to_le_bytes())?;
                }
            }
        }
        w.write_all(&(segs.len() as u32).to_le_bytes())?;
        for s in segs {
            let v = [
                s.origin.x, s.origin.y, s.origin.z, s.dir.x, s.dir.y, s.dir.z, s.tmin, s.tmax,
            ];
            for x in v {
                w.write_all(&x.to_le_bytes())?;
            }
        }
        Ok(())
    })
}

/// Read the segments of a file in the exchange format of [`export_segments`] (written by
/// `hirad raybench --export` or `hirad solve --export-rays`), checking that its triangles are
/// those of `scene`.
pub fn import_segments(path: &std::path::Path, scene: &Scene) -> hirad_core::Result<Vec<Segment>> {
    use hirad_core::Error;
    let bytes = std::fs::read(path).map_err(|err| Error::Io {
        path: path.to_path_buf(),
        err,
    })?;
    let bad = |msg: &str| Error::input(path, msg.to_string());
    let mut words = bytes.chunks_exact(4).map(|w| [w[0], w[1], w[2], w[3]]);
    let mut next = || words.next().ok_or_else(|| bad("file ends early"));
    let nt = u32::from_le_bytes(next()?) as usize;
    if nt != scene.num_triangles() {
        return Err(bad(&format!(
            "{nt} triangles, but the scene has {}",
            scene.num_triangles()
        )));
    }
    for i in 0..nt {
        for c in scene.tri_vertices(i) {
            for x in c.to_array() {
                if f32::from_le_bytes(next()?).to_bits() != x.to_bits() {
                    return Err(bad(&format!("triangle {i} differs from the scene's")));
                }
            }
        }
    }
    let ns = u32::from_le_bytes(next()?) as usize;
    let mut segs = Vec::with_capacity(ns.min(bytes.len() / 32));
    for _ in 0..ns {
        let mut v = [0f32; 8];
        for x in &mut v {
            *x = f32::from_le_bytes(next()?);
        }
        segs.push(Segment {
            origin: glam::Vec3::new(v[0], v[1], v[2]),
            dir: glam::Vec3::new(v[3], v[4], v[5]),
            tmin: v[6],
            tmax: v[7],
        });
    }
    if next().is_ok() {
        return Err(bad("data after the last segment"));
    }
    Ok(segs)
}
