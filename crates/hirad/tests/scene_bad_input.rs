//! Bad input: every error is of the right kind and names the file (and the line where there is
//! one); ρ = 1 is clamped with a report entry.

use hirad::scene::{Scene, SceneOptions};
use hirad::Error;
use std::path::{Path, PathBuf};

fn write(dir: &Path, name: &str, text: impl AsRef<[u8]>) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p
}

fn load(p: &Path) -> hirad::Result<Scene> {
    Scene::load(p.to_str().unwrap(), &SceneOptions::default())
}

/// Assert an `Error::Input` for `file` at `line` whose message contains `needle`.
fn assert_input(r: hirad::Result<Scene>, file: &Path, line: Option<usize>, needle: &str) {
    let e = r.expect_err("expected an error");
    let text = e.to_string();
    match &e {
        Error::Input {
            file: f,
            line: l,
            msg,
        } => {
            assert_eq!(f, file, "{text}");
            assert_eq!(*l, line, "{text}");
            assert!(
                msg.to_lowercase().contains(&needle.to_lowercase()),
                "'{needle}' not in: {text}"
            );
        }
        other => panic!("expected Error::Input, got {other:?}"),
    }
    let name = file.file_name().unwrap().to_str().unwrap();
    assert!(text.contains(name), "{text}");
    if let Some(l) = line {
        assert!(text.contains(&format!("{name}:{l}:")), "{text}");
    }
    assert!(e.is_input());
}

const QUAD: &str = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n";

#[test]
fn malformed_obj_lines() {
    let d = tempfile::tempdir().unwrap();
    let cases = [
        ("v 1 2 x\n", 5, "not a number"),
        ("v 1 2\n", 5, "2 coordinates"),
        ("f 1 2\n", 5, "2 vertices"),
        ("f a b c\n", 5, "not an index"),
        ("f 1/2/3 2// 3x\n", 5, "not an index"),
    ];
    for (i, (line, no, what)) in cases.iter().enumerate() {
        let p = write(
            d.path(),
            &format!("m{i}.obj"),
            format!("{QUAD}{line}f 1 2 3\n"),
        );
        assert_input(load(&p), &p, Some(*no), what);
    }
}

#[test]
fn non_finite_coordinates() {
    let d = tempfile::tempdir().unwrap();
    for (i, v) in ["nan 0 0", "0 inf 0", "0 0 -inf", "1e39 0 0", "0 NaN 0"]
        .iter()
        .enumerate()
    {
        let p = write(
            d.path(),
            &format!("n{i}.obj"),
            format!("# c\n{QUAD}v {v}\nf 1 2 3\n"),
        );
        assert_input(load(&p), &p, Some(6), "not finite");
    }
}

#[test]
fn out_of_range_indices() {
    let d = tempfile::tempdir().unwrap();
    for (i, (f, what)) in [
        ("f 1 2 99", "vertex 99"),
        ("f -9 -2 -1", "relative vertex -9"),
        ("f 0 1 2", "index 0"),
        ("f 1 2 99999999999", "out of range"),
    ]
    .iter()
    .enumerate()
    {
        let p = write(
            d.path(),
            &format!("i{i}.obj"),
            format!("{QUAD}f 1 2 3\n{f}\nf 1 3 4\n"),
        );
        assert_input(load(&p), &p, Some(6), what);
    }
}

#[test]
fn reflectance_out_of_range_names_the_mtl_line() {
    let d = tempfile::tempdir().unwrap();
    for (i, kd) in ["-0.1 0.5 0.5", "0.5 1.5 0.5", "0.5 0.5 nan"]
        .iter()
        .enumerate()
    {
        let mtl = write(
            d.path(),
            &format!("r{i}.mtl"),
            format!("newmtl ok\nKd 0.5 0.5 0.5\n\nnewmtl bad\nKd {kd}\n"),
        );
        let p = write(
            d.path(),
            &format!("r{i}.obj"),
            format!("mtllib r{i}.mtl\n{QUAD}usemtl bad\nf 1 2 3\n"),
        );
        assert_input(load(&p), &mtl, Some(5), "material 'bad'");
    }
    let mtl = write(d.path(), "e.mtl", "newmtl lamp\nKd 0 0 0\nKe 1 -2 1\n");
    let p = write(
        d.path(),
        "e.obj",
        format!("mtllib e.mtl\n{QUAD}usemtl lamp\nf 1 2 3\n"),
    );
    assert_input(load(&p), &mtl, Some(3), "emission");
}

