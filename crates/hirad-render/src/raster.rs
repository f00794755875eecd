//! Z-buffer rasteriser of a triangle mesh with per-vertex radiance (Gouraud, perspective-correct)
//! or per-triangle radiance (flat), with supersampling and near-plane clipping. [`rasterize`]
//! describes the pipeline; [`render_solution`] draws a radiosity solution as radiance.
//!
//! The result does not depend on the number of threads.

use super::camera::{CameraFrame, CameraView};
use super::image::Image;
use glam::Vec3;
use hirad_core::geom::Aabb;
use hirad_core::{Error, Result};
use hirad_scene::export::ColoredMesh;
use rayon::prelude::*;

/// Output rows per band (the unit of parallel work).
const BAND_ROWS: u32 = 8;
/// Fixed-point sub-pixel precision: 1/256 pixel.
const SUB_BITS: u32 = 8;
const SUB: f32 = (1 << SUB_BITS) as f32;
/// Largest screen coordinate (pixels, either side of the image) kept after guard-band clipping.
const GUARD_PIXELS: f32 = (1u32 << 20) as f32;

/// What to draw for the back side of a triangle (the side opposite its counter-clockwise
/// normal).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum BackFaces {
    /// One-sided surfaces (the solver's default): a back face is opaque and black, as in the
    /// path tracer.
    #[default]
    Black,
    /// Back faces are not drawn (meshes that carry explicit back-face triangles, e.g. a
    /// `--two-sided` solution).
    Cull,
    /// Back faces show the same colour as the front.
    Shade,
}

/// Rasteriser settings.
#[derive(Clone, Debug, PartialEq)]
pub struct RasterOptions {
    /// Supersampling factor per axis: `ss × ss` samples per pixel, box-filtered (≥ 1).
    pub supersample: u32,
    /// Back-face handling.
    pub back_faces: BackFaces,
    /// Colour of pixels no triangle covers.
    pub background: Vec3,
    /// Near clipping distance along the viewing direction; `None`: 1e-5 × the distance from
    /// the eye to the farthest corner of the mesh's bounding box.
    pub near: Option<f32>,
    /// Every colour is multiplied by this factor (1/π turns radiosity into radiance).
    pub scale: f32,
}

impl Default for RasterOptions {
    fn default() -> Self {
        Self {
            supersample: 1,
            back_faces: BackFaces::Black,
            background: Vec3::ZERO,
            near: None,
            scale: 1.0,
        }
    }
}

/// Colours of a mesh to rasterise.
#[derive(Clone, Copy, Debug)]
pub enum MeshColors<'a> {
    /// One colour per vertex, interpolated (Gouraud, perspective-correct).
    PerVertex(&'a [Vec3]),
    /// One colour per triangle (flat).
    PerTriangle(&'a [Vec3]),
}

/// A triangle mesh with colours, borrowed.
#[derive(Clone, Copy, Debug)]
pub struct RasterMesh<'a> {
    /// Vertex positions.
    pub positions: &'a [Vec3],
    /// Triangles as indices into `positions`.
    pub triangles: &'a [[u32; 3]],
    /// Radiance per vertex or per triangle.
    pub colors: MeshColors<'a>,
}

impl<'a> RasterMesh<'a> {
    /// Check index ranges and colour counts.
    pub fn validate(&self) -> Result<()> {
        let nv = self.positions.len();
        if let Some((i, t)) = self
            .triangles
            .iter()
            .enumerate()
            .find(|(_, t)| t.iter().any(|&v| v as usize >= nv))
        {
            return Err(Error::Config(format!(
                "mesh triangle {i} {t:?} uses a vertex out of range ({nv} vertices)"
            )));
        }
        let (n, want, what) = match self.colors {
            MeshColors::PerVertex(c) => (c.len(), nv, "vertices"),
            MeshColors::PerTriangle(c) => (c.len(), self.triangles.len(), "triangles"),
        };
        if n != want {
            return Err(Error::Config(format!(
                "mesh has {n} colours for {want} {what}"
            )));
        }
        Ok(())
    }
}

/// Counts from one rasterisation.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct RasterStats {
    /// Input triangles.
    pub triangles: usize,
    /// Screen triangles after culling and clipping.
    pub screen_triangles: usize,
    /// Input triangles that needed clipping (near plane or guard band).
    pub clipped: usize,
    /// Samples that passed the depth test (including later overwritten ones).
    pub fragments: u64,
}

