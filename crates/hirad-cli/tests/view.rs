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
    solve_fast(dir, "cornell")
}

/// `hirad solve SCENE --preset fast` into `dir`; returns the solution glb.
fn solve_fast(dir: &Path, scene: &str) -> PathBuf {
    let out = hirad()
        .args(["-q", "solve", scene, "--preset", "fast", "--out"])
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
        .args(["--exposure", "-1.5", "--up", "Z"])
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
    assert!(html.contains(r#""up":"z""#));
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
    for bad in [["--exposure", "bright"], ["--up", "x"]] {
        let r = hirad().args(["view", "x.glb"]).args(bad).output().unwrap();
        assert_eq!(r.status.code(), Some(2));
    }
}

/// The first browser of `chromium`, `chromium-browser`, `google-chrome` on PATH (the test is
/// skipped without one); required when `HIRAD_REQUIRE_BROWSER` is set (CI sets it).
fn browser() -> Option<PathBuf> {
    let found = std::env::var_os("PATH").and_then(|path| {
        ["chromium", "chromium-browser", "google-chrome"]
            .iter()
            .flat_map(|b| std::env::split_paths(&path).map(move |d| d.join(b)))
            .find(|p| p.is_file())
    });
    assert!(
        found.is_some() || std::env::var_os("HIRAD_REQUIRE_BROWSER").is_none(),
        "a headless browser is required: install chromium"
    );
    if found.is_none() {
        eprintln!("note: no chromium, chromium-browser or google-chrome on PATH: skipped");
    }
    found
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
    let d = tempfile::tempdir().unwrap();
    let glb = solve_fast(d.path(), "cornell");
    view_matches_render(d.path(), &glb, "cornell");
}

/// The same for the Z-up office, whose solution glb turns it to +Y up for other viewers: the
/// page, given nothing but the glb, leaves that turn out and takes Z as up (`"up":"z"`); with
/// `--scene`, the scene's camera then sees what `render` draws.
#[test]
fn view_of_a_z_up_solution_at_the_scene_camera_matches_render() {
    let d = tempfile::tempdir().unwrap();
    let glb = solve_fast(d.path(), "office");
    let r = hirad().args(["-q", "view"]).arg(&glb).output().unwrap();
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let html = std::fs::read_to_string(d.path().join("viewer.html")).unwrap();
    assert!(html.contains(r#""up":"z""#));
    view_matches_render(d.path(), &glb, "office");
}

/// Write the page of solution `glb` (in `dir`) with `--scene SCENE`, and compare its picture at
/// its starting view with `render --scene SCENE --ss 1` (RMS ΔE*uv ≤ 3, mean luminance within
/// 2%).
fn view_matches_render(dir: &Path, glb: &Path, scene: &str) {
    let Some(chrome) = browser() else {
        return;
    };
    let r = hirad()
        .args(["-q", "view", "--scene", scene])
        .arg(glb)
        .output()
        .unwrap();
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let tmp = Path::new(env!("CARGO_TARGET_TMPDIR"));
    let shot = tmp.join(format!("view_scene_camera_{scene}.png"));
    let page = dir.join("viewer.html");
    screenshot(&chrome, &page, "#noui&noaa", &shot, &dir.join("profile"));
    let rendered = tmp.join(format!("view_scene_camera_render_{scene}.png"));
    let r = hirad()
        .args([
            "-q", "render", "--scene", scene, "--ss", "1", "--size", "640x480",
        ])
        .arg(glb)
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
    eprintln!("{scene}: viewer vs render: RMS ΔE*uv {rms:.3}");
    assert!(rms <= 3.0, "RMS ΔE*uv {rms} between the page and render");
    assert!(
        (v["mean_luminance_ratio"].as_f64().unwrap() - 1.0).abs() < 0.02,
        "{v}"
    );
}

/// A hand-made glb: a 2×2 quad (uint16 indices, `COLOR_0` as normalized uint8 VEC4, no
/// `_RADIOSITY`) under a node translated by +1 in x, and a camera node "cam A" at (1, 0, 5)
/// looking down −z.
fn quad_glb() -> Vec<u8> {
    let mut bin = Vec::new();
    for p in [[-1f32, -1., 0.], [1., -1., 0.], [1., 1., 0.], [-1., 1., 0.]] {
        for x in p {
            bin.extend_from_slice(&x.to_le_bytes());
        }
    }
    for _ in 0..4 {
        bin.extend_from_slice(&[255, 128, 0, 255]);
    }
    for i in [0u16, 1, 2, 0, 2, 3] {
        bin.extend_from_slice(&i.to_le_bytes());
    }
    let doc = serde_json::json!({
        "asset": {"version": "2.0"},
        "scene": 0,
        "scenes": [{"nodes": [0, 1]}],
        "nodes": [{"mesh": 0, "translation": [1, 0, 0]},
                  {"camera": 0, "name": "cam A", "translation": [1, 0, 5]}],
        "cameras": [{"type": "perspective",
                     "perspective": {"yfov": 0.8, "znear": 0.01, "aspectRatio": 1.5}}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0, "COLOR_0": 1}, "indices": 2}]}],
        "buffers": [{"byteLength": bin.len()}],
        "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": 48},
                        {"buffer": 0, "byteOffset": 48, "byteLength": 16},
                        {"buffer": 0, "byteOffset": 64, "byteLength": 12}],
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3",
             "min": [-1, -1, 0], "max": [1, 1, 0]},
            {"bufferView": 1, "componentType": 5121, "normalized": true, "count": 4, "type": "VEC4"},
            {"bufferView": 2, "componentType": 5123, "count": 6, "type": "SCALAR"}]
    });
    while !bin.len().is_multiple_of(4) {
        bin.push(0);
    }
    let mut js = serde_json::to_vec(&doc).unwrap();
    while !js.len().is_multiple_of(4) {
        js.push(b' ');
    }
    let mut out = b"glTF".to_vec();
    out.extend_from_slice(&2u32.to_le_bytes());
    out.extend_from_slice(&((28 + js.len() + bin.len()) as u32).to_le_bytes());
    out.extend_from_slice(&(js.len() as u32).to_le_bytes());
    out.extend_from_slice(b"JSON");
    out.extend_from_slice(&js);
    out.extend_from_slice(&(bin.len() as u32).to_le_bytes());
    out.extend_from_slice(b"BIN\0");
    out.extend_from_slice(&bin);
    out
}

