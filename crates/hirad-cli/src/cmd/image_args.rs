//! Flags shared by every command that makes an image (`solve --image`, `render`, `reference`):
//! camera overrides, output file and exposure, rasteriser and final-gather options, and their
//! parsers.
//!
//! `--up` takes either an axis (`y` or `z`: the scene's up axis, which also becomes the camera's
//! up vector) or a vector `x,y,z` (the camera's up vector only), so that one flag serves both
//! meanings the spec gives it. Commands that load a scene and flatten [`CameraArgs`] take the
//! scene's up axis from [`CameraArgs::scene_up`] instead of flattening `info::LoadArgs`.

use anyhow::Context;
use glam::Vec3;
use hirad::cluster::{ClusterConfig, ClusterTree, Strategy};
use hirad::progress::Progress;
use hirad::ray::RayCaster;
use hirad::render::{
    BackFaces, CameraOverrides, CameraView, GatherOptions, GatherStats, Gatherer, Image, Lookup,
    RasterOptions, SolutionLookup,
};
use hirad::scene::export::ColoredMesh;
use hirad::scene::Scene;
use hirad::scene::UpAxis;
use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;

/// The value of `--up`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum UpArg {
    /// `y` or `z`: scene up axis (and camera up).
    Axis(UpAxis),
    /// `x,y,z`: camera up vector.
    Vector(Vec3),
}

/// Parse `x,y,z` (three finite numbers separated by commas).
pub fn parse_vec3(s: &str) -> Result<Vec3, String> {
    let parts: Vec<&str> = s.split(',').map(str::trim).collect();
    if parts.len() != 3 {
        return Err(format!("expected x,y,z, got '{s}'"));
    }
    let mut v = [0f32; 3];
    for (i, p) in parts.iter().enumerate() {
        v[i] = p
            .parse::<f32>()
            .ok()
            .filter(|x| x.is_finite())
            .ok_or_else(|| format!("'{p}' is not a finite number (in '{s}')"))?;
    }
    Ok(Vec3::from(v))
}

/// Parse `WxH` (two positive integers, at most 65536 each).
pub fn parse_size(s: &str) -> Result<(u32, u32), String> {
    let (w, h) = s
        .to_ascii_lowercase()
        .split_once('x')
        .map(|(a, b)| (a.trim().to_string(), b.trim().to_string()))
        .ok_or_else(|| format!("expected WxH, got '{s}'"))?;
    let num = |t: &str| {
        t.parse::<u32>()
            .ok()
            .filter(|&n| (1..=65536).contains(&n))
            .ok_or_else(|| format!("'{t}' is not a size between 1 and 65536 (in '{s}')"))
    };
    Ok((num(&w)?, num(&h)?))
}

/// Parse `--up`: `y`, `z` or `x,y,z`.
pub fn parse_up(s: &str) -> Result<UpArg, String> {
    match s.trim().to_ascii_lowercase().as_str() {
        "y" | "+y" => Ok(UpArg::Axis(UpAxis::Y)),
        "z" | "+z" => Ok(UpArg::Axis(UpAxis::Z)),
        _ => parse_vec3(s)
            .map(UpArg::Vector)
            .map_err(|e| format!("--up takes an axis (y or z) or a vector x,y,z: {e}")),
    }
}

/// Parse a vertical field of view in degrees, (0, 180).
pub fn parse_fov(s: &str) -> Result<f32, String> {
    s.trim()
        .parse::<f32>()
        .ok()
        .filter(|f| *f > 0.0 && *f < 180.0)
        .ok_or_else(|| format!("fov must be a number of degrees in (0, 180), got '{s}'"))
}

/// Camera flags overriding the scene's default viewpoint.
#[derive(clap::Args, Debug, Clone, Default)]
pub struct CameraArgs {
    /// Eye position x,y,z [default: the scene camera's].
    #[arg(long, value_parser = parse_vec3, allow_hyphen_values = true)]
    pub eye: Option<Vec3>,
    /// Point looked at x,y,z [default: the scene camera's].
    #[arg(long, value_parser = parse_vec3, allow_hyphen_values = true)]
    pub target: Option<Vec3>,
    /// Up: an axis `y`/`z` (scene up axis and camera up) or a camera up vector x,y,z [default:
    /// the scene's up axis].
    #[arg(long, value_parser = parse_up, allow_hyphen_values = true)]
    pub up: Option<UpArg>,
    /// Vertical field of view, degrees [default: the scene camera's].
    #[arg(long, value_parser = parse_fov)]
    pub fov: Option<f32>,
    /// Image size WxH in pixels [default: the scene camera's].
    #[arg(long, value_parser = parse_size)]
    pub size: Option<(u32, u32)>,
}

