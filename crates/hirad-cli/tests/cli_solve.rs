//! `hirad solve` end to end: the spec's camera flags on the image it writes; choices and usage
//! errors.

use hirad::render::Image;
use std::process::Command;

fn hirad() -> Command {
    Command::new(env!("CARGO_BIN_EXE_hirad"))
}

fn ok(cmd: &mut Command) {
    let o = cmd.output().unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
}

/// Run `cmd`, check that it exits with 2, and return its stderr.
fn exit2(cmd: &mut Command) -> String {
    let o = cmd.output().unwrap();
    let err = String::from_utf8_lossy(&o.stderr).into_owned();
    assert_eq!(o.status.code(), Some(2), "{err}");
    err
}

/// `solve --eye --target --up --fov --size` makes the image `render` makes of the solution from
/// that view, and it differs from the default view's.
#[test]
fn solve_image_takes_the_camera_flags() {
    let d = tempfile::tempdir().unwrap();
    let cam = [
        "--eye", "1,-1,1.6", "--target", "6,-5,0.8", "--up", "0,0,1", "--fov", "70", "--size",
        "64x48",
    ];
    let out = d.path().join("s");
    ok(hirad()
        .args(["-q", "solve", "office", "--preset", "fast", "--out"])
        .arg(&out)
        .args(cam));
    let img = Image::read(&out.join("image.exr")).unwrap();
    assert_eq!((img.width, img.height), (64, 48));
    let r = d.path().join("r.exr");
    ok(hirad()
        .args(["-q", "render"])
        .arg(out.join("solution.glb"))
        .args(["--scene", "office", "--image"])
        .arg(&r)
        .args(cam));
    assert_eq!(Image::read(&r).unwrap().pixels, img.pixels);
    let dflt = d.path().join("d.exr");
    ok(hirad()
        .args(["-q", "render"])
        .arg(out.join("solution.glb"))
        .args(["--scene", "office", "--size", "64x48", "--image"])
        .arg(&dflt));
    assert_ne!(Image::read(&dflt).unwrap().pixels, img.pixels);
}

/// `solve --gather N` with camera flags writes the image `render SOLUTION.glb --scene S --gather
/// N` makes with the same flags and seed (the glb holds all the gather needs), whatever the
/// thread count; the camera flags are one definition shared by `solve`, `render` and
/// `reference` (the same flags give the same size); `render --gather` without `--scene` is
/// refused.
#[test]
fn solve_gather_equals_render_gather_with_the_same_flags() {
    let d = tempfile::tempdir().unwrap();
    let cam = [
        "--eye",
        "0.2,0.3,-0.5",
        "--target",
        "0.3,0.2,0.3",
        "--up",
        "0,1,0",
        "--fov",
        "50",
        "--size",
        "40x30",
    ];
    let out = d.path().join("s");
    ok(hirad()
        .args([
            "-q",
            "--threads",
            "2",
            "solve",
            "cornell",
            "--preset",
            "fast",
            "--seed",
            "5",
        ])
        .args(["--gather", "8", "--out"])
        .arg(&out)
        .args(cam));
    let img = Image::read(&out.join("image.exr")).unwrap();
    assert_eq!((img.width, img.height), (40, 30));
    assert!(img.mean().x > 0.0);
    let r = d.path().join("r.exr");
    ok(hirad()
        .args(["-q", "--threads", "1", "render"])
        .arg(out.join("solution.glb"))
        .args([
            "--scene", "cornell", "--gather", "8", "--seed", "5", "--image",
        ])
        .arg(&r)
        .args(cam));
    assert_eq!(Image::read(&r).unwrap().pixels, img.pixels);
    // Another seed: another image; the per-vertex image is another one too.
    let r2 = d.path().join("r2.exr");
    ok(hirad()
        .args(["-q", "render"])
        .arg(out.join("solution.glb"))
        .args([
            "--scene", "cornell", "--gather", "8", "--seed", "6", "--image",
        ])
        .arg(&r2)
        .args(cam));
    assert_ne!(Image::read(&r2).unwrap().pixels, img.pixels);
    let p = d.path().join("p.exr");
    ok(hirad()
        .args(["-q", "reference", "cornell", "--spp", "1", "--image"])
        .arg(&p)
        .args(cam));
    assert_eq!(Image::read(&p).unwrap().width, 40);
    let o = hirad()
        .args(["-q", "render"])
        .arg(out.join("solution.glb"))
        .args(["--gather", "8"])
        .output()
        .unwrap();
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("--gather needs --scene"));
    // An irradiance cache whose points would need more rays than it holds: exit 2, said.
    let o = hirad()
        .args(["-q", "render"])
        .arg(out.join("solution.glb"))
        .args([
            "--scene",
            "cornell",
            "--gather",
            "8",
            "--gather-cache",
            "1024",
        ])
        .args(["--image"])
        .arg(d.path().join("c.exr"))
        .args(cam)
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("gather rays per point"));
}