/// A triangle ready for scan conversion.
#[derive(Clone, Copy, Debug)]
struct ScreenTri {
    /// Fixed-point vertex positions (1/256 pixel) in the supersampled image.
    x: [i32; 3],
    y: [i32; 3],
    /// 1/W per vertex.
    iw: [f32; 3],
    /// Colour per vertex divided by W (perspective-correct interpolation), or the flat colour
    /// in `c[0]` when `flat`.
    c: [Vec3; 3],
    flat: bool,
    /// Inclusive sample bounding box, clamped to the image.
    x0: u32,
    x1: u32,
    y0: u32,
    y1: u32,
}

/// A clip-space polygon vertex.
#[derive(Clone, Copy, Debug)]
struct ClipVert {
    p: Vec3,
    c: Vec3,
}

/// Rasterise a mesh seen from `view`.
///
/// Pipeline:
/// 1. every vertex goes to clip coordinates `(X, Y, W)` of the [`CameraFrame`] (`W` = depth
///    along the viewing direction);
/// 2. per triangle (parallel, in triangle order): trivial frustum rejection, facing from the
///    world-space normal (one-sided surfaces: back faces are drawn black, culled, or shaded like
///    the front, [`BackFaces`]), clipping against the near plane `W = near` and a guard band
///    (Sutherland–Hodgman, attributes interpolated linearly in clip space, which is exact), then
///    snapping to a fixed-point grid of 1/256 pixel;
/// 3. binning into bands of rows, then each band is rasterised in parallel: integer edge
///    functions with a consistent tie rule (an edge shared by two triangles covers each sample
///    exactly once: no cracks), samples at the centres of the supersampled pixels, depth test on
///    `1/W` (closest wins, ties keep the earlier triangle; back faces are pushed back by a
///    relative 1e-5 so that a coinciding front face always wins), colour interpolated
///    perspective-correctly (`Σ bᵢ cᵢ/Wᵢ / Σ bᵢ/Wᵢ`);
/// 4. the `ss × ss` samples of each pixel are averaged (box filter), uncovered samples count as
///    the background.
pub fn rasterize(mesh: &RasterMesh, view: &CameraView, opts: &RasterOptions) -> Result<Image> {
    rasterize_with_stats(mesh, view, opts).map(|(img, _)| img)
}

/// Render a radiosity solution: per-vertex radiosity B (W/m²) drawn as radiance B/π.
pub fn render_solution(
    mesh: &ColoredMesh,
    view: &CameraView,
    opts: &RasterOptions,
) -> Result<Image> {
    let opts = RasterOptions {
        scale: opts.scale / std::f32::consts::PI,
        ..opts.clone()
    };
    let m = RasterMesh {
        positions: &mesh.positions,
        triangles: &mesh.triangles,
        colors: MeshColors::PerVertex(&mesh.colors),
    };
    rasterize(&m, view, &opts)
}

