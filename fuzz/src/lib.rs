//! Entry points shared by the fuzz targets (`fuzz_targets/*.rs`) and the stable replay test
//! (`crates/hirad/tests/fuzz_replay.rs`, which includes this file by path).
//!
//! The loaders take paths and follow references (OBJ → MTL, MGF includes, TOML → mesh files,
//! glTF → buffers), so an input is unpacked into a fresh temporary directory and the loader runs
//! on the main file there: the loaders stay as they are and are fuzzed as users call them. An
//! input is the main file, then any number of extra files, each introduced by a line
//! `@@@ NAME` (NAME: `[A-Za-z0-9_.-]{1,32}`, no leading dot; other names are dropped).

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};

/// One loader under fuzzing.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Target {
    /// OBJ with MTL libraries (`Scene::load`).
    Obj,
    /// glTF (`.gltf` with external buffers) or GLB, chosen by the `glTF` magic.
    Gltf,
    /// PLY, ASCII or binary.
    Ply,
    /// TOML scene description and the mesh files it names.
    Toml,
    /// MGF with includes.
    Mgf,
    /// EXR or PNG (PNG signature) as `hirad diff` reads them (`Image::read`).
    Image,
    /// A solution `.glb` as `hirad render` reads it (`read_colored_mesh`).
    Solution,
}

/// Every target with its directory name under `fuzz/corpus/`.
pub const TARGETS: [(&str, Target); 7] = [
    ("obj", Target::Obj),
    ("gltf", Target::Gltf),
    ("ply", Target::Ply),
    ("toml", Target::Toml),
    ("mgf", Target::Mgf),
    ("image", Target::Image),
    ("solution", Target::Solution),
];

/// Separator that starts an extra file: `\n@@@ NAME\n`.
pub const SEP: &[u8] = b"\n@@@ ";

/// Split an input into (name, contents) files; the first is the main file named `main`.
pub fn unpack<'a>(main: &str, data: &'a [u8]) -> Vec<(String, &'a [u8])> {
    let mut parts = Vec::new();
    let mut rest = data;
    let mut name = Some(main.to_string());
    loop {
        let (body, next) = match find(rest, SEP) {
            Some(i) => (&rest[..i], Some(&rest[i + SEP.len()..])),
            None => (rest, None),
        };
        if let Some(n) = name.take() {
            if !parts.iter().any(|(p, _): &(String, &[u8])| *p == n) {
                parts.push((n, body));
            }
        }
        let Some(next) = next else { break };
        let eol = next.iter().position(|&b| b == b'\n').unwrap_or(next.len());
        let n = &next[..eol];
        let ok = (1..=32).contains(&n.len())
            && n[0] != b'.'
            && n.iter()
                .all(|&b| b.is_ascii_alphanumeric() || b"_.-".contains(&b));
        name = ok.then(|| String::from_utf8_lossy(n).into_owned());
        rest = &next[(eol + 1).min(next.len())..];
    }
    parts
}

fn find(hay: &[u8], needle: &[u8]) -> Option<usize> {
    hay.windows(needle.len()).position(|w| w == needle)
}

/// Name of the main file for an input of `target`.
pub fn main_name(target: Target, data: &[u8]) -> &'static str {
    match target {
        Target::Obj => "s.obj",
        Target::Gltf if data.starts_with(b"glTF") => "s.glb",
        Target::Gltf => "s.gltf",
        Target::Ply => "s.ply",
        Target::Toml => "s.toml",
        Target::Mgf => "s.mgf",
        Target::Image if data.starts_with(b"\x89PNG") => "s.png",
        Target::Image => "s.exr",
        Target::Solution => "s.glb",
    }
}

/// Unpack `data` into a fresh directory and run the target's loader on its main file.
/// `Err` carries the loader's error message.
pub fn run(target: Target, data: &[u8]) -> Result<(), String> {
    static COUNTER: AtomicUsize = AtomicUsize::new(0);
    let dir = std::env::temp_dir().join(format!(
        "hirad-fuzz-{}-{}",
        std::process::id(),
        COUNTER.fetch_add(1, Ordering::Relaxed)
    ));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let main = main_name(target, data);
    for (name, body) in unpack(main, data) {
        std::fs::write(dir.join(name), body).expect("write temp file");
    }
    let r = load(target, &dir.join(main));
    let _ = std::fs::remove_dir_all(&dir);
    r
}

fn load(target: Target, path: &Path) -> Result<(), String> {
    let opts = hirad_scene::SceneOptions::default();
    let spec = path.to_str().expect("utf-8 temp path");
    match target {
        Target::Image => hirad_render::Image::read(path).map(|_| ()),
        Target::Solution => hirad_scene::export::read_colored_mesh(path).map(|_| ()),
        _ => hirad_scene::Scene::load(spec, &opts).map(|_| ()),
    }
    .map_err(|e| e.to_string())
}

/// What a fuzz target calls: [`run`], result ignored. Findings are panics that escape the
/// loader, hangs and huge allocations. libfuzzer-sys aborts in its panic hook, before a
/// loader's own `catch_unwind` (the glTF guard) could turn a panic into an error; the hook is
/// replaced by a silent one here, and libfuzzer-sys still aborts on a panic that reaches it.
pub fn fuzz_one(target: Target, data: &[u8]) {
    static HOOK: std::sync::Once = std::sync::Once::new();
    HOOK.call_once(|| std::panic::set_hook(Box::new(|_| {})));
    let _ = run(target, data);
}

/// The stored inputs of a corpus or regression directory, sorted by name.
pub fn files_in(dir: &Path) -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(dir)
        .map(|rd| rd.filter_map(|e| e.ok().map(|e| e.path())).collect())
        .unwrap_or_default();
    v.retain(|p| p.is_file());
    v.sort();
    v
}
