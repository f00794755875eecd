//! Mode `image`: the scene camera's view at half size drawn three ways (per-vertex image,
//! leaf radiosity at the first hit, path tracer); mean luminances, the objects behind the gap,
//! and images in $TMPDIR/hirad-audit.
use crate::elements::{leaf_at, object_index, root, short_name};
use crate::opts::Opts;
use glam::Vec3;
use hirad::metrics::luminance;
use hirad::radiosity::output::radiosity_mesh;
use hirad::radiosity::Solution;
use hirad::ray::RayCaster;
use hirad::render::{render_solution, BackFaces, CameraView, Image, PathTracer, RasterOptions};
use hirad::rng::SplitMix64;
use hirad::scene::Scene;
use rayon::prelude::*;
use std::f64::consts::PI;

/// Pixels of one object binned 10 × 8 over the two widest axes of their hit points' box:
/// leaf / path-traced mean luminance per bin (rows from the top of the second axis).
fn image_bins(hits: &[(Vec3, f64, f64)]) {
    let (lo, hi) = hits.iter().fold(
        (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
        |(a, b), h| (a.min(h.0), b.max(h.0)),
    );
    let ext = hi - lo;
    let mut ax = [0usize, 1, 2];
    ax.sort_by(|&a, &b| ext[b].total_cmp(&ext[a]));
    let (u, v) = (ax[0].min(ax[1]), ax[0].max(ax[1]));
    const NU: usize = 10;
    const NV: usize = 8;
    let mut bins = vec![(0u64, 0.0f64, 0.0f64); NU * NV];
    for &(p, l, t) in hits {
        let bu = (((p[u] - lo[u]) / ext[u].max(1e-9)) * NU as f32) as usize;
        let bv = (((p[v] - lo[v]) / ext[v].max(1e-9)) * NV as f32) as usize;
        let b = &mut bins[bv.min(NV - 1) * NU + bu.min(NU - 1)];
        b.0 += 1;
        b.1 += l;
        b.2 += t;
    }
    println!(
        "pixels of --object by axis {u} ({:.2}..{:.2}, columns) and axis {v} ({:.2}..{:.2}, rows from the top): leaf/path mean luminance, pixels",
        lo[u], hi[u], lo[v], hi[v]
    );
    for r in (0..NV).rev() {
        let line: Vec<String> = (0..NU)
            .map(|c| {
                let b = bins[r * NU + c];
                if b.0 == 0 {
                    format!("{:>15}", "-")
                } else {
                    format!(
                        "{:5.1}/{:5.1} {:>3}",
                        b.1 / b.0 as f64,
                        b.2 / b.0 as f64,
                        b.0
                    )
                }
            })
            .collect();
        println!("{}", line.join(" "));
    }
}

/// Mean luminance of the view drawn three ways, and the visible objects behind the gap.
pub fn image(o: &Opts, scene: &Scene, caster: &RayCaster, sol: &Solution) {
    let mut view = CameraView::from_camera(&scene.default_camera());
    view.width = (view.width / 2).max(1);
    view.height = (view.height / 2).max(1);
    if let Some(f) = o.fov {
        view.fov_deg = f;
    }
    let raster = RasterOptions {
        back_faces: if o.two_sided {
            BackFaces::Cull
        } else {
            BackFaces::Black
        },
        ..Default::default()
    };
    let gouraud =
        render_solution(&radiosity_mesh(sol, scene, false), &view, &raster).expect("raster");
    let pt = PathTracer::new(scene, caster, &o.reference_options());
    let frame = view.frame();
    let spp = (o.samples / 100).max(1);
    let el = &sol.elements;
    // Per object: (pixels, leaf luminance sum, path-traced luminance sum).
    // Per image row: per object (pixels, leaf luminance sum, path-traced luminance sum), and
    // per pixel (leaf radiance, path-traced radiance).
    // With --object: (hit point, leaf luminance, path-traced luminance) of its pixels.
    type Row = (
        Vec<(u64, f64, f64)>,
        Vec<(Vec3, Vec3)>,
        Vec<(Vec3, f64, f64)>,
    );
    let focus = o.object.as_deref().map(|n| object_index(scene, n));
    let rows: Vec<Row> = (0..view.height)
        .into_par_iter()
        .map(|y| {
            let mut acc = vec![(0u64, 0.0f64, 0.0f64); scene.objects.len() + 1];
            let mut px = Vec::with_capacity(view.width as usize);
            let mut hits = Vec::new();
            let mut rng = SplitMix64::for_item(0xA0D1, y as u64);
            for x in 0..view.width {
                let d = frame.direction(x as f32 + 0.5, y as f32 + 0.5).normalize();
                let mut ptc = Vec3::ZERO;
                for _ in 0..spp {
                    ptc += pt.radiance(frame.eye, d, &mut rng);
                }
                ptc /= spp as f32;
                let ptl = luminance(ptc);
                let (obj, leaf) = match caster.closest(frame.eye, d, 0.0, f32::INFINITY) {
                    Some(h) => {
                        let t = h.tri;
                        let p = frame.eye + d * h.t;
                        let back = scene.normals[t as usize].dot(d) > 0.0;
                        let b = if back && !o.two_sided {
                            glam::DVec3::ZERO
                        } else {
                            el.b[leaf_at(sol, root(sol, t, back), p) as usize]
                        };
                        px.push((b.as_vec3() / std::f32::consts::PI, ptc));
                        if focus == Some(scene.tri_object[t as usize] as usize) {
                            hits.push((p, luminance(b.as_vec3()) / PI, ptl));
                        }
                        (
                            scene.tri_object[t as usize] as usize,
                            luminance(b.as_vec3()) / PI,
                        )
                    }
                    None => {
                        px.push((Vec3::ZERO, ptc));
                        (scene.objects.len(), 0.0)
                    }
                };
                let a = &mut acc[obj];
                a.0 += 1;
                a.1 += leaf;
                a.2 += ptl;
            }
            (acc, px, hits)
        })
        .collect();
    let mut tot = vec![(0u64, 0.0f64, 0.0f64); scene.objects.len() + 1];
    let mut img_leaf = Image::new(view.width, view.height, Vec3::ZERO);
    let mut img_pt = img_leaf.clone();
    let mut hits = Vec::new();
    for (y, (r, px, hs)) in rows.into_iter().enumerate() {
        hits.extend(hs);
        for (x, (l, p)) in px.into_iter().enumerate() {
            img_leaf.set(x as u32, y as u32, l);
            img_pt.set(x as u32, y as u32, p);
        }
        for (t, a) in tot.iter_mut().zip(r) {
            t.0 += a.0;
            t.1 += a.1;
            t.2 += a.2;
        }
    }
    let dir = std::env::temp_dir().join("hirad-audit");
    std::fs::create_dir_all(&dir).ok();
    img_leaf
        .write_exr(&dir.join("image_leaf.exr"))
        .expect("exr");
    img_pt.write_exr(&dir.join("image_path.exr")).expect("exr");
    gouraud
        .write_exr(&dir.join("image_gouraud.exr"))
        .expect("exr");
    // Side by side (leaf | path tracer | ratio: red where the leaf is darker, green brighter).
    let (w, h) = (view.width, view.height);
    let mut side = Image::new(3 * w, h, Vec3::ZERO);
    // The first two panels are exposed to put the path tracer's mean luminance at 0.3.
    let mean_pt = (0..h)
        .flat_map(|y| (0..w).map(move |x| (x, y)))
        .map(|(x, y)| luminance(img_pt.get(x, y)))
        .sum::<f64>()
        / (w * h) as f64;
    let k = (0.3 / mean_pt.max(1e-12)) as f32;
    for y in 0..h {
        for x in 0..w {
            let (l, p) = (img_leaf.get(x, y), img_pt.get(x, y));
            side.set(x, y, l * k);
            side.set(w + x, y, p * k);
            // Ratio of 9×9 box means (the path tracer's pixels are noisy).
            let (mut sl, mut sp) = (0.0, 0.0);
            for yy in y.saturating_sub(4)..(y + 5).min(h) {
                for xx in x.saturating_sub(4)..(x + 5).min(w) {
                    sl += luminance(img_leaf.get(xx, yy));
                    sp += luminance(img_pt.get(xx, yy));
                }
            }
            let r = (sl / f64::max(sp, 1e-9)) as f32;
            let c = if r < 1.0 {
                Vec3::new(1.0 - r, 0.0, 0.0) * 2.0
            } else {
                Vec3::new(0.0, (r - 1.0).min(1.0), 0.0) * 2.0
            };
            side.set(2 * w + x, y, c);
        }
    }
    side.write_png(&dir.join("image_side.png"), 1.0)
        .expect("png");
    println!("images: {}/image_{{leaf,path,gouraud}}.exr", dir.display());
    let n = (view.width * view.height) as f64;
    let (leaf, ptm) = tot.iter().fold((0.0, 0.0), |s, a| (s.0 + a.1, s.1 + a.2));
    let gm = gouraud.pixels.iter().map(|&p| luminance(p)).sum::<f64>() / n;
    println!(
        "{}x{}, {spp} paths per pixel: mean luminance path tracer {:.5}, per-vertex image {:.5} ({:.4}), leaf at the first hit {:.5} ({:.4})",
        view.width,
        view.height,
        ptm / n,
        gm,
        gm / (ptm / n),
        leaf / n,
        leaf / ptm
    );
    let mut idx: Vec<usize> = (0..tot.len()).filter(|&i| tot[i].0 > 0).collect();
    idx.sort_by(|&a, &b| {
        (tot[b].1 - tot[b].2)
            .abs()
            .total_cmp(&(tot[a].1 - tot[a].2).abs())
    });
    println!(
        "{:40} {:>8} {:>10} {:>10} {:>7} {:>9}",
        "object", "pixels", "leaf", "path", "ratio", "Δ/total"
    );
    if !hits.is_empty() {
        image_bins(&hits);
    }
    for &i in idx.iter().take(25) {
        let name: String = if i < scene.objects.len() {
            short_name(scene, i)
        } else {
            "(nothing)".into()
        };
        let t = tot[i];
        println!(
            "{name:40} {:8} {:10.4} {:10.4} {:7.3} {:9.4}",
            t.0,
            t.1 / t.0 as f64,
            t.2 / t.0 as f64,
            t.1 / t.2,
            (t.1 - t.2) / ptm
        );
    }
}
