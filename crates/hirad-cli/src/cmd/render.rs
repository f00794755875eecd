//! `hirad render SOLUTION.glb|.ply --image out.png`: rasterise a radiosity solution mesh. The
//! mesh's vertex colours are radiosity B in W/m²; pixels are radiance B/π (so the image compares
//! directly with `hirad reference`). The viewpoint is the default camera of `--scene` when given,
//! else a view of the mesh's bounding box, overridden by the camera flags.
//!
//! `--gather N` (with `--scene`) makes the image by final gather instead
//! (`hirad::render::gather`): exact direct light and shadows, indirect light read from the
//! solution; two-sided when the solution has back faces or the scene is two-sided.

use super::image_args::{CameraArgs, GatherArgs, ImageArgs, RasterArgs};
use crate::progress::Bars;
use crate::Global;
use hirad::geom::Aabb;
use hirad::render::{render_solution, CameraView};
use hirad::scene::export::read_colored_mesh;
use hirad::scene::SceneOptions;
use serde::Serialize;
use std::path::{Path, PathBuf};

#[derive(clap::Args, Debug)]
pub struct Args {
    /// Solution mesh (`.glb` or `.ply` with linear vertex colours = radiosity B).
    pub solution: PathBuf,
    /// Take the default viewpoint (and up axis) of this scene (file or built-in name).
    #[arg(long)]
    pub scene: Option<String>,
    #[command(flatten)]
    pub camera: CameraArgs,
    #[command(flatten)]
    pub raster: RasterArgs,
    #[command(flatten)]
    pub gather: GatherArgs,
    /// Seed of the final gather's per-pixel generators.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Final gather: give every surface a diffuse back face even if the solution has none.
    #[arg(long)]
    pub two_sided: bool,
    #[command(flatten)]
    pub out: ImageArgs,
}

#[derive(Serialize)]
struct Report {
    solution: String,
    triangles: usize,
    vertices: usize,
    width: u32,
    height: u32,
    supersample: u32,
    #[serde(skip_serializing_if = "Option::is_none")]
    gather: Option<u32>,
    #[serde(skip_serializing_if = "Option::is_none")]
    gather_stats: Option<hirad::render::GatherStats>,
    /// Final gather: seconds to build the accelerator and match the solution to the scene.
    #[serde(skip_serializing_if = "Option::is_none")]
    prepare_seconds: Option<f64>,
    seconds: f64,
    mean_radiance: [f32; 3],
    images: Vec<String>,
}

pub fn run(a: Args, g: &Global) -> anyhow::Result<()> {
    let mesh = read_colored_mesh(&a.solution)?;
    if a.gather.gather.is_some() && a.scene.is_none() {
        anyhow::bail!(hirad::Error::Config(
            "--gather needs --scene: the scene the solution was solved from".into()
        ));
    }
    let mut scene = None;
    let base = match &a.scene {
        Some(s) => {
            let opts = SceneOptions {
                up: a.camera.scene_up(),
                ..Default::default()
            };
            let sc = super::load_scene(s, &opts)?;
            let v = CameraView::from_camera(&sc.default_camera());
            scene = Some(sc);
            v
        }
        None => {
            let bbox = Aabb::from_points(mesh.positions.iter());
            if bbox.is_empty() {
                anyhow::bail!(hirad::Error::input(&a.solution, "the mesh has no vertices"));
            }
            let up = a.camera.overrides().up.unwrap_or(glam::Vec3::Y);
            CameraView::looking_at_box(&bbox, up, 512, 512)
        }
    };
    let view = a.camera.apply(base)?;
    let t0 = std::time::Instant::now();
    let (img, gather_stats, prepare_seconds) = match (a.gather.gather, &scene) {
        (Some(n), Some(sc)) => {
            let cancel = super::cancel_on_ctrl_c(None);
            let bars = Bars::new(g.quiet || g.json);
            let r = a.gather.gather(
                n,
                sc,
                &mesh,
                &view,
                a.seed,
                a.two_sided,
                &bars,
                Some(&cancel),
            )?;
            (r.image, Some(r.stats), Some(r.prepare_seconds))
        }
        _ => (
            render_solution(&mesh, &view, &a.raster.options())?,
            None,
            None,
        ),
    };
    let seconds = t0.elapsed().as_secs_f64();
    let stem = a
        .solution
        .file_stem()
        .and_then(|s| s.to_str())
        .map(super::reference::sanitize)
        .unwrap_or_else(|| "render".into());
    let files = a.out.write(&img, Path::new("hirad-out"), &stem)?;
    let r = Report {
        solution: a.solution.display().to_string(),
        triangles: mesh.triangles.len(),
        vertices: mesh.positions.len(),
        width: view.width,
        height: view.height,
        supersample: a.raster.ss,
        gather: a.gather.gather,
        gather_stats,
        prepare_seconds,
        seconds,
        mean_radiance: img.mean().to_array(),
        images: files.iter().map(|f| f.display().to_string()).collect(),
    };
    if g.json {
        return super::print_json(&r);
    }
    match r.gather {
        Some(n) => println!(
            "{}: {} triangles, {}x{} final gather {} samples per pixel in {:.3} s",
            r.solution, r.triangles, r.width, r.height, n, r.seconds
        ),
        None => println!(
            "{}: {} triangles, {}x{} ({}x{} samples) in {:.3} s",
            r.solution, r.triangles, r.width, r.height, r.supersample, r.supersample, r.seconds
        ),
    }
    for f in &r.images {
        println!("wrote {f}");
    }
    Ok(())
}
