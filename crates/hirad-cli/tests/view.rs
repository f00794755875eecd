//! `hirad view`: the HTML page is self-contained and holds the glb byte for byte; bad input
//! exits 2 naming the file; with a Chromium on PATH, the page draws the model (headless,
//! WebGL2 through SwiftShader).

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

fn hirad() -> Command {
    Command::new(env!("CARGO_BIN_EXE_hirad"))
}

/// `hirad solve cornell --preset fast` into `dir`; returns the solution glb.
fn solve_cornell(dir: &Path) -> PathBuf {
    let out = hirad()
        .args(["-q", "solve", "cornell", "--preset", "fast", "--out"])
        .arg(dir)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    dir.join("solution.glb")
}

/// The base64 text of the embedded glb.
fn embedded_glb(html: &str) -> Vec<u8> {
    let start = html
        .find("const GLB_BASE64 = \"")
        .expect("GLB_BASE64 in the page")
        + 20;
    let len = html[start..].find('"').unwrap();
    base64::decode(&html[start..start + len]).unwrap()
}

#[test]
fn view_writes_one_self_contained_page_holding_the_glb() {
    let d = tempfile::tempdir().unwrap();
    let glb = solve_cornell(d.path());
    let out = d.path().join("page.html");
    let r = hirad()
        .args(["-q", "view"])
        .arg(&glb)
        .arg("--out")
        .arg(&out)
        .args(["--exposure", "-1.5"])
        .output()
        .unwrap();
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let html = std::fs::read_to_string(&out).unwrap();
    assert_eq!(embedded_glb(&html), std::fs::read(&glb).unwrap());
    let lower = html.to_ascii_lowercase();
    for bad in [
        "http://",
        "https://",
        "<script src",
        "<link",
        "@import",
        "url(",
    ] {
        assert!(!lower.contains(bad), "the page holds '{bad}'");
    }
    assert!(html.contains(r#""exposure":-1.5"#));
    assert!(html.contains(r#""name":"solution.glb""#));
    assert!(!html.contains("HIRAD_CONFIG"));

    // Default output: viewer.html next to the glb.
    let r = hirad().args(["-q", "view"]).arg(&glb).output().unwrap();
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let html = std::fs::read_to_string(d.path().join("viewer.html")).unwrap();
    assert_eq!(embedded_glb(&html), std::fs::read(&glb).unwrap());
}

#[test]
fn view_of_a_non_glb_exits_2_naming_the_file() {
    let d = tempfile::tempdir().unwrap();
    let bogus = d.path().join("bogus.glb");
    std::fs::write(&bogus, "solid cube\nendsolid\n").unwrap();
    for input in [bogus, d.path().join("missing.glb")] {
        let r = hirad().arg("view").arg(&input).output().unwrap();
        let err = String::from_utf8_lossy(&r.stderr);
        assert_eq!(r.status.code(), Some(2), "{err}");
        let name = input.file_name().unwrap().to_str().unwrap();
        assert!(err.contains(name), "{err}");
        assert!(!d.path().join("viewer.html").exists());
    }
    let r = hirad()
        .args(["view", "x.glb", "--exposure", "bright"])
        .output()
        .unwrap();
    assert_eq!(r.status.code(), Some(2));
}

/// The first browser of `chromium`, `chromium-browser`, `google-chrome` on PATH.
fn browser() -> Option<PathBuf> {
    let path = std::env::var_os("PATH")?;
    ["chromium", "chromium-browser", "google-chrome"]
        .iter()
        .flat_map(|b| std::env::split_paths(&path).map(move |d| d.join(b)))
        .find(|p| p.is_file())
}

/// Screenshot of `page` (with `#flags`) at 640×480 by a headless Chromium into `png`; fails
/// on a page error in the browser's log.
fn screenshot(chrome: &Path, page: &Path, flags: &str, png: &Path, profile: &Path) {
    let _ = std::fs::remove_file(png);
    let mut child = Command::new(chrome)
        .args([
            "--headless=new",
            "--no-sandbox",
            "--disable-gpu",
            "--use-gl=swiftshader",
            "--enable-unsafe-swiftshader",
            "--enable-logging=stderr",
            "--window-size=640,480",
        ])
        .arg(format!("--user-data-dir={}", profile.display()))
        .arg(format!("--screenshot={}", png.display()))
        .arg(format!(
            "file://{}{flags}",
            page.canonicalize().unwrap().display()
        ))
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // Read stderr on a thread so a chatty browser cannot block on a full pipe.
    let mut stderr = child.stderr.take().unwrap();
    let log = std::thread::spawn(move || {
        let mut s = String::new();
        std::io::Read::read_to_string(&mut stderr, &mut s).ok();
        s
    });
    let t0 = Instant::now();
    while child.try_wait().unwrap().is_none() {
        if t0.elapsed() > Duration::from_secs(90) {
            child.kill().ok();
            panic!("{} did not finish in 90 s", chrome.display());
        }
        std::thread::sleep(Duration::from_millis(100));
    }
    let log = log.join().unwrap();
    assert!(png.is_file(), "no screenshot; browser log:\n{log}");
    for bad in ["Uncaught", "hirad view: "] {
        assert!(!log.contains(bad), "page error in the browser log:\n{log}");
    }
    eprintln!("screenshot: {}", png.display());
}

#[test]
fn view_draws_the_model_in_headless_chromium() {
    let Some(chrome) = browser() else {
        eprintln!("note: no chromium, chromium-browser or google-chrome on PATH: skipped");
        return;
    };
    let d = tempfile::tempdir().unwrap();
    let glb = solve_cornell(d.path());
    let r = hirad().args(["-q", "view"]).arg(&glb).output().unwrap();
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let png = Path::new(env!("CARGO_TARGET_TMPDIR")).join("view_screenshot.png");
    let page = d.path().join("viewer.html");
    screenshot(&chrome, &page, "", &png, &d.path().join("profile"));
    let img = image::open(&png).unwrap().to_rgb8();
    assert_eq!(img.dimensions(), (640, 480));
    // Below the overlay (top left), the model: many colours, not only the background.
    let background = image::Rgb([0u8, 0, 0]);
    let lower: Vec<_> = img
        .enumerate_pixels()
        .filter(|p| p.1 >= 200)
        .map(|p| *p.2)
        .collect();
    let model = lower.iter().filter(|&&p| p != background).count();
    let mut distinct = lower.clone();
    distinct.sort_by_key(|p| p.0);
    distinct.dedup();
    assert!(
        model > lower.len() / 10 && distinct.len() > 50,
        "{model} of {} pixels drawn, {} colours",
        lower.len(),
        distinct.len()
    );
}

/// `view --scene` opens at the scene's default camera; without overlay and antialiasing
/// (`#noui&noaa`) the page shows what `hirad render --ss 1` draws of the same view and size:
/// RMS ΔE*uv ≤ 3 (`hirad diff`, after sRGB decoding).
#[test]
fn view_at_the_scene_camera_matches_render() {
    let Some(chrome) = browser() else {
        eprintln!("note: no chromium, chromium-browser or google-chrome on PATH: skipped");
        return;
    };
    let d = tempfile::tempdir().unwrap();
    let glb = solve_cornell(d.path());
    let r = hirad()
        .args(["-q", "view", "--scene", "cornell"])
        .arg(&glb)
        .output()
        .unwrap();
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let tmp = Path::new(env!("CARGO_TARGET_TMPDIR"));
    let shot = tmp.join("view_scene_camera.png");
    let page = d.path().join("viewer.html");
    screenshot(
        &chrome,
        &page,
        "#noui&noaa",
        &shot,
        &d.path().join("profile"),
    );
    let rendered = tmp.join("view_scene_camera_render.png");
    let r = hirad()
        .args([
            "-q", "render", "--scene", "cornell", "--ss", "1", "--size", "640x480",
        ])
        .arg(&glb)
        .arg("--image")
        .arg(&rendered)
        .output()
        .unwrap();
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let r = hirad()
        .args(["--json", "diff"])
        .arg(&shot)
        .arg(&rendered)
        .output()
        .unwrap();
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let v: serde_json::Value = serde_json::from_slice(&r.stdout).unwrap();
    let rms = v["rms_delta_e"].as_f64().unwrap();
    eprintln!("viewer vs render: RMS ΔE*uv {rms:.3}");
    assert!(rms <= 3.0, "RMS ΔE*uv {rms} between the page and render");
    assert!(
        (v["mean_luminance_ratio"].as_f64().unwrap() - 1.0).abs() < 0.02,
        "{v}"
    );
}