impl CameraArgs {
    /// The scene up axis given by `--up y|z`, if any.
    pub fn scene_up(&self) -> Option<UpAxis> {
        match self.up {
            Some(UpArg::Axis(a)) => Some(a),
            _ => None,
        }
    }

    /// The camera overrides of these flags.
    pub fn overrides(&self) -> CameraOverrides {
        CameraOverrides {
            eye: self.eye,
            target: self.target,
            up: self.up.map(|u| match u {
                UpArg::Axis(a) => a.vector(),
                UpArg::Vector(v) => v,
            }),
            fov_deg: self.fov,
            size: self.size,
        }
    }

    /// `base` with the overrides applied, validated.
    pub fn apply(&self, base: CameraView) -> anyhow::Result<CameraView> {
        let mut v = base;
        v.apply(&self.overrides());
        v.validate()?;
        Ok(v)
    }
}

/// Output image flags.
#[derive(clap::Args, Debug, Clone, Default)]
pub struct ImageArgs {
    /// Output image: `.exr` (linear) or `.png` (sRGB), by extension; a directory (existing, or
    /// a path without extension) receives both [default: none; `solve` writes image.exr and
    /// image.png into --out].
    #[arg(long)]
    pub image: Option<PathBuf>,
    /// PNG exposure in stops (pixels × 2^exposure before the sRGB transfer and clamping), or
    /// `auto`: the image's white luminance (99th percentile, as `hirad diff` takes it) maps to 1;
    /// the stops chosen are logged. Give the same number to images that are to be compared.
    #[arg(long, default_value = "0", value_parser = parse_exposure, allow_hyphen_values = true)]
    pub exposure: Exposure,
}

/// The value of `--exposure`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Exposure {
    /// Stops: pixels × 2^stops.
    Stops(f32),
    /// From the image: its white luminance maps to 1.
    Auto,
}

impl Default for Exposure {
    /// 0 stops, as the flag's default.
    fn default() -> Self {
        Exposure::Stops(0.0)
    }
}

impl Exposure {
    /// Stops for `img`.
    pub fn stops(self, img: &Image) -> f32 {
        match self {
            Exposure::Stops(s) => s,
            Exposure::Auto => auto_exposure(img),
        }
    }
}

/// Stops that map the white luminance of `img` (the 99th-percentile luminance, see
/// [`hirad::metrics::white_luminance`]) to 1; 0 for a black image.
pub fn auto_exposure(img: &Image) -> f32 {
    let y = hirad::metrics::white_luminance(img);
    if y > 0.0 && y.is_finite() {
        (-y.log2()) as f32
    } else {
        0.0
    }
}

/// Parse `--exposure`: a finite number of stops or `auto`.
pub fn parse_exposure(s: &str) -> Result<Exposure, String> {
    if s.trim().eq_ignore_ascii_case("auto") {
        return Ok(Exposure::Auto);
    }
    s.trim()
        .parse::<f32>()
        .ok()
        .filter(|x| x.is_finite())
        .map(Exposure::Stops)
        .ok_or_else(|| format!("exposure must be a number of stops or `auto`, got '{s}'"))
}

impl ImageArgs {
    /// Write `img` to `--image` (or to `default_dir` when it is absent); `stem` names the files
    /// written into a directory. Returns the files written.
    pub fn write(
        &self,
        img: &Image,
        default_dir: &Path,
        stem: &str,
    ) -> anyhow::Result<Vec<PathBuf>> {
        let target = self
            .image
            .clone()
            .unwrap_or_else(|| default_dir.to_path_buf());
        let stops = self.exposure.stops(img);
        if self.exposure == Exposure::Auto {
            tracing::info!("--exposure auto: {stops:.3} stops");
            eprintln!("exposure auto: {stops:.3} stops");
        }
        write_image(img, &target, stops, stem)
    }
}

/// Write an image to `path`: one file when it ends in `.exr` or `.png`, else `path` is a
/// directory that receives `stem.exr` and `stem.png`.
pub fn write_image(
    img: &Image,
    path: &Path,
    exposure: f32,
    stem: &str,
) -> anyhow::Result<Vec<PathBuf>> {
    if !exposure.is_finite() {
        anyhow::bail!(hirad::Error::Config(format!(
            "exposure {exposure} is not finite"
        )));
    }
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(|e| e.to_ascii_lowercase());
    let files = match ext.as_deref() {
        Some("exr") | Some("png") => vec![path.to_path_buf()],
        _ if path.extension().is_none() || path.is_dir() => {
            vec![
                path.join(format!("{stem}.exr")),
                path.join(format!("{stem}.png")),
            ]
        }
        _ => anyhow::bail!(hirad::Error::input(
            path,
            "image must end in .exr or .png (or be a directory)"
        )),
    };
    for f in &files {
        img.write(f, exposure)
            .with_context(|| format!("writing {}", f.display()))?;
    }
    Ok(files)
}