/// [`rasterize`], also returning counts.
pub fn rasterize_with_stats(
    mesh: &RasterMesh,
    view: &CameraView,
    opts: &RasterOptions,
) -> Result<(Image, RasterStats)> {
    view.validate()?;
    mesh.validate()?;
    let ss = opts.supersample;
    if !(1..=16).contains(&ss) {
        return Err(Error::Config(format!(
            "supersampling {ss} must be between 1 and 16"
        )));
    }
    if !(opts.scale.is_finite() && opts.background.is_finite()) {
        return Err(Error::Config("scale and background must be finite".into()));
    }
    let frame = view.frame();
    let (sw, sh) = (view.width * ss, view.height * ss);
    if sw > 65536 || sh > 65536 {
        return Err(Error::Config(format!(
            "{}x{} pixels with {ss}x{ss} supersampling exceed 65536 samples per row or column",
            view.width, view.height
        )));
    }

    let clip: Vec<Vec3> = mesh
        .positions
        .par_iter()
        .map(|&p| frame.to_clip(p))
        .collect();
    let near = match opts.near {
        Some(n) if n > 0.0 && n.is_finite() => n,
        Some(n) => return Err(Error::Config(format!("near distance {n} must be > 0"))),
        None => auto_near(mesh.positions, &frame),
    };
    let setup = Setup {
        frame: &frame,
        clip: &clip,
        mesh,
        opts,
        near,
        sw,
        sh,
        guard_x: GUARD_PIXELS / (0.5 * sw as f32),
        guard_y: GUARD_PIXELS / (0.5 * sh as f32),
    };

    const CHUNK: usize = 16 * 1024;
    let per_chunk: Vec<(Vec<ScreenTri>, usize)> = mesh
        .triangles
        .par_chunks(CHUNK)
        .enumerate()
        .map(|(ci, tris)| {
            let mut out = Vec::with_capacity(tris.len());
            let mut clipped = 0;
            for (k, _) in tris.iter().enumerate() {
                clipped += setup.triangle(ci * CHUNK + k, &mut out) as usize;
            }
            (out, clipped)
        })
        .collect();
    let clipped = per_chunk.iter().map(|c| c.1).sum();
    let tris: Vec<ScreenTri> = if per_chunk.len() == 1 {
        per_chunk.into_iter().next().unwrap().0
    } else {
        let n = per_chunk.iter().map(|c| c.0.len()).sum();
        let mut v = Vec::with_capacity(n);
        for (c, _) in per_chunk {
            v.extend_from_slice(&c);
        }
        v
    };

    // Bin by band of supersampled rows (counting sort keeps triangle order inside a band).
    let band_rows = BAND_ROWS * ss;
    let nbands = view.height.div_ceil(BAND_ROWS) as usize;
    let mut start = vec![0u32; nbands + 1];
    for t in &tris {
        for b in (t.y0 / band_rows)..=(t.y1 / band_rows) {
            start[b as usize + 1] += 1;
        }
    }
    for b in 0..nbands {
        start[b + 1] += start[b];
    }
    let mut fill = start.clone();
    let mut binned = vec![0u32; start[nbands] as usize];
    for (i, t) in tris.iter().enumerate() {
        for b in (t.y0 / band_rows)..=(t.y1 / band_rows) {
            binned[fill[b as usize] as usize] = i as u32;
            fill[b as usize] += 1;
        }
    }

    let w = view.width as usize;
    let mut img = Image::new(view.width, view.height, opts.background);
    let fragments: u64 = img
        .pixels
        .par_chunks_mut(BAND_ROWS as usize * w)
        .enumerate()
        .map(|(b, out)| {
            let list = &binned[start[b] as usize..start[b + 1] as usize];
            raster_band(
                &tris,
                list,
                b as u32 * band_rows,
                out,
                sw,
                ss,
                opts.background,
            )
        })
        .sum();
    let stats = RasterStats {
        triangles: mesh.triangles.len(),
        screen_triangles: tris.len(),
        clipped,
        fragments,
    };
    Ok((img, stats))
}

/// Default near distance: 1e-5 × the farthest bounding-box corner's distance (at least 1e-6).
fn auto_near(positions: &[Vec3], frame: &CameraFrame) -> f32 {
    let bbox = positions
        .par_iter()
        .fold(
            || Aabb::EMPTY,
            |mut b, &p| {
                if p.is_finite() {
                    b.grow(p);
                }
                b
            },
        )
        .reduce(|| Aabb::EMPTY, |a, b| a.union(&b));
    if bbox.is_empty() {
        return 1e-6;
    }
    let mut far: f32 = 0.0;
    for i in 0..8 {
        let c = Vec3::new(
            if i & 1 == 0 { bbox.min.x } else { bbox.max.x },
            if i & 2 == 0 { bbox.min.y } else { bbox.max.y },
            if i & 4 == 0 { bbox.min.z } else { bbox.max.z },
        );
        far = far.max((c - frame.eye).length());
    }
    (far * 1e-5).max(1e-6)
}

struct Setup<'a> {
    frame: &'a CameraFrame,
    clip: &'a [Vec3],
    mesh: &'a RasterMesh<'a>,
    opts: &'a RasterOptions,
    near: f32,
    sw: u32,
    sh: u32,
    guard_x: f32,
    guard_y: f32,
}