/// Choices parse in any case; `solve --clustering all` is refused with a list that does not
/// offer `all` (exit 2: a usage error), while `clusters --clustering all` takes it.
#[test]
fn choices_parse_in_any_case() {
    let d = tempfile::tempdir().unwrap();
    ok(hirad().args([
        "-q",
        "solve",
        "cornell",
        "--preset",
        "Fast",
        "--clustering",
        "PROXI",
        "--refine",
        "BF",
        "--visibility",
        "Rays",
        "--bench",
    ]));
    let err = exit2(
        hirad()
            .args(["-q", "solve", "cornell", "--clustering", "all", "--out"])
            .arg(d.path()),
    );
    assert!(err.contains("unknown clustering strategy 'all'"), "{err}");
    assert!(!err.contains(", all"), "{err}");
    ok(hirad().args(["-q", "clusters", "cornell", "--clustering", "ALL"]));
}

/// `hirad study` without a scene is a usage error: exit 2.
#[test]
fn study_without_a_scene_exits_2() {
    let err = exit2(hirad().args(["-q", "study"]));
    assert!(err.contains("a scene is required"), "{err}");
}

/// Every option that takes a value says in its help what it is when not given (or that it is
/// required), in every command.
#[test]
fn every_option_shows_its_default() {
    let cmds = [
        "info",
        "scene",
        "clusters",
        "raybench",
        "solve",
        "render",
        "diff",
        "reference",
        "study",
        "validate",
    ];
    for c in cmds {
        let o = hirad().args([c, "--help"]).output().unwrap();
        let help = String::from_utf8_lossy(&o.stdout);
        let opts = help.split("Options:").nth(1).unwrap_or("");
        // One entry per option: from a line starting with `-x, --` or `--` to the next.
        let mut entries: Vec<String> = Vec::new();
        for line in opts.lines() {
            let t = line.trim_start();
            if t.starts_with("--") || (t.starts_with('-') && t.get(2..6) == Some(", --")) {
                entries.push(t.to_string());
            } else if let Some(e) = entries.last_mut() {
                e.push(' ');
                e.push_str(t);
            }
        }
        for e in entries {
            let name = e
                .split_whitespace()
                .find(|w| w.starts_with("--"))
                .unwrap_or("");
            let takes_value = e
                .split_whitespace()
                .nth(if e.starts_with("--") { 1 } else { 2 })
                .is_some_and(|w| w.starts_with('<'));
            let lower = e.to_lowercase();
            if takes_value {
                assert!(
                    lower.contains("default") || lower.contains("required"),
                    "hirad {c} {name}: no default in its help: {e}"
                );
            }
        }
    }
}

/// A `--max-memory` below what the scene needs before refinement is an exit-2 error naming the
/// size needed, before any work (no output directory); that size lets the solve run, and its
/// counted peak stays within it.
#[test]
fn too_small_a_memory_budget_exits_2_naming_the_size() {
    let d = tempfile::tempdir().unwrap();
    let out = d.path().join("s");
    let err = exit2(
        hirad()
            .args([
                "-q",
                "solve",
                "office",
                "--preset",
                "fast",
                "--max-memory",
                "10MB",
                "--out",
            ])
            .arg(&out),
    );
    assert!(!out.exists());
    // "... is below the N MB that the scene needs ...; give at least M MB"
    let mb = |after: &str| -> u64 {
        let i = err
            .find(after)
            .unwrap_or_else(|| panic!("no '{after}' in {err}"))
            + after.len();
        err[i..].split(' ').next().unwrap().parse().unwrap()
    };
    let (need, give) = (mb("is below the "), mb("give at least "));
    assert!(need > 10 && give >= need, "{err}");
    ok(hirad()
        .args(["-q", "solve", "office", "--preset", "fast", "--max-memory"])
        .arg(format!("{give}MB"))
        .arg("--out")
        .arg(&out));
    let st: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("stats.json")).unwrap()).unwrap();
    let peak = st["memory"]["peak_counted_bytes"].as_u64().unwrap();
    assert!(peak <= give * 1_000_000, "{peak} > {give} MB");
}

