//! No-panic fuzz-style test: truncated and randomly mutated copies of real OBJ scenes (a prefix
//! of each, with its MTL), of the shared MGF files (with their includes), and of generated
//! glTF, GLB, PLY (ASCII and binary) and TOML files,
//! go through `Scene::load`, which must return `Ok` or `Err` and never panic. Deterministic
//! (SplitMix64, fixed seeds).

use hirad::rng::SplitMix64;
use hirad::scene::export::{write_colored_mesh, write_scene_glb, ColoredMesh};
use hirad::scene::{Scene, SceneOptions};
use std::path::{Path, PathBuf};

const PREFIX: usize = 200_000;

fn real_dir(name: &str) -> PathBuf {
    PathBuf::from(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../../shared/scenes"
    ))
    .join(name)
}

fn below(rng: &mut SplitMix64, n: usize) -> usize {
    (rng.next_u64() % n.max(1) as u64) as usize
}

/// One random mutation of `data` (text-aware operations still apply to binary data).
fn mutate(rng: &mut SplitMix64, data: &[u8]) -> Vec<u8> {
    let mut d = data.to_vec();
    if d.is_empty() {
        return d;
    }
    let line_bounds = |d: &[u8], at: usize| {
        let s = d[..at]
            .iter()
            .rposition(|&b| b == b'\n')
            .map_or(0, |p| p + 1);
        let e = d[at..]
            .iter()
            .position(|&b| b == b'\n')
            .map_or(d.len(), |p| at + p + 1);
        (s, e)
    };
    let ops = 1 + below(rng, 4);
    for _ in 0..ops {
        if d.is_empty() {
            break;
        }
        let at = below(rng, d.len());
        match below(rng, 8) {
            0 => d[at] ^= 1 << below(rng, 8),
            1 => {
                let (s, e) = line_bounds(&d, at);
                d.drain(s..e);
            }
            2 => {
                let (s, e) = line_bounds(&d, at);
                let line = d[s..e].to_vec();
                d.splice(s..s, line);
            }
            3 => {
                // A digit becomes a letter.
                if let Some(p) = d[at..].iter().position(|b| b.is_ascii_digit()) {
                    d[at + p] = b"xeEnai-"[below(rng, 7)];
                }
            }
            4 => {
                // A number becomes huge, negative, zero or non-finite.
                let big: &[&[u8]] = &[
                    b"99999999999999999999",
                    b"-4294967297",
                    b"1e39",
                    b"0",
                    b"-1",
                    b"nan",
                    b"4294967295",
                ];
                if let Some(p) = d[at..].iter().position(|b| b.is_ascii_digit()) {
                    let s = at + p;
                    let e = d[s..]
                        .iter()
                        .position(|b| !(b.is_ascii_digit() || *b == b'.'))
                        .map_or(d.len(), |q| s + q);
                    d.splice(s..e, big[below(rng, big.len())].iter().copied());
                }
            }
            5 => d.truncate(at),
            6 => d[at] = (rng.next_u64() & 0xff) as u8,
            _ => {
                // Swap two lines.
                let (s1, e1) = line_bounds(&d, at);
                let at2 = below(rng, d.len());
                let (s2, e2) = line_bounds(&d, at2);
                if e1 <= s2 {
                    let a = d[s1..e1].to_vec();
                    let b = d[s2..e2].to_vec();
                    d.splice(s2..e2, a);
                    d.splice(s1..e1, b);
                }
            }
        }
    }
    d
}

/// Load `path` and fail the test (with the case) if loading panics.
fn must_not_panic(path: &Path, case: &str) -> bool {
    let spec = path.to_str().unwrap().to_string();
    let r = std::panic::catch_unwind(|| Scene::load(&spec, &SceneOptions::default()));
    match r {
        Ok(res) => res.is_ok(),
        Err(_) => panic!("Scene::load panicked on {case}"),
    }
}