impl Setup<'_> {
    /// Cull, clip and snap triangle `i`, pushing its screen triangles. Returns whether it was
    /// clipped.
    fn triangle(&self, i: usize, out: &mut Vec<ScreenTri>) -> bool {
        let t = self.mesh.triangles[i];
        let c = t.map(|v| self.clip[v as usize]);
        if !c.iter().all(|p| p.is_finite()) {
            return false;
        }
        // Trivial rejection against the view frustum.
        let all = |f: &dyn Fn(&Vec3) -> bool| c.iter().all(f);
        if all(&|p| p.z < self.near)
            || all(&|p| p.x > p.z)
            || all(&|p| p.x < -p.z)
            || all(&|p| p.y > p.z)
            || all(&|p| p.y < -p.z)
        {
            return false;
        }
        let [p0, p1, p2] = t.map(|v| self.mesh.positions[v as usize]);
        let facing = (p1 - p0).cross(p2 - p0).dot(self.frame.eye - p0);
        if facing == 0.0 || facing.is_nan() {
            return false; // seen edge-on (or degenerate): covers no area
        }
        let back = facing < 0.0;
        let k = self.opts.scale;
        let (cols, flat) = match self.mesh.colors {
            MeshColors::PerVertex(cv) => (t.map(|v| cv[v as usize] * k), false),
            MeshColors::PerTriangle(ct) => ([ct[i] * k; 3], true),
        };
        let cols = if back {
            match self.opts.back_faces {
                BackFaces::Black => [Vec3::ZERO; 3],
                BackFaces::Cull => return false,
                BackFaces::Shade => cols,
            }
        } else {
            cols
        };
        let inside = c.iter().all(|p| {
            p.z >= self.near && p.x.abs() <= self.guard_x * p.z && p.y.abs() <= self.guard_y * p.z
        });
        let verts = [0, 1, 2].map(|j| ClipVert {
            p: c[j],
            c: cols[j],
        });
        if inside {
            self.emit(&verts, flat, back, out);
            return false;
        }
        let poly = self.clip_polygon(&verts);
        for j in 1..poly.len().saturating_sub(1) {
            self.emit(&[poly[0], poly[j], poly[j + 1]], flat, back, out);
        }
        true
    }

    /// Sutherland–Hodgman against W ≥ near and the guard band |X| ≤ gx·W, |Y| ≤ gy·W.
    fn clip_polygon(&self, tri: &[ClipVert; 3]) -> Vec<ClipVert> {
        let (gx, gy, near) = (self.guard_x, self.guard_y, self.near);
        let planes: [&dyn Fn(Vec3) -> f32; 5] = [
            &|p: Vec3| p.z - near,
            &|p: Vec3| gx * p.z - p.x,
            &|p: Vec3| gx * p.z + p.x,
            &|p: Vec3| gy * p.z - p.y,
            &|p: Vec3| gy * p.z + p.y,
        ];
        let mut poly: Vec<ClipVert> = tri.to_vec();
        let mut next = Vec::with_capacity(9);
        for dist in planes {
            if poly.is_empty() {
                break;
            }
            next.clear();
            for j in 0..poly.len() {
                let a = poly[j];
                let b = poly[(j + 1) % poly.len()];
                let (da, db) = (dist(a.p), dist(b.p));
                if da >= 0.0 {
                    next.push(a);
                }
                if (da >= 0.0) != (db >= 0.0) {
                    let s = da / (da - db);
                    next.push(ClipVert {
                        p: a.p + (b.p - a.p) * s,
                        c: a.c + (b.c - a.c) * s,
                    });
                }
            }
            std::mem::swap(&mut poly, &mut next);
        }
        poly
    }

    /// Snap a clipped triangle to the fixed-point grid and push it if it covers a sample.
    /// Back faces get their depth pushed back by a relative 1e-5, so that a front face
    /// coinciding with a back face (explicit back-face triangles of two-sided meshes) wins the
    /// depth test whatever the triangle order.
    fn emit(&self, v: &[ClipVert; 3], flat: bool, back: bool, out: &mut Vec<ScreenTri>) {
        let depth_bias = if back { 1.0 - 1e-5 } else { 1.0 };
        let (sw, sh) = (self.sw as f32, self.sh as f32);
        let mut x = [0i32; 3];
        let mut y = [0i32; 3];
        let mut iw = [0f32; 3];
        let mut c = [Vec3::ZERO; 3];
        for j in 0..3 {
            let p = v[j].p;
            let inv = 1.0 / p.z;
            let fx = (p.x * inv + 1.0) * 0.5 * sw;
            let fy = (1.0 - p.y * inv) * 0.5 * sh;
            x[j] = (fx * SUB).round() as i32;
            y[j] = (fy * SUB).round() as i32;
            iw[j] = inv * depth_bias;
            c[j] = if flat { v[j].c } else { v[j].c * iw[j] };
        }
        let area = edge(x[0], y[0], x[1], y[1], x[2], y[2]);
        if area == 0 {
            return;
        }
        if area < 0 {
            x.swap(1, 2);
            y.swap(1, 2);
            iw.swap(1, 2);
            c.swap(1, 2);
        }
        // Samples sit at pixel centres (k + 0.5) · SUB; the box of centres inside the extent.
        let half = 1i64 << (SUB_BITS - 1);
        let lo = |m: i32| ((m as i64 - half + (1 << SUB_BITS) - 1) >> SUB_BITS).max(0);
        let hi = |m: i32, n: u32| ((m as i64 - half) >> SUB_BITS).min(n as i64 - 1);
        let x0 = lo(*x.iter().min().unwrap());
        let x1 = hi(*x.iter().max().unwrap(), self.sw);
        let y0 = lo(*y.iter().min().unwrap());
        let y1 = hi(*y.iter().max().unwrap(), self.sh);
        if x0 > x1 || y0 > y1 {
            return;
        }
        out.push(ScreenTri {
            x,
            y,
            iw,
            c,
            flat,
            x0: x0 as u32,
            x1: x1 as u32,
            y0: y0 as u32,
            y1: y1 as u32,
        });
    }
}