/// Rasteriser flags (`render`, `solve --image`).
#[derive(clap::Args, Debug, Clone)]
pub struct RasterArgs {
    /// Supersampling: N×N samples per pixel, box-filtered.
    #[arg(long, default_value_t = 2, value_parser = clap::value_parser!(u32).range(1..=16))]
    pub ss: u32,
    /// Back faces: black (one-sided surfaces, as the path tracer), cull (meshes with explicit
    /// back faces, e.g. two-sided solutions) or shade.
    #[arg(long, default_value = "black", value_parser = parse_back_faces)]
    pub back_faces: BackFaces,
}

impl Default for RasterArgs {
    fn default() -> Self {
        Self {
            ss: 2,
            back_faces: BackFaces::Black,
        }
    }
}

impl RasterArgs {
    /// The library's rasteriser options.
    pub fn options(&self) -> RasterOptions {
        RasterOptions {
            supersample: self.ss,
            back_faces: self.back_faces,
            ..Default::default()
        }
    }
}

/// Final-gather flags (`render --gather`, `solve --gather`).
#[derive(clap::Args, Debug, Clone, Default)]
pub struct GatherArgs {
    /// Final gather with N samples per pixel instead of the per-vertex image: per sample a camera
    /// ray, an emitter sample with a shadow ray and a cosine-weighted gather ray that reads the
    /// solution's radiosity (`render` needs --scene) [default: none, the per-vertex image].
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..))]
    pub gather: Option<u32>,
    /// How gather rays read the solution: element (the triangle's mean) or vertex (interpolated
    /// as the per-vertex image).
    #[arg(long, default_value = "element", value_parser = parse_lookup)]
    pub gather_lookup: Lookup,
    /// Importance to bright elements: solution triangles whose reflected radiosity is above
    /// this multiple of the area-weighted mean are also sampled by area, combined with the
    /// gather rays by multiple importance sampling (0: off).
    #[arg(long, default_value_t = 16.0, value_parser = parse_factor)]
    pub gather_bright: f32,
    /// One more bounce near the shading point: gather hits closer than this multiple of the
    /// square root of their element's area are shaded there instead of reading the element's
    /// radiosity (0: off).
    #[arg(long, default_value_t = 8.0, value_parser = parse_factor)]
    pub gather_near: f32,
    /// Irradiance cache: the indirect light of one point per block of N×N pixels, gathered
    /// with the block's rays and interpolated where valid (0: every sample gathers its own).
    #[arg(long, default_value_t = 2)]
    pub gather_cache: u32,
    /// Adaptive sampling: after every pixel's N samples, about this many times N more per
    /// pixel on average, given to the pixels whose neighbours' samples spread most in lightness
    /// (edges, emitter outlines) (0: every pixel takes N).
    #[arg(long, default_value_t = 1.0, value_parser = parse_factor)]
    pub gather_adaptive: f32,
}

fn parse_lookup(s: &str) -> Result<Lookup, String> {
    Lookup::parse(s).map_err(|e| e.to_string())
}

fn parse_factor(s: &str) -> Result<f32, String> {
    s.trim()
        .parse::<f32>()
        .ok()
        .filter(|x| x.is_finite() && *x >= 0.0)
        .ok_or_else(|| format!("expected a number >= 0, got '{s}'"))
}

/// A gathered image and what it took.
pub struct Gathered {
    pub image: Image,
    pub stats: GatherStats,
    /// Seconds to build the scene's accelerator and match the solution to the scene.
    pub prepare_seconds: f64,
}