/// Truncations at `cuts` points plus `mutations` mutated copies of `data` written as `name`.
/// Returns (cases, ok count).
fn run_cases(
    dir: &Path,
    name: &str,
    data: &[u8],
    seed: u64,
    cuts: usize,
    mutations: usize,
) -> (usize, usize) {
    let p = dir.join(name);
    let mut rng = SplitMix64::new(seed);
    let (mut n, mut ok) = (0, 0);
    for k in 0..cuts {
        let cut = if k == 0 {
            0
        } else {
            below(&mut rng, data.len())
        };
        std::fs::write(&p, &data[..cut]).unwrap();
        n += 1;
        ok += must_not_panic(&p, &format!("{name} truncated at {cut}")) as usize;
    }
    for k in 0..mutations {
        let m = mutate(&mut rng, data);
        std::fs::write(&p, &m).unwrap();
        n += 1;
        ok += must_not_panic(&p, &format!("{name} mutation {k} (seed {seed})")) as usize;
    }
    (n, ok)
}

#[test]
fn real_obj_prefixes_never_panic() {
    let d = tempfile::tempdir().unwrap();
    let mut total = 0;
    for (i, name) in ["bathroom", "franka_panda", "copper_beech", "graz_office"]
        .iter()
        .enumerate()
    {
        let src = real_dir(name);
        let obj = std::fs::read(src.join(format!("{name}.obj"))).unwrap();
        let mtl = std::fs::read(src.join(format!("{name}.mtl"))).unwrap();
        let prefix = &loadable_prefix(&obj)[..];
        std::fs::write(d.path().join(format!("{name}.mtl")), &mtl).unwrap();
        // The unmutated prefix loads.
        let p = d.path().join(format!("{name}.obj"));
        std::fs::write(&p, prefix).unwrap();
        let intact = Scene::load(p.to_str().unwrap(), &SceneOptions::default());
        assert!(
            intact.is_ok_and(|s| s.num_triangles() > 100),
            "{name} prefix"
        );
        let (n, ok) = run_cases(
            d.path(),
            &format!("{name}.obj"),
            prefix,
            11 + i as u64,
            10,
            50,
        );
        assert!(ok > 0 && ok < n, "{name}: {ok} of {n} loaded");
        total += n;
        // The MTL mutated under an intact OBJ prefix.
        std::fs::write(&p, prefix).unwrap();
        let mut rng = SplitMix64::new(101 + i as u64);
        for k in 0..15 {
            std::fs::write(d.path().join(format!("{name}.mtl")), mutate(&mut rng, &mtl)).unwrap();
            must_not_panic(&p, &format!("{name}.mtl mutation {k}"));
            total += 1;
        }
    }
    assert!(total >= 300, "{total}");
}

/// Every shared MGF file (its first 200 lines; includes still resolve), truncated and mutated,
/// and with one line replaced by an `xf -a` array (MGF's own way to multiply work).
#[test]
fn real_mgf_files_never_panic() {
    let src = real_dir("mgf");
    if !src.is_dir() {
        eprintln!("skipped: {} not found", src.display());
        return;
    }
    let d = tempfile::tempdir().unwrap();
    let mut list = Vec::new();
    for sub in ["", "office1", "office2", "office3", "hospital", "Materials"] {
        for e in std::fs::read_dir(src.join(sub)).unwrap() {
            let p = e.unwrap().path();
            if p.extension().is_some_and(|x| x == "mgf") {
                let text = std::fs::read_to_string(&p).unwrap();
                let cut: String = text.lines().take(200).map(|l| format!("{l}\n")).collect();
                let rel = Path::new(sub).join(p.file_name().unwrap());
                std::fs::create_dir_all(d.path().join(sub)).unwrap();
                std::fs::write(d.path().join(&rel), &cut).unwrap();
                list.push((rel.to_str().unwrap().to_string(), cut.into_bytes()));
            }
        }
    }
    list.sort();
    let (mut total, mut loaded) = (0, 0);
    for (k, (name, data)) in list.iter().enumerate() {
        let (n, ok) = run_cases(d.path(), name, data, 0x3ad + k as u64, 3, 10);
        let mut rng = SplitMix64::new(0x3ae + k as u64);
        let lines: Vec<&[u8]> = data.split_inclusive(|&b| b == b'\n').collect();
        let at = below(&mut rng, lines.len());
        let mut arr: Vec<u8> = lines[..at].concat();
        arr.extend_from_slice(b"xf -a 3 -t 0 0 1\n");
        arr.extend(lines.get(at + 1..).unwrap_or_default().concat());
        let p = d.path().join(name);
        std::fs::write(&p, &arr).unwrap();
        must_not_panic(&p, &format!("{name} with an xf array at line {}", at + 1));
        // Restored: other files include it.
        std::fs::write(&p, data).unwrap();
        total += n + 1;
        loaded += ok;
    }
    assert!(
        list.len() >= 30 && total >= 400,
        "{} files, {total} cases",
        list.len()
    );
    assert!(loaded > 0 && loaded < total, "{loaded} of {total} loaded");
}

