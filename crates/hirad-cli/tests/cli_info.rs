//! `hirad info` and `hirad scene` end to end: exit codes, error messages, JSON numbers.

use std::path::Path;
use std::process::Command;

fn hirad() -> Command {
    Command::new(env!("CARGO_BIN_EXE_hirad"))
}

/// Run `cmd`, which must succeed, and parse its standard output as JSON.
fn json_ok(cmd: &mut Command) -> serde_json::Value {
    let out = cmd.output().unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).unwrap()
}

fn real(name: &str) -> String {
    format!(
        "{}/../../../shared/scenes/{name}/{name}.obj",
        env!("CARGO_MANIFEST_DIR")
    )
}

#[test]
fn missing_file_exits_2_and_names_it() {
    let d = tempfile::tempdir().unwrap();
    let p = d.path().join("missing.obj");
    let out = hirad().arg("info").arg(&p).output().unwrap();
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("missing.obj"), "{err}");
    assert!(out.stdout.is_empty());
}

#[test]
fn bad_line_exits_2_with_file_and_line() {
    let d = tempfile::tempdir().unwrap();
    let p = d.path().join("bad.obj");
    std::fs::write(&p, "v 0 0 0\nv 1 0 0\nv 0 1 oops\nf 1 2 3\n").unwrap();
    let out = hirad().arg("info").arg(&p).output().unwrap();
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("bad.obj:3:"), "{err}");
    let out = hirad().args(["info", "no_such_builtin"]).output().unwrap();
    assert_eq!(out.status.code(), Some(2));
}

#[test]
fn info_json_on_a_real_scene() {
    let v = json_ok(hirad().args([
        "info",
        &real("graz_office"),
        "--json",
        "--max-reflectance",
        "0.9",
    ]));
    assert_eq!(v["triangles"], 26_928);
    assert_eq!(v["vertices"], 16_949);
    assert_eq!(v["materials"], 52);
    assert_eq!(v["emitter_triangles"], 16);
    assert_eq!(v["up"], "z");
    assert_eq!(v["degenerate_dropped"], 0);
    assert!(v["total_area"].as_f64().unwrap() > 300.0);
    assert!(v["load_seconds"].as_f64().unwrap() >= 0.0);
    // `--up` overrides the file's header; the human table prints it.
    let out = hirad()
        .args(["info", &real("graz_office"), "--up", "y"])
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("+Y") && text.contains("26928"), "{text}");
}

#[test]
fn every_example_scene_loads_lit_with_a_camera() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes");
    let mut n = 0;
    for e in std::fs::read_dir(&dir).unwrap() {
        let p = e.unwrap().path();
        if p.extension().and_then(|x| x.to_str()) != Some("toml") {
            continue;
        }
        n += 1;
        let v = json_ok(hirad().arg("info").arg(&p).arg("--json"));
        let power: f64 = (0..3)
            .map(|c| v["emitted_power"][c].as_f64().unwrap())
            .sum();
        let lit = power > 0.0 || !v["sun"].is_null() || !v["sky"].is_null();
        assert!(lit, "{}: no light", p.display());
        assert!(v["triangles"].as_u64().unwrap() > 0, "{}", p.display());
        assert!(
            !v["cameras"].as_array().unwrap().is_empty(),
            "{}: no camera",
            p.display()
        );
    }
    assert!(n >= 4, "{} scene files", n);
}

#[test]
fn scene_export_then_info() {
    let d = tempfile::tempdir().unwrap();
    for ext in ["obj", "glb"] {
        let p = d.path().join(format!("cornell.{ext}"));
        let out = hirad()
            .args(["scene", "cornell", "--out"])
            .arg(&p)
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let a = json_ok(hirad().args(["info", "cornell", "--json"]));
        let b = json_ok(hirad().arg("info").arg(&p).arg("--json"));
        for k in ["triangles", "materials", "objects", "emitter_triangles"] {
            assert_eq!(a[k], b[k], "{ext} {k}");
        }
        let (ta, tb) = (
            a["total_area"].as_f64().unwrap(),
            b["total_area"].as_f64().unwrap(),
        );
        assert!((ta - tb).abs() < 1e-5 * ta, "{ext}: {ta} vs {tb}");
    }
}