/// Edge function of a→b at p: positive on one side, twice the signed area of (a, b, p).
#[inline]
fn edge(ax: i32, ay: i32, bx: i32, by: i32, px: i32, py: i32) -> i64 {
    (bx as i64 - ax as i64) * (py as i64 - ay as i64)
        - (by as i64 - ay as i64) * (px as i64 - ax as i64)
}

/// Rasterise the triangles `list` into the band starting at supersampled row `row0`, then
/// box-filter into `out` (the band's output rows). Returns the number of depth-test passes.
fn raster_band(
    tris: &[ScreenTri],
    list: &[u32],
    row0: u32,
    out: &mut [Vec3],
    sw: u32,
    ss: u32,
    background: Vec3,
) -> u64 {
    let out_w = (sw / ss) as usize;
    let out_rows = out.len() / out_w;
    let rows = out_rows as u32 * ss;
    let n = (sw * rows) as usize;
    let mut depth = vec![0f32; n];
    let mut color = vec![background; n];
    let mut fragments = 0u64;
    let row1 = row0 + rows - 1;
    let one = 1i64 << SUB_BITS;
    let half = one >> 1;
    for &ti in list {
        let t = &tris[ti as usize];
        let ya = t.y0.max(row0);
        let yb = t.y1.min(row1);
        if ya > yb {
            continue;
        }
        let (x, y) = (t.x, t.y);
        // Edge k is opposite vertex k: from vertex k+1 to vertex k+2.
        let mut w_row = [0i64; 3];
        let mut dx = [0i64; 3];
        let mut dy = [0i64; 3];
        let mut bias = [0i64; 3];
        let px = t.x0 as i64 * one + half;
        let py = ya as i64 * one + half;
        for k in 0..3 {
            let (a, b) = ((k + 1) % 3, (k + 2) % 3);
            let ex = x[b] as i64 - x[a] as i64;
            let ey = y[b] as i64 - y[a] as i64;
            // Tie rule: samples exactly on an edge belong to it when the edge points "down", or
            // is horizontal pointing "left"; the neighbour traverses the edge the other way.
            let owns = ey > 0 || (ey == 0 && ex < 0);
            bias[k] = if owns { 0 } else { -1 };
            w_row[k] = ex * (py - y[a] as i64) - ey * (px - x[a] as i64) + bias[k];
            dx[k] = -ey * one;
            dy[k] = ex * one;
        }
        let area = (edge(x[0], y[0], x[1], y[1], x[2], y[2])) as f64;
        let inv_area = (1.0 / area) as f32;
        for sy in ya..=yb {
            let base = ((sy - row0) * sw) as usize;
            let mut w = w_row;
            for sx in t.x0..=t.x1 {
                if (w[0] | w[1] | w[2]) >= 0 {
                    // Weights without the tie bias.
                    let wt = [
                        (w[0] - bias[0]) as f32,
                        (w[1] - bias[1]) as f32,
                        (w[2] - bias[2]) as f32,
                    ];
                    let b = [wt[0] * inv_area, wt[1] * inv_area, wt[2] * inv_area];
                    let iw = b[0] * t.iw[0] + b[1] * t.iw[1] + b[2] * t.iw[2];
                    let idx = base + sx as usize;
                    if iw > depth[idx] {
                        depth[idx] = iw;
                        color[idx] = if t.flat {
                            t.c[0]
                        } else {
                            (b[0] * t.c[0] + b[1] * t.c[1] + b[2] * t.c[2]) / iw
                        };
                        fragments += 1;
                    }
                }
                w[0] += dx[0];
                w[1] += dx[1];
                w[2] += dx[2];
            }
            w_row[0] += dy[0];
            w_row[1] += dy[1];
            w_row[2] += dy[2];
        }
    }
    // Box filter ss × ss samples into each output pixel.
    let inv = 1.0 / (ss * ss) as f32;
    for oy in 0..out_rows {
        for ox in 0..out_w {
            let mut s = Vec3::ZERO;
            for j in 0..ss as usize {
                let row = (oy * ss as usize + j) * sw as usize;
                for i in 0..ss as usize {
                    s += color[row + ox * ss as usize + i];
                }
            }
            out[oy * out_w + ox] = s * inv;
        }
    }
    fragments
}