#[test]
fn rho_one_is_clamped_and_reported() {
    let d = tempfile::tempdir().unwrap();
    write(
        d.path(),
        "c.mtl",
        "newmtl white\nKd 1 1 1\nnewmtl grey\nKd 0.5 0.5 0.5\n",
    );
    let p = write(
        d.path(),
        "c.obj",
        format!("mtllib c.mtl\n{QUAD}usemtl white\nf 1 2 3\nusemtl grey\nf 1 3 4\n"),
    );
    let s = load(&p).unwrap();
    assert_eq!(s.report.clamped_materials, vec!["white".to_string()]);
    assert_eq!(s.materials[0].rho, glam::Vec3::splat(0.95));
    let opts = SceneOptions {
        max_reflectance: 0.8,
        ..Default::default()
    };
    let s = Scene::load(p.to_str().unwrap(), &opts).unwrap();
    assert_eq!(s.materials[0].rho, glam::Vec3::splat(0.8));
}

#[test]
fn empty_scene() {
    let d = tempfile::tempdir().unwrap();
    let p = write(d.path(), "empty.obj", QUAD);
    assert_input(load(&p), &p, None, "no triangles");
    let p = write(d.path(), "flat.obj", format!("{QUAD}f 1 1 2\nf 1 2 2\n"));
    assert_input(load(&p), &p, None, "2 degenerate");
    let p = write(d.path(), "nothing.obj", "");
    assert_input(load(&p), &p, None, "no triangles");
}

#[test]
fn missing_mtl_names_it_and_the_mtllib_line() {
    let d = tempfile::tempdir().unwrap();
    let p = write(
        d.path(),
        "mm.obj",
        format!("# header\nmtllib gone.mtl\n{QUAD}f 1 2 3\n"),
    );
    assert_input(load(&p), &p, Some(2), "gone.mtl not found");
    let p = write(
        d.path(),
        "um.obj",
        format!("{QUAD}usemtl nowhere\nf 1 2 3\n"),
    );
    assert_input(load(&p), &p, Some(5), "'nowhere'");
}

#[test]
fn missing_file_is_an_io_error_naming_it() {
    let d = tempfile::tempdir().unwrap();
    for name in ["missing.obj", "missing.glb", "missing.ply", "missing.toml"] {
        let p = d.path().join(name);
        let e = load(&p).err().unwrap();
        assert!(matches!(e, Error::Io { .. }), "{e:?}");
        assert!(e.to_string().contains(name), "{e}");
        assert!(e.is_input());
    }
    let e = Scene::load("no_such_scene", &SceneOptions::default())
        .err()
        .unwrap();
    assert!(matches!(e, Error::Config(_)) && e.to_string().contains("no_such_scene"));
}

