//! `hirad view SOLUTION.glb`: one self-contained HTML file that shows a baked solution in a
//! browser (WebGL2). The glb is embedded as base64 and parsed by the page's own script, so the
//! file can be mailed or opened offline: nothing is fetched at view time. The page draws
//! radiance B/π (`_RADIOSITY`, else `COLOR_0`) × 2^exposure, linear → sRGB in the shader, back
//! faces black, as `hirad render` does; orbit and walk cameras, the glb's cameras and those of
//! `--scene` as presets (template: `view.html`; `#noui&noaa` after its URL gives the bare
//! canvas without antialiasing, the pixels of `hirad render --ss 1`). `--serve` serves the same
//! page and the glb over local HTTP instead (`view_serve`).

use super::image_args::{parse_exposure, Exposure};
use crate::Global;
use hirad::scene::export::Z_UP_NODE;
use hirad::scene::SceneOptions;
use hirad::Error;
use std::path::{Path, PathBuf};

/// The page; `/*HIRAD_CONFIG*/null` is replaced by the settings, `HIRAD_GLB_BASE64` by the glb.
const TEMPLATE: &str = include_str!("view.html");

#[derive(clap::Args, Debug)]
pub struct Args {
    /// Solution to show: a `.glb` (as `hirad solve` writes it; any triangle glb works).
    pub solution: PathBuf,
    /// Output HTML file [default: viewer.html next to SOLUTION].
    #[arg(long, conflicts_with = "serve")]
    pub out: Option<PathBuf>,
    /// Serve the page over HTTP instead of writing a file, until interrupted (Ctrl-C), and
    /// print its URL (also with -q). ADDR is PORT, IP:PORT or [IPv6]:PORT; the default binds
    /// 127.0.0.1 only, on a free port (port 0: the system chooses). Only the page (`/`) and
    /// the glb (`/NAME.glb`) are served, from memory: no directory listing, no other file;
    /// paths with `..` (also %2e%2e) or that are not plain absolute URL paths are refused
    /// (403), any other path is 404. An address other than loopback exposes the page to the
    /// network.
    #[arg(long, value_name = "ADDR", num_args = 0..=1,
          default_missing_value = super::view_serve::DEFAULT_ADDR,
          value_parser = super::view_serve::parse_addr)]
    pub serve: Option<std::net::SocketAddr>,
    /// Initial exposure in stops (radiance × 2^exposure before the sRGB transfer and clamping,
    /// as `hirad render --exposure`), or `auto`: the 99th percentile of vertex luminance maps
    /// to 1. Changed in the page with the slider or the +/- keys.
    #[arg(long, default_value = "0", value_parser = parse_exposure, allow_hyphen_values = true)]
    pub exposure: Exposure,
    /// The scene the solution was solved from (file or built-in name): its up axis, and its
    /// cameras as presets, the page starting at its default view (the one `hirad render
    /// --scene` draws) instead of the fit view.
    #[arg(long)]
    pub scene: Option<String>,
    /// Up axis of the model's coordinates: `y` (glTF's convention) or `z` (hirad solutions of
    /// Z-up scenes keep the scene's coordinates under a root node turning them to +Y up, which
    /// the page leaves out) [default: the scene's with --scene, else z for a solution with that
    /// node, else y].
    /// Also switchable in the page.
    #[arg(long, value_parser = parse_up)]
    pub up: Option<String>,
}

/// `y` or `z`, in any case.
fn parse_up(s: &str) -> Result<String, String> {
    match s.trim().to_ascii_lowercase().as_str() {
        u @ ("y" | "z") => Ok(u.to_string()),
        _ => Err(format!("the up axis is y or z, got '{s}'")),
    }
}

pub fn run(a: Args, _g: &Global) -> anyhow::Result<()> {
    let glb = std::fs::read(&a.solution).map_err(|e| Error::io(&a.solution, e))?;
    let z_up = check_glb(&a.solution, &glb)?;
    let out = a.out.clone().unwrap_or_else(|| {
        a.solution
            .parent()
            .unwrap_or(Path::new(""))
            .join("viewer.html")
    });
    let name = a
        .solution
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let mut config = serde_json::json!({
        "name": name,
        "exposure": match a.exposure {
            Exposure::Stops(s) => serde_json::json!(s),
            Exposure::Auto => serde_json::json!("auto"),
        },
        "up": a.up.as_deref().unwrap_or(if z_up { "z" } else { "y" }),
        // The root node of a Z-up solution, which the page leaves out.
        "z_up_node": Z_UP_NODE,
    });
    if let Some(spec) = &a.scene {
        let sc = super::load_scene(spec, &SceneOptions::default())?;
        if a.up.is_none() {
            config["up"] = serde_json::json!(sc.up);
        }
        let mut cams = sc.cameras.clone();
        if cams.is_empty() {
            cams.push(sc.default_camera());
        }
        config["cameras"] = cams
            .iter()
            .map(|c| {
                serde_json::json!({
                    "name": c.name, "eye": c.eye.to_array(), "target": c.target.to_array(),
                    "fov": c.fov_deg.to_radians(),
                })
            })
            .collect();
        config["start"] = serde_json::json!(0);
    }
    // `</` cannot end the script element early when written as `<\/`.
    let config = serde_json::to_string(&config)?.replace("</", "<\\/");
    // The glb last: its base64 cannot hold the config's marker (no `*`).
    let html = TEMPLATE
        .replacen("/*HIRAD_CONFIG*/null", &config, 1)
        .replacen("HIRAD_GLB_BASE64", &base64::encode(&glb), 1);
    if let Some(addr) = a.serve {
        return super::view_serve::serve(addr, html, glb, &name);
    }
    hirad::io::write_bytes_atomic(&out, html.as_bytes())?;
    tracing::info!("wrote {} ({} bytes)", out.display(), html.len());
    if !_g.quiet {
        println!("{}", out.display());
    }
    Ok(())
}

/// Check that `b` is a binary glTF with meshes, in the container layout the page's parser
/// relies on; true when it holds hirad's node turning a Z-up model to +Y up.
fn check_glb(path: &Path, b: &[u8]) -> hirad::Result<bool> {
    let bad = |msg: &str| Error::input(path, format!("not a binary glTF (.glb): {msg}"));
    let u32_at = |o: usize| u32::from_le_bytes([b[o], b[o + 1], b[o + 2], b[o + 3]]) as usize;
    if b.len() < 20 || &b[0..4] != b"glTF" {
        return Err(bad("no 'glTF' header"));
    }
    if u32_at(4) != 2 {
        return Err(bad(&format!("container version {}, expected 2", u32_at(4))));
    }
    if u32_at(8) > b.len() {
        return Err(bad("truncated"));
    }
    if &b[16..20] != b"JSON" || 20 + u32_at(12) > b.len() {
        return Err(bad("the first chunk is not a complete JSON chunk"));
    }
    let json: serde_json::Value = serde_json::from_slice(&b[20..20 + u32_at(12)])
        .map_err(|e| bad(&format!("JSON chunk: {e}")))?;
    if json
        .get("meshes")
        .and_then(|m| m.as_array())
        .is_none_or(|m| m.is_empty())
    {
        return Err(bad("no meshes"));
    }
    let z_up = json
        .get("nodes")
        .and_then(|n| n.as_array())
        .is_some_and(|n| n.iter().any(|x| x["name"] == Z_UP_NODE));
    Ok(z_up)
}