/// `solve --export-rays` writes a share of the solver's shadow segments that `raybench
/// --segments` casts (every strategy finds the same occluded count, and the file holds about
/// one in 16 of the solve's rays, the same whatever the thread count); a file made for
/// another scene exits 2 naming it.
#[test]
fn solver_rays_are_exported_for_raybench() {
    let d = tempfile::tempdir().unwrap();
    let f = d.path().join("rays.bin");
    let f1 = d.path().join("rays1.bin");
    let solve = |threads: &str, file: &std::path::Path| {
        let o = hirad()
            .args(["-q", "--threads", threads, "solve", "cornell", "--bench"])
            .arg("--export-rays")
            .arg(file)
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let st: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        st["rays"].as_u64().unwrap()
    };
    let rays = solve("2", &f);
    solve("1", &f1);
    assert_eq!(std::fs::read(&f).unwrap(), std::fs::read(&f1).unwrap());
    let o = hirad()
        .args([
            "-q",
            "--json",
            "raybench",
            "cornell",
            "--clustering",
            "sah,proxi,kdt",
        ])
        .arg("--segments")
        .arg(&f)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let rb: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let n = rb["pairs"].as_u64().unwrap();
    // The share is chosen by a hash of the end points: about 1/16 of the rays between link
    // ends (sky and sun rays are not among them).
    assert!(n * 16 > rays / 2 && n * 16 < rays * 2, "{n} of {rays}");
    assert_eq!(rb["counts_agree"], true);
    assert!(rb["segments"].as_str().unwrap().ends_with("rays.bin"));
    let occ: Vec<u64> = rb["rows"]
        .as_array()
        .unwrap()
        .iter()
        .map(|r| r["occluded"].as_u64().unwrap())
        .collect();
    assert!(
        occ.iter().all(|&c| c == occ[0] && c > 0 && c < n),
        "{occ:?}"
    );
    let err = exit2(
        hirad()
            .args(["-q", "raybench", "office", "--segments"])
            .arg(&f),
    );
    assert!(
        err.contains("rays.bin") && err.contains("triangles"),
        "{err}"
    );
    // Volume visibility casts no shadow rays: nothing to export.
    let err = exit2(
        hirad()
            .args([
                "-q",
                "solve",
                "cornell",
                "--bench",
                "--visibility",
                "volume",
            ])
            .arg("--export-rays")
            .arg(d.path().join("v.bin")),
    );
    assert!(
        err.contains("--export-rays") && err.contains("volume"),
        "{err}"
    );
}

/// `raybench --embree` times Embree 3 beside the strategies, on the same segments: its
/// default and robust builds count what `sah` counts up to segments that graze an edge. Where
/// the library is missing (allowed unless HIRAD_REQUIRE_EMBREE is set) it exits 2 saying how
/// to install it.
#[test]
fn raybench_times_embree_beside_the_strategies() {
    let args = [
        "-q",
        "--json",
        "raybench",
        "cornell",
        "--clustering",
        "sah",
        "--pairs",
        "20000",
        "--repeat",
        "1",
        "--closest",
        "--embree",
    ];
    let o = hirad().args(args).output().unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    if err.contains("Embree 3 not found") && std::env::var_os("HIRAD_REQUIRE_EMBREE").is_none() {
        assert_eq!(o.status.code(), Some(2), "{err}");
        assert!(err.contains("apt-get install libembree3-3"), "{err}");
        return;
    }
    assert!(o.status.success(), "{err}");
    let rb: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let sah = rb["rows"][0]["occluded"].as_u64().unwrap();
    assert!(sah > 1000, "{sah}");
    let rows = rb["embree"].as_array().unwrap();
    let names: Vec<&str> = rows.iter().map(|r| r["name"].as_str().unwrap()).collect();
    assert_eq!(names, ["embree", "embree-robust"]);
    for r in rows {
        for key in ["occluded", "single_occluded"] {
            let n = r[key].as_u64().unwrap();
            assert!(
                n.abs_diff(sah) * 200 <= sah,
                "{key} {n} against sah's {sah}"
            );
        }
        for key in ["sah_batch_ratio", "sah_single_ratio", "closest_mrays_per_s"] {
            assert!(r[key].as_f64().unwrap() > 0.0, "{key}: {r}");
        }
    }
}