#[test]
fn malformed_gltf() {
    let d = tempfile::tempdir().unwrap();
    // Broken JSON: the line of the syntax error.
    let p = write(
        d.path(),
        "a.gltf",
        "{\n  \"asset\": {\"version\": \"2.0\"},\n  \"nodes\": [\n  }\n",
    );
    assert_input(load(&p), &p, Some(4), "malformed glTF");
    // Valid JSON, invalid references.
    let p = write(
        d.path(),
        "b.gltf",
        r#"{"asset": {"version": "2.0"}, "scenes": [{"nodes": [5]}], "scene": 0}"#,
    );
    assert_input(load(&p), &p, None, "malformed glTF");
    // A GLB header with garbage after it.
    let mut glb = b"glTF".to_vec();
    glb.extend(2u32.to_le_bytes());
    glb.extend(1000u32.to_le_bytes());
    glb.extend([7u8; 13]);
    let p = write(d.path(), "c.glb", glb);
    assert_input(load(&p), &p, None, "malformed glTF");
    // Buffer shorter than declared.
    write(d.path(), "short.bin", [0u8; 8]);
    let p = write(
        d.path(),
        "d.gltf",
        r#"{"asset": {"version": "2.0"}, "buffers": [{"uri": "short.bin", "byteLength": 36}],
            "bufferViews": [{"buffer": 0, "byteLength": 36}],
            "accessors": [{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3",
                           "min": [0,0,0], "max": [1,1,0]}],
            "meshes": [{"primitives": [{"attributes": {"POSITION": 0}}]}],
            "nodes": [{"mesh": 0}], "scenes": [{"nodes": [0]}], "scene": 0}"#,
    );
    assert_input(load(&p), &p, None, "malformed glTF");
}

#[test]
fn truncated_ply() {
    let d = tempfile::tempdir().unwrap();
    let ascii = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n\
                 property float z\nelement face 1\nproperty list uchar int vertex_indices\n\
                 end_header\n0 0 0\n1 0 0\n";
    let p = write(d.path(), "t.ply", ascii);
    assert_input(load(&p), &p, Some(12), "file ends");
    let p = write(
        d.path(),
        "h.ply",
        "ply\nformat ascii 1.0\nelement vertex 3\n",
    );
    assert_input(load(&p), &p, Some(3), "end_header");
    let mut bin = b"ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\n\
                    property float y\nproperty float z\nelement face 1\n\
                    property list uchar int vertex_indices\nend_header\n"
        .to_vec();
    for x in [0f32, 0., 0., 1., 0., 0., 0., 1., 0.] {
        bin.extend(x.to_le_bytes());
    }
    bin.extend([3u8, 0, 0, 0, 0, 1, 0, 0, 0]);
    let p = write(d.path(), "b.ply", &bin);
    assert_input(load(&p), &p, None, "truncated");
    let p = write(d.path(), "x.ply", "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\nend_header\n0 0 zz\n");
    assert_input(load(&p), &p, Some(8), "'zz'");
}

#[test]
fn bad_toml() {
    let d = tempfile::tempdir().unwrap();
    write(d.path(), "q.obj", format!("{QUAD}f 1 2 3 4\n"));
    let cases = [
        ("name = \"x\"\n[[mesh]\nfile = \"q.obj\"\n", 2, ""),
        ("[[mesh]]\nfile = \"q.obj\"\ncolour = 3\n", 3, "colour"),
        ("\n[[mesh]]\nfile = \"nope.obj\"\n", 3, "nope.obj not found"),
        ("[[mesh]]\nfile = \"q.obj\"\n[materials.steel]\nrho = [0.5, 0.5, 0.5]\n", 3, "'steel'"),
        ("[[mesh]]\nfile = \"q.obj\"\n[sun]\ndirection = [0.0, 0.0, 0.0]\nirradiance = [1.0, 1.0, 1.0]\n", 4, "non-zero"),
        ("[[mesh]]\nfile = \"q.obj\"\nscale = \"big\"\n", 3, ""),
    ];
    for (i, (text, line, what)) in cases.iter().enumerate() {
        let p = write(d.path(), &format!("s{i}.toml"), text);
        assert_input(load(&p), &p, Some(*line), what);
    }
    // A light with a negative radiance is caught by validation and names the TOML file.
    let p = write(
        d.path(),
        "neg.toml",
        "[[light]]\ncorner = [0.0, 0.0, 0.0]\nedge1 = [1.0, 0.0, 0.0]\nedge2 = [0.0, 1.0, 0.0]\n\
         radiance = [1.0, -1.0, 1.0]\n",
    );
    assert_input(load(&p), &p, None, "emission");
}

#[test]
fn unknown_extension() {
    let d = tempfile::tempdir().unwrap();
    let p = write(d.path(), "s.stl", "solid x\n");
    assert_input(load(&p), &p, None, "unknown file type");
}