#[test]
fn builtin_name_wins_over_a_directory_of_that_name() {
    // `hirad solve office --out office` leaves a directory `office`; the next run in the same
    // place must still find the built-in scene, and a directory of another name is an error.
    let d = tempfile::tempdir().unwrap();
    std::fs::create_dir(d.path().join("office")).unwrap();
    std::fs::create_dir(d.path().join("results")).unwrap();
    let v = json_ok(
        hirad()
            .current_dir(d.path())
            .args(["info", "office", "--json"]),
    );
    assert_eq!(v["triangles"], 8_354);
    let out = hirad()
        .current_dir(d.path())
        .args(["info", "results"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("results"), "{err}");
}

#[test]
fn validate_compares_the_solution_with_two_references() {
    let v = json_ok(hirad().args([
        "validate", "cornell", "--size", "64x48", "--spp", "256", "--json",
    ]));
    let f = |k: &str| v[k].as_f64().unwrap_or_else(|| panic!("{k} in {v}"));
    // The references agree on the energy, with and without the lamp's pixels; the lamp
    // (0.5% of the pixels) holds about half the luminance, so the solution is judged on the
    // rest too (seeds 1–3: 0.967–0.973 overall, 0.972–0.974 without the lamp; 1.070–1.077
    // overall with one sample per pixel, from the lamp's edges).
    assert!((f("reference_luminance_ratio") - 1.0).abs() < 0.03, "{v}");
    assert!(
        (f("reference_surface_luminance_ratio") - 1.0).abs() < 0.02,
        "{v}"
    );
    assert!((0.4..0.7).contains(&f("emitter_luminance_share")), "{v}");
    assert!((f("mean_luminance_ratio") - 1.0).abs() < 0.06, "{v}");
    assert!((f("surface_luminance_ratio") - 1.0).abs() < 0.05, "{v}");
    assert!(
        f("rms_delta_e") > 0.0 && f("reference_rms_delta_e") > 0.0,
        "{v}"
    );
    assert_eq!(v["width"], 64);
    assert!(v["links"].as_u64().unwrap() > 0);
}

/// `validate` takes the solver's flags as `solve` does, and reports them.
#[test]
fn validate_takes_the_solver_flags() {
    let v = json_ok(hirad().args([
        "validate",
        "cornell",
        "--size",
        "64x48",
        "--spp",
        "64",
        "--visibility",
        "volume",
        "--refine",
        "error",
        "--json",
    ]));
    assert_eq!(v["visibility"], "volume", "{v}");
    assert_eq!(v["refine"], "error", "{v}");
    assert_eq!(v["cluster_emission"], "directional", "{v}");
    let f = |k: &str| v[k].as_f64().unwrap_or_else(|| panic!("{k} in {v}"));
    assert!((f("surface_luminance_ratio") - 1.0).abs() < 0.05, "{v}");
}

#[test]
fn validate_from_a_view_that_sees_nothing_says_so() {
    let o = hirad()
        .args([
            "validate", "cornell", "--size", "32x24", "--spp", "4", "--preset", "fast", "--eye",
            "0,0,100", "--target", "0,0,200",
        ])
        .output()
        .unwrap();
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("reference") && err.contains("black"), "{err}");
}

/// `--mgf-divisions` reaches the MGF loader: corridor.mgf's sphere, cylinders and torus are
/// tessellated more coarsely with 1 division than with the default 4.
#[test]
fn mgf_divisions_set_the_tessellation() {
    let f = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/scenes/mgf/corridor.mgf");
    if !f.is_file() {
        eprintln!("skipped: {} not found", f.display());
        return;
    }
    let tris = |extra: &[&str]| {
        let v = json_ok(hirad().arg("--json").arg("info").arg(&f).args(extra));
        v["triangles"].as_u64().unwrap()
    };
    let (coarse, default) = (tris(&["--mgf-divisions", "1"]), tris(&[]));
    assert!(coarse < default, "{coarse} against {default}");
    let o = hirad()
        .arg("info")
        .arg(&f)
        .args(["--mgf-divisions", "0"])
        .output()
        .unwrap();
    assert_eq!(
        o.status.code(),
        Some(2),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
}

#[test]
fn info_table_prints_units() {
    let o = hirad().args(["info", "office"]).output().unwrap();
    assert!(o.status.success());
    let t = String::from_utf8_lossy(&o.stdout);
    for (row, unit) in [
        ("total area", "scene units²"),
        ("bbox", "scene units"),
        ("emitted power", " W per RGB channel"),
        ("load time", " s"),
    ] {
        let line = t.lines().find(|l| l.starts_with(row)).unwrap_or("");
        assert!(line.contains(unit), "{row}: {line}");
    }
}

#[test]
fn top_level_help_says_what_hirad_is() {
    let o = hirad().arg("--help").output().unwrap();
    let t = String::from_utf8_lossy(&o.stdout);
    assert!(
        t.lines()
            .next()
            .unwrap_or("")
            .starts_with("hirad: hierarchical radiosity"),
        "{t}"
    );
    for c in ["solve", "study", "render", "diff", "reference", "validate"] {
        assert!(
            t.lines()
                .any(|l| l.trim_start().starts_with(&format!("hirad {c} "))),
            "no example of {c}: {t}"
        );
    }
}

/// The binary names the commit it was built from (embedded by build.rs), as run records do.
#[test]
fn version_names_the_build_commit() {
    let o = hirad().arg("--version").output().unwrap();
    let v = String::from_utf8_lossy(&o.stdout).to_string();
    let head = Command::new("git")
        .args(["rev-parse", "--short=12", "HEAD"])
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .ok()
        .filter(|o| o.status.success())
        .map(|o| String::from_utf8_lossy(&o.stdout).trim().to_string());
    match head {
        Some(h) => assert!(v.contains(&format!("(commit {h}")), "{v} against HEAD {h}"),
        None => assert!(v.contains("(commit "), "{v}"),
    }
}

/// Output into a pipe whose reader is gone (`hirad info … | head`) ends the process by
/// SIGPIPE, as other Unix tools end, not by a panic in `println!`.
#[cfg(unix)]
#[test]
fn a_closed_pipe_ends_the_process_quietly() {
    use std::os::fd::{FromRawFd, OwnedFd};
    use std::os::unix::process::ExitStatusExt;
    let mut fds = [0i32; 2];
    assert_eq!(unsafe { libc::pipe(fds.as_mut_ptr()) }, 0);
    let (read, write) = unsafe { (OwnedFd::from_raw_fd(fds[0]), OwnedFd::from_raw_fd(fds[1])) };
    drop(read);
    let out = hirad()
        .args(["info", "cornell"])
        .stdout(std::process::Stdio::from(write))
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!err.contains("panicked"), "{err}");
    assert_eq!(
        out.status.signal(),
        Some(libc::SIGPIPE),
        "{:?}: {err}",
        out.status
    );
}