impl GatherArgs {
    /// Gather `rays` samples per pixel of the solution `mesh` of `scene` seen from `view`.
    /// Two-sided when `two_sided`, the scene says so or the solution has back faces.
    #[allow(clippy::too_many_arguments)]
    pub fn gather(
        &self,
        rays: u32,
        scene: &Scene,
        mesh: &ColoredMesh,
        view: &CameraView,
        seed: u64,
        two_sided: bool,
        progress: &dyn Progress,
        cancel: Option<&AtomicBool>,
    ) -> anyhow::Result<Gathered> {
        let t0 = std::time::Instant::now();
        let tree = ClusterTree::build(scene, Strategy::Sah, &ClusterConfig::default());
        let caster = RayCaster::new(scene, &tree);
        let sol = SolutionLookup::new(mesh, scene, &caster, self.gather_lookup)?;
        let prepare_seconds = t0.elapsed().as_secs_f64();
        let opts = GatherOptions {
            rays,
            seed,
            two_sided: two_sided || scene.two_sided || sol.has_back_faces(),
            lookup: self.gather_lookup,
            bright: self.gather_bright,
            near: self.gather_near,
            cache: self.gather_cache,
            adaptive: self.gather_adaptive,
        };
        tracing::info!(
            "gather: solution matched in {prepare_seconds:.2} s ({} front, {} back triangles, \
             {} on no surface), two-sided {}",
            sol.front,
            sol.back,
            sol.unmatched,
            opts.two_sided
        );
        let (image, stats) =
            Gatherer::new(scene, &caster, &sol, &opts).render(view, progress, cancel)?;
        // A look-up can miss at a crack of the leaf mesh (1 in 4.6 million on the office).
        if stats.lookup_misses as f64 > 1e-4 * stats.lookups as f64 {
            tracing::warn!(
                "gather: {} of {} look-ups found no element of the solution (read as black)",
                stats.lookup_misses,
                stats.lookups
            );
        }
        Ok(Gathered {
            image,
            stats,
            prepare_seconds,
        })
    }
}

fn parse_back_faces(s: &str) -> Result<BackFaces, String> {
    match s.to_ascii_lowercase().as_str() {
        "black" => Ok(BackFaces::Black),
        "cull" => Ok(BackFaces::Cull),
        "shade" => Ok(BackFaces::Shade),
        _ => Err(format!("back faces: black, cull or shade, got '{s}'")),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parsers() {
        assert_eq!(
            parse_vec3("1, -2.5,3e1").unwrap(),
            Vec3::new(1.0, -2.5, 30.0)
        );
        assert!(parse_vec3("1,2").is_err());
        assert!(parse_vec3("1,2,nan").is_err());
        assert!(parse_vec3("1,2,x").is_err());
        assert_eq!(parse_size("640x480").unwrap(), (640, 480));
        assert_eq!(parse_size("8X8").unwrap(), (8, 8));
        assert!(parse_size("0x5").is_err());
        assert!(parse_size("640").is_err());
        assert!(parse_size("-3x4").is_err());
        assert_eq!(parse_up("z").unwrap(), UpArg::Axis(UpAxis::Z));
        assert_eq!(parse_up("0,0,1").unwrap(), UpArg::Vector(Vec3::Z));
        assert!(parse_up("w").is_err());
        assert_eq!(parse_fov("45").unwrap(), 45.0);
        assert!(parse_fov("180").is_err());
        assert!(parse_fov("0").is_err());
        assert_eq!(parse_exposure("-2.5").unwrap(), Exposure::Stops(-2.5));
        assert_eq!(parse_exposure("AUTO").unwrap(), Exposure::Auto);
        assert!(parse_exposure("inf").is_err());
        assert!(parse_exposure("bright").is_err());
    }

    #[test]
    fn auto_exposure_maps_the_white_to_one() {
        // Luminance of grey g is g; 99th percentile of 100 pixels 0.01..=1.0 (× 8) is 0.99 × 8.
        let mut img = Image::new(10, 10, Vec3::ZERO);
        for (i, p) in img.pixels.iter_mut().enumerate() {
            *p = Vec3::splat(8.0 * (i + 1) as f32 / 100.0);
        }
        let stops = Exposure::Auto.stops(&img);
        assert!((stops - (-(8.0f32 * 0.99).log2())).abs() < 1e-4, "{stops}");
        assert_eq!(Exposure::Stops(1.5).stops(&img), 1.5);
        assert_eq!(auto_exposure(&Image::new(2, 2, Vec3::ZERO)), 0.0);
    }

    #[test]
    fn writes_one_file_or_both() {
        let dir = tempfile::tempdir().unwrap();
        let img = Image::new(3, 2, Vec3::splat(0.5));
        let one = write_image(&img, &dir.path().join("a.png"), 0.0, "x").unwrap();
        assert_eq!(one.len(), 1);
        assert!(one[0].exists());
        let both = write_image(&img, &dir.path().join("out"), 0.0, "ref").unwrap();
        assert_eq!(both.len(), 2);
        assert!(both.iter().all(|p| p.exists()));
        assert!(write_image(&img, &dir.path().join("a.jpg"), 0.0, "x").is_err());
    }
}
