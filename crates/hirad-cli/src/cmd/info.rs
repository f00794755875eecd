//! `hirad info SCENE`: counts, area, bounding box, materials, emitters, load time and the
//! estimated memory of a default solve (`radiosity::memory::estimate`).

use crate::Global;
use hirad::radiosity::memory::{self, mb};
use hirad::scene::{SceneOptions, UpAxis};

/// Scene-loading options shared by subcommands that load a scene (flatten into their `Args`).
#[derive(clap::Args, Debug, Clone)]
pub struct LoadArgs {
    /// Up axis of the scene, overriding what the file says (y or z) [default: the file's, else
    /// y].
    #[arg(long, value_parser = parse_up)]
    pub up: Option<UpAxis>,
    #[command(flatten)]
    pub reflectance: SceneFileArgs,
}

impl LoadArgs {
    /// The library's scene options.
    pub fn options(&self) -> SceneOptions {
        self.reflectance.options(self.up)
    }
}

/// `--max-reflectance` and `--mgf-divisions`, for commands whose `--up` is the camera flags'
/// (`CameraArgs`).
#[derive(clap::Args, Debug, Clone)]
pub struct SceneFileArgs {
    /// Reflectance channels equal to 1 are clamped to this value.
    #[arg(long, default_value_t = 0.95)]
    pub max_reflectance: f32,
    /// Quarter-circle divisions of the curved primitives of MGF files (sphere, cylinder, cone,
    /// ring, torus), 1 to 64; 4 is RenderPark's default.
    #[arg(long, default_value_t = hirad::scene::mgf::DEFAULT_DIVISIONS)]
    pub mgf_divisions: usize,
}

impl SceneFileArgs {
    /// The library's scene options with up axis `up`.
    pub fn options(&self, up: Option<UpAxis>) -> SceneOptions {
        SceneOptions {
            max_reflectance: self.max_reflectance,
            up,
            mgf_divisions: self.mgf_divisions,
        }
    }
}

fn parse_up(s: &str) -> Result<UpAxis, String> {
    match s.to_ascii_lowercase().as_str() {
        "y" | "+y" => Ok(UpAxis::Y),
        "z" | "+z" => Ok(UpAxis::Z),
        _ => Err(format!("up axis must be y or z, got '{s}'")),
    }
}

#[derive(clap::Args, Debug)]
pub struct Args {
    /// Scene: a file path (.obj, .gltf, .glb, .ply, .toml) or a built-in name.
    pub scene: String,
    #[command(flatten)]
    pub load: LoadArgs,
}

pub fn run(args: Args, g: &Global) -> anyhow::Result<()> {
    let scene = super::load_scene(&args.scene, &args.load.options())?;
    let s = scene.summary();
    // A default solve, its image from the default camera included.
    let cfg = hirad::radiosity::SolverConfig {
        two_sided: scene.two_sided,
        ..Default::default()
    };
    let cam = scene.default_camera();
    let image = cam.width as u64 * cam.height as u64 * 64;
    let mem = memory::estimate(&scene, &cfg, rayon::current_num_threads(), image);
    if g.json {
        let mut v = serde_json::to_value(&s)?;
        v["memory_estimate"] = serde_json::to_value(&mem)?;
        return super::print_json(&v);
    }
    let rows: Vec<(&str, String)> = vec![
        ("scene", s.name.clone()),
        (
            "source",
            s.source
                .as_ref()
                .map(|p| p.display().to_string())
                .unwrap_or_else(|| "built-in".into()),
        ),
        ("triangles", s.triangles.to_string()),
        ("vertices", s.vertices.to_string()),
        ("objects", s.objects.to_string()),
        ("materials", s.materials.to_string()),
        (
            "emitters",
            format!(
                "{} materials, {} triangles",
                s.emitter_materials, s.emitter_triangles
            ),
        ),
        ("degenerate dropped", s.degenerate_dropped.to_string()),
        (
            "clamped rho",
            if s.clamped_materials.is_empty() {
                "none".into()
            } else {
                format!(
                    "{} ({})",
                    s.clamped_materials.len(),
                    s.clamped_materials.join(", ")
                )
            },
        ),
        ("total area", format!("{:.6} scene units²", s.total_area)),
        (
            "bbox",
            format!(
                "({:.3}, {:.3}, {:.3}) -> ({:.3}, {:.3}, {:.3}) scene units",
                s.bbox_min.x, s.bbox_min.y, s.bbox_min.z, s.bbox_max.x, s.bbox_max.y, s.bbox_max.z
            ),
        ),
        (
            "up",
            match s.up {
                UpAxis::Y => "+Y".into(),
                UpAxis::Z => "+Z".into(),
            },
        ),
        (
            "two-sided",
            if s.two_sided {
                "yes (the file gives every surface a back face)".into()
            } else if s.two_sided_materials > 0 {
                format!(
                    "{} of {} materials (the file's; --two-sided gives every surface a back face)",
                    s.two_sided_materials, s.materials
                )
            } else {
                "no (--two-sided gives every surface a back face)".into()
            },
        ),
        (
            "emitted power",
            format!(
                "({:.6e}, {:.6e}, {:.6e}) W per RGB channel (scene units as metres)",
                s.emitted_power[0], s.emitted_power[1], s.emitted_power[2]
            ),
        ),
        (
            "sun",
            s.sun
                .map(|sun| {
                    format!(
                        "direction {:?}, irradiance {:?} W/m²",
                        sun.direction.to_array(),
                        sun.irradiance.to_array()
                    )
                })
                .unwrap_or_else(|| "none".into()),
        ),
        (
            "sky",
            s.sky
                .map(|k| format!("radiance {:?} W/(m²·sr)", k.to_array()))
                .unwrap_or_else(|| "none".into()),
        ),
        (
            "cameras",
            if s.cameras.is_empty() {
                "none".into()
            } else {
                s.cameras.join(", ")
            },
        ),
        ("load time", format!("{:.3} s", s.load_seconds)),
        (
            "memory (estimate)",
            format!(
                "~{} for a default solve: {} before refinement (scene {}, cluster tree, ray \
                 layout, overlaps, element arena ~{}, process {}, image {}) + refinement ~{} \
                 ({} B per triangle side in all, measured; --max-memory bounds it)",
                mb(mem.total),
                mb(mem.fixed),
                mb(mem.scene),
                mb(mem.tree + mem.layout + mem.covers + mem.elements),
                mb(mem.process),
                mb(mem.reserved),
                mb(mem.solve),
                memory::SOLVE_PER_ROOT
            ),
        ),
    ];
    for (k, v) in rows {
        println!("{k:<20} {v}");
    }
    Ok(())
}