/// About `PREFIX` bytes of a real OBJ that still load: the first half from the start of the file
/// (header, vertices), the second half from the first `o`/`g`/`usemtl` statement on, keeping only
/// faces whose vertices are among those kept (all the vertices come first in these files).
fn loadable_prefix(obj: &[u8]) -> Vec<u8> {
    let lines: Vec<&[u8]> = obj.split_inclusive(|&b| b == b'\n').collect();
    let mut out = Vec::new();
    let mut nv = 0usize;
    let mut i = 0;
    while i < lines.len() && out.len() < PREFIX / 2 {
        let l = lines[i];
        if l.starts_with(b"o ") || l.starts_with(b"g ") || l.starts_with(b"usemtl") {
            break;
        }
        nv += l.starts_with(b"v ") as usize;
        out.extend_from_slice(l);
        i += 1;
    }
    let start = lines
        .iter()
        .position(|l| l.starts_with(b"o ") || l.starts_with(b"g ") || l.starts_with(b"usemtl"))
        .unwrap_or(lines.len());
    for l in &lines[start..] {
        if out.len() >= PREFIX {
            break;
        }
        if l.starts_with(b"v ") {
            continue;
        }
        if l.starts_with(b"f ") {
            let ok = String::from_utf8_lossy(&l[2..])
                .split_whitespace()
                .all(|t| {
                    t.split('/')
                        .next()
                        .and_then(|v| v.parse::<usize>().ok())
                        .is_some_and(|v| v <= nv)
                });
            if !ok {
                continue;
            }
        }
        out.extend_from_slice(l);
    }
    out
}

fn sample_mesh() -> ColoredMesh {
    let mut m = ColoredMesh::default();
    for j in 0..6u32 {
        for i in 0..6u32 {
            m.positions.push(glam::Vec3::new(
                i as f32,
                j as f32,
                ((i * j) % 3) as f32 * 0.1,
            ));
            m.colors.push(glam::Vec3::new(i as f32, j as f32, 0.5));
            if i < 5 && j < 5 {
                let v = j * 6 + i;
                m.triangles.push([v, v + 1, v + 7]);
                m.triangles.push([v, v + 7, v + 6]);
            }
        }
    }
    m
}

