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
pub mod study_slurm;
pub mod validate;
pub mod view;
pub mod view_serve;

use hirad::scene::{Scene, SceneOptions};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

/// A flag that the first Ctrl-C sets (printing `message`, if any), for long work to stop at
/// its next check; a second Ctrl-C ends the process (exit 130). A handler cannot be installed
/// twice in one process; the flag then stays unset.
pub fn cancel_on_ctrl_c(message: Option<&'static str>) -> Arc<AtomicBool> {
    let cancel = Arc::new(AtomicBool::new(false));
    let c = cancel.clone();
    let _ = ctrlc::set_handler(move || {
        if c.swap(true, Ordering::SeqCst) {
            std::process::exit(130);
        }
        if let Some(m) = message {
            eprintln!("{m}");
        }
    });
    cancel
}

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
