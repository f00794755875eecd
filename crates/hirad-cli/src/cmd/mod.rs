//! One module per subcommand: each has an `Args` (clap) and a `run`.

pub mod clusters;
pub mod diff;
pub mod image_args;
pub mod info;
pub mod raybench;
pub mod reference;
pub mod render;
pub mod scene;
pub mod solve;
pub mod study;
pub mod validate;
pub mod view;

use hirad::scene::{Scene, SceneOptions};

/// Load a scene (path or built-in name), logging the time.
pub fn load_scene(spec: &str, opts: &SceneOptions) -> anyhow::Result<Scene> {
    let s = Scene::load(spec, opts)?;
    tracing::info!(
        "loaded {} ({} triangles) in {:.3} s",
        spec,
        s.num_triangles(),
        s.report.load_seconds
    );
    Ok(s)
}

/// Print a value as pretty JSON on stdout.
/// A closed pipe (`hirad ... --json | head`) ends the output quietly instead of panicking.
pub fn print_json<T: serde::Serialize>(v: &T) -> anyhow::Result<()> {
    use std::io::Write;
    let text = serde_json::to_string_pretty(v)?;
    let mut out = std::io::stdout().lock();
    match writeln!(out, "{text}").and_then(|_| out.flush()) {
        Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => Ok(()),
        r => Ok(r?),
    }
}