#[test]
fn generated_gltf_ply_toml_never_panic() {
    let d = tempfile::tempdir().unwrap();
    let mut total = 0;
    // GLB written by the scene exporter (binary container, JSON chunk, BIN chunk).
    let cornell = Scene::load("cornell", &SceneOptions::default()).unwrap();
    let glb = d.path().join("src.glb");
    write_scene_glb(&glb, &cornell).unwrap();
    let bytes = std::fs::read(&glb).unwrap();
    let (n, ok) = run_cases(d.path(), "m.glb", &bytes, 21, 20, 60);
    assert!(ok > 0 && ok < n, "glb: {ok} of {n}");
    total += n;
    // glTF JSON with an external buffer: mutate the JSON text.
    let json_start = 20;
    let json_len = u32::from_le_bytes(bytes[12..16].try_into().unwrap()) as usize;
    let mut doc: serde_json::Value =
        serde_json::from_slice(&bytes[json_start..json_start + json_len]).unwrap();
    std::fs::write(d.path().join("m.bin"), &bytes[json_start + json_len + 8..]).unwrap();
    doc["buffers"][0]["uri"] = "m.bin".into();
    let text = serde_json::to_vec_pretty(&doc).unwrap();
    let (n, ok) = run_cases(d.path(), "m.gltf", &text, 22, 10, 60);
    assert!(ok > 0 && ok < n, "gltf: {ok} of {n}");
    total += n;
    // Binary PLY from the mesh exporter, and an ASCII PLY.
    let ply = d.path().join("src.ply");
    write_colored_mesh(&ply, &sample_mesh()).unwrap();
    let bytes = std::fs::read(&ply).unwrap();
    let (n, ok) = run_cases(d.path(), "m.ply", &bytes, 23, 20, 60);
    assert!(ok > 0 && ok < n, "ply: {ok} of {n}");
    total += n;
    let m = sample_mesh();
    let mut ascii = format!(
        "ply\nformat ascii 1.0\nelement vertex {}\nproperty float x\nproperty float y\n\
         property float z\nelement face {}\nproperty list uchar int vertex_indices\nend_header\n",
        m.positions.len(),
        m.triangles.len() / 2
    );
    for p in &m.positions {
        ascii += &format!("{} {} {}\n", p.x, p.y, p.z);
    }
    for t in m.triangles.chunks(2) {
        ascii += &format!("4 {} {} {} {}\n", t[0][0], t[0][1], t[0][2], t[1][2]);
    }
    let (n, ok) = run_cases(d.path(), "a.ply", ascii.as_bytes(), 24, 10, 40);
    assert!(ok > 0 && ok < n, "ascii ply: {ok} of {n}");
    total += n;
    // TOML scene file combining the OBJ export of cornell with a light and a camera.
    hirad::scene::export::write_scene(&d.path().join("c.obj"), &cornell).unwrap();
    let toml = "name = \"t\"\nsky = [0.1, 0.1, 0.1]\n[[mesh]]\nfile = \"c.obj\"\nscale = 2.0\n\
                rotate = [0.0, 90.0, 0.0]\n[[light]]\ncorner = [0.0, 1.0, 0.0]\n\
                edge1 = [1.0, 0.0, 0.0]\nedge2 = [0.0, 0.0, 1.0]\nradiance = [2.0, 2.0, 2.0]\n\
                [sun]\ndirection = [0.0, 1.0, 0.0]\nirradiance = [9.0, 9.0, 9.0]\n\
                [[camera]]\nname = \"c\"\neye = [0.0, 0.0, 3.0]\ntarget = [0.0, 0.0, 0.0]\n\
                [materials.white]\nrho = [0.7, 0.7, 0.7]\n";
    let (n, ok) = run_cases(d.path(), "s.toml", toml.as_bytes(), 25, 10, 40);
    assert!(ok > 0 && ok < n, "toml: {ok} of {n}");
    total += n;
    assert!(total >= 300, "{total}");
}

/// The tobj fallback path (guarded by `catch_unwind`) on mutated copies of a real prefix.
#[test]
fn tobj_fallback_never_panics() {
    let d = tempfile::tempdir().unwrap();
    let src = real_dir("graz_office");
    let obj = std::fs::read(src.join("graz_office.obj")).unwrap();
    std::fs::copy(
        src.join("graz_office.mtl"),
        d.path().join("graz_office.mtl"),
    )
    .unwrap();
    let prefix = loadable_prefix(&obj);
    let p = d.path().join("graz_office.obj");
    let mut rng = SplitMix64::new(31);
    let mut ok = 0;
    for k in 0..60 {
        let m = if k == 0 {
            prefix.clone()
        } else {
            mutate(&mut rng, &prefix)
        };
        std::fs::write(&p, &m).unwrap();
        let r = std::panic::catch_unwind(|| hirad::scene::obj::load_with_tobj(&p));
        match r {
            Ok(res) => ok += res.is_ok() as usize,
            Err(_) => panic!("load_with_tobj panicked on mutation {k}"),
        }
    }
    assert!(ok > 0 && ok < 60, "{ok} of 60 loaded");
}