/// The page's parser (node transforms, uint16 indices, normalized `COLOR_0`, camera nodes) and
/// its controls, driven by synthetic events from a probe script added to a copy of the page;
/// the results are read back from the DOM Chromium dumps.
#[test]
fn view_parses_a_hand_made_glb_and_its_controls_move_the_camera() {
    let Some(chrome) = browser() else {
        return;
    };
    let d = tempfile::tempdir().unwrap();
    let glb = d.path().join("quad.glb");
    std::fs::write(&glb, quad_glb()).unwrap();
    let r = hirad().args(["-q", "view"]).arg(&glb).output().unwrap();
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let html = std::fs::read_to_string(d.path().join("viewer.html")).unwrap();
    let probe = r#"<script>
const out = {}, near = (a, b) => Math.hypot(...sub(a, b)) < 1e-4;
const key = (k) => window.dispatchEvent(new KeyboardEvent("keydown", { key: k }));
const canvas = $("gl");
const ptr = (type, x, y, o) => canvas.dispatchEvent(new PointerEvent(type,
  { clientX: x, clientY: y, pointerId: 1, button: 0, ...o }));
out.count = $("count").textContent;
out.options = [...$("cams").options].map((o) => o.text);
out.centre = centre;
out.colour = Array.from(model.col.slice(0, 3));
out.fit = [cam.dist, cam.yaw, cam.pitch];
key("+"); out.exposurePlus = exposure;
$("auto").click(); out.exposureAuto = exposure;
// Orbit drag: yaw turns, the target and distance stay.
const t0 = cam.target.slice(), d0 = cam.dist, y0 = cam.yaw;
ptr("pointerdown", 100, 100); ptr("pointermove", 150, 100); ptr("pointerup", 150, 100);
out.orbit = { turned: cam.yaw !== y0, targetKept: near(cam.target, t0), distKept: cam.dist === d0 };
// Wheel zooms, shift-drag pans.
canvas.dispatchEvent(new WheelEvent("wheel", { deltaY: 100, cancelable: true }));
out.zoomedOut = cam.dist > d0;
ptr("pointerdown", 100, 100, { shiftKey: true }); ptr("pointermove", 100, 150); ptr("pointerup", 100, 150);
out.panned = !near(cam.target, t0);
// The glb's camera as a preset.
$("cams").value = "0"; $("cams").onchange();
out.presetEye = eye(); out.presetFov = cam.fov; out.presetDir = dir();
// Walk: W moves the eye forward, a drag turns around the eye.
key("Tab"); out.mode = $("mode").textContent;
const e0 = eye(); key("w"); moveKeys(1); window.dispatchEvent(new KeyboardEvent("keyup", { key: "w" }));
out.walked = sub(eye(), e0);
const e1 = eye(); ptr("pointerdown", 100, 100); ptr("pointermove", 160, 120); ptr("pointerup", 160, 120);
out.lookKeptEye = near(eye(), e1);
key("f"); out.fitAgain = [cam.dist, cam.yaw, cam.pitch];
document.body.insertAdjacentHTML("beforeend", "<pre id='probe'>" + JSON.stringify(out) + "</pre>");
</script>
</body>"#;
    let page = d.path().join("probe.html");
    std::fs::write(&page, html.replacen("</body>", probe, 1)).unwrap();
    let r = Command::new(&chrome)
        .args([
            "--headless=new",
            "--no-sandbox",
            "--disable-gpu",
            "--use-gl=swiftshader",
            "--enable-unsafe-swiftshader",
            "--dump-dom",
        ])
        .arg(format!(
            "--user-data-dir={}",
            d.path().join("profile").display()
        ))
        .arg(format!("file://{}", page.display()))
        .output()
        .unwrap();
    let dom = String::from_utf8_lossy(&r.stdout);
    let start = dom
        .find("<pre id=\"probe\">")
        .expect("probe output in the DOM")
        + "<pre id=\"probe\">".len();
    let len = dom[start..].find("</pre>").unwrap();
    let v: serde_json::Value = serde_json::from_str(&dom[start..start + len]).unwrap();
    eprintln!("{v}");
    let f = |x: &serde_json::Value| x.as_f64().unwrap();
    let close = |a: &serde_json::Value, b: [f64; 3]| (0..3).all(|i| (f(&a[i]) - b[i]).abs() < 1e-4);
    assert_eq!(v["count"], "2 triangles · COLOR_0");
    assert_eq!(v["options"], serde_json::json!(["fit view", "cam A"]));
    assert!(close(&v["centre"], [1.0, 0.0, 0.0]), "{v}");
    assert!(close(&v["colour"], [1.0, 128.0 / 255.0, 0.0]), "{v}");
    assert_eq!(f(&v["exposurePlus"]), 0.5);
    // 99th percentile of luminance 0.2126 + 0.7152 · 128/255, to 0.1 stop.
    let auto = -(0.2126f64 + 0.7152 * 128.0 / 255.0).log2();
    assert!((f(&v["exposureAuto"]) - auto).abs() < 0.051, "{v}");
    assert_eq!(
        v["orbit"],
        serde_json::json!({"turned": true, "targetKept": true, "distKept": true})
    );
    assert_eq!(v["zoomedOut"], true);
    assert_eq!(v["panned"], true);
    assert!(close(&v["presetEye"], [1.0, 0.0, 5.0]), "{v}");
    assert!(close(&v["presetDir"], [0.0, 0.0, -1.0]), "{v}");
    assert!((f(&v["presetFov"]) - 0.8).abs() < 1e-6);
    assert_eq!(v["mode"], "walk");
    // Y up: forward along −z, by the walking speed (a quarter of the radius √2 per second).
    assert!(close(&v["walked"], [0.0, 0.0, -0.25 * 2f64.sqrt()]), "{v}");
    assert_eq!(v["lookKeptEye"], true);
    assert_eq!(v["fitAgain"], v["fit"]);
}
