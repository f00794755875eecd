//! MGF 2.0 loader: the classic test scenes of `shared/scenes/mgf` against the counts, emitters
//! and bounding boxes of its README (skipped when the directory is absent), hand-made files
//! for every construct (xf arrays, includes, holes, mirroring, sides, concave polygons, errors),
//! and a deterministic no-panic mutation test.

use glam::Vec3;
use hirad::scene::{mgf, Scene, SceneOptions};
use std::path::{Path, PathBuf};

fn mgf_dir() -> Option<PathBuf> {
    let d = PathBuf::from(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../../shared/scenes/mgf"
    ));
    if d.is_dir() {
        Some(d)
    } else {
        eprintln!("skipped: {} is absent", d.display());
        None
    }
}

fn load(p: &Path) -> Scene {
    Scene::load(p.to_str().unwrap(), &SceneOptions::default()).unwrap_or_else(|e| panic!("{e}"))
}

fn luminance(p: glam::DVec3) -> f64 {
    0.2126 * p.x + 0.7152 * p.y + 0.0722 * p.z
}

/// Write `files` (relative path, content) into a fresh temp dir.
fn files(list: &[(&str, &str)]) -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    for (name, text) in list {
        let p = dir.path().join(name);
        std::fs::create_dir_all(p.parent().unwrap()).unwrap();
        std::fs::write(p, text).unwrap();
    }
    dir
}

fn load_str(text: &str) -> hirad::Result<Scene> {
    let dir = files(&[("t.mgf", text)]);
    Scene::load(
        dir.path().join("t.mgf").to_str().unwrap(),
        &SceneOptions::default(),
    )
}

const QUAD: &str = "m white =\n  rd 0.5\nv a =\n p 0 0 0\nv b =\n p 1 0 0\nv c =\n p 1 1 0\n\
                    v d =\n p 0 1 0\n";

/// Root file, triangles, emitted power (lm), bounding box min and max.
type Golden = (&'static str, usize, f64, [f32; 3], [f32; 3]);

/// Triangles, emitted power (lm) and bounding box as listed in `shared/scenes/mgf/README.md`.
#[test]
fn root_scenes_match_readme() {
    let Some(dir) = mgf_dir() else { return };
    #[rustfmt::skip]
    let golden: [Golden; 9] = [
        ("cube.mgf", 67, 2.0e5, [0.0, 0.0, 0.0], [10.0, 9.8, 10.0]),
        ("examp1.mgf", 484, 8.7e3, [-0.62, -0.13, -0.05], [0.62, 0.13, 0.05]),
        ("corridor.mgf", 936, 2.3e6, [-5.0, 0.0, -0.3], [15.0, 20.0, 10.3]),
        ("soda.mgf", 95_908, 1.6e3, [-2.03, -0.19, -3.81], [3.05, 2.57, 6.36]),
        ("office2/office2.mgf", 741, 2.6e3, [-0.08, -0.15, -0.02], [4.0, 5.75, 2.8]),
        ("office3/office.mgf", 22_428, 1.7e4, [-2.29, 1.12, -2.29], [2.29, 3.89, 2.29]),
        ("office1/graz.mgf", 26_928, 4.5e3, [-0.3, -0.3, -0.01], [5.32, 4.73, 2.65]),
        ("hospital/main.mgf", 21_118, 1.4e4, [-5.0, 0.0, -0.18], [8.5, 13.0, 2.5]),
        ("hospital/hosp.mgf", 41_748, 2.0e4, [-5.0, 0.0, -0.18], [8.5, 13.0, 2.5]),
    ];
    let mut failures = Vec::new();
    for (name, tris, lm, min, max) in golden {
        let s = load(&dir.join(name));
        let power = luminance(s.emitted_power());
        let (bmin, bmax) = (s.bbox.min, s.bbox.max);
        println!(
            "{name:22} {:>7} tris (README ≈ {tris}), {:>6} dropped, {power:10.4e} lm (≈ {lm:.1e}), \
             bbox {bmin:.3} → {bmax:.3}, {:.3} s",
            s.num_triangles(),
            s.report.degenerate_dropped,
            s.report.load_seconds
        );
        let n = s.num_triangles() as f64;
        if (n - tris as f64).abs() > 0.02 * tris as f64 {
            failures.push(format!("{name}: {n} triangles, README ≈ {tris}"));
        }
        // README powers have two significant digits; tessellated spheres lose a few percent.
        if (power - lm).abs() > 0.1 * lm {
            failures.push(format!("{name}: {power:.4e} lm, README {lm:.1e}"));
        }
        // The README's boxes bound curved primitives conservatively (a cylinder along z from
        // 0 to 10 of radius 0.3 counts as z ∈ [−0.3, 10.3]), so the tessellated box lies
        // inside them and is close: 0.02 + 3 % of the extent.
        let (rmin, rmax) = (Vec3::from(min), Vec3::from(max));
        let tol = 0.02 + 0.03 * (rmax - rmin).max_element();
        let inside = bmin.cmpge(rmin - 0.01).all() && bmax.cmple(rmax + 0.01).all();
        if !inside
            || (bmin - rmin).abs().max_element() > tol
            || (bmax - rmax).abs().max_element() > tol
        {
            failures.push(format!(
                "{name}: bbox {bmin} → {bmax}, README {min:?} → {max:?}"
            ));
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// `office1/graz.mgf` against the OBJ converted from it with the same tessellation.
#[test]
fn graz_matches_obj_triangle_count() {
    let Some(dir) = mgf_dir() else { return };
    let s = load(&dir.join("office1/graz.mgf"));
    let n = s.num_triangles() as f64;
    assert!((n - 26_928.0).abs() <= 0.02 * 26_928.0, "{n} triangles");
    // graz is two-sided throughout (MGF default), examp1 and office2 are not.
    let m = mgf::load_with(&dir.join("office1/graz.mgf"), 4).unwrap();
    assert!(m.all_two_sided());
    let m = mgf::load_with(&dir.join("office2/office2.mgf"), 4).unwrap();
    assert!(!m.all_two_sided());
}

/// The largest scenes load well under a second in release builds.
#[test]
fn load_time_of_largest() {
    let Some(dir) = mgf_dir() else { return };
    for name in ["soda.mgf", "hospital/main.mgf", "office1/graz.mgf"] {
        let t0 = std::time::Instant::now();
        let s = load(&dir.join(name));
        let dt = t0.elapsed().as_secs_f64();
        println!("{name}: {} triangles in {dt:.3} s", s.num_triangles());
        if !cfg!(debug_assertions) {
            assert!(dt < 2.0, "{name} took {dt:.3} s");
        }
    }
}

/// More divisions, more triangles.
#[test]
fn divisions_parameter() {
    let s = format!("{QUAD}v z =\np 0 0 0\nn 0 0 1\nsph a 1\nring z 0 1\n");
    let dir = files(&[("t.mgf", &s)]);
    let p = dir.path().join("t.mgf");
    let n4 = mgf::load_with(&p, 4).unwrap().raw.triangles.len();
    let n2 = mgf::load_with(&p, 2).unwrap().raw.triangles.len();
    assert_eq!(n4, 224 + 16);
    assert_eq!(n2, 48 + 8);
    assert!(mgf::load_with(&p, 0).is_err());
}

/// `xf -a 3 -t 1 0 0` instantiates a unit quad at x = 0, 1, 2.
#[test]
fn xf_array_of_quads() {
    let s = load_str(&format!("{QUAD}xf -a 3 -t 1 0 0\nf a b c d\nxf\n")).unwrap();
    assert_eq!(s.num_triangles(), 6);
    assert!((s.total_area() - 3.0).abs() < 1e-6);
    assert_eq!(s.bbox.min, Vec3::ZERO);
    assert_eq!(s.bbox.max, Vec3::new(3.0, 1.0, 0.0));
    let mut xs: Vec<i32> = (0..6)
        .map(|i| {
            s.tri_vertices(i)
                .iter()
                .map(|p| p.x)
                .fold(f32::MAX, f32::min) as i32
        })
        .collect();
    xs.sort();
    assert_eq!(xs, vec![0, 0, 1, 1, 2, 2]);
}

/// Nested arrays: 2 × 3 quads, cumulative transforms; `-i` repeats; plain blocks nest.
#[test]
fn xf_nested_arrays_and_iterate() {
    let s = load_str(&format!(
        "{QUAD}xf -a 2 -t 0 2 0\nxf -a 3 -t 2 0 0\nf a b c d\nxf\nxf\n\
         xf -t 0 0 5\nxf -i 3 -t 1 0 0\nf a b c d\nxf\nxf\n"
    ))
    .unwrap();
    assert_eq!(s.num_triangles(), 14);
    assert!((s.total_area() - 7.0).abs() < 1e-5);
    assert_eq!(s.bbox.min, Vec3::ZERO);
    assert_eq!(s.bbox.max, Vec3::new(5.0, 3.0, 5.0));
    // The iterated quad sits at x = 3..4, z = 5.
    let top: Vec<_> = (0..14).filter(|&i| s.tri_vertices(i)[0].z == 5.0).collect();
    assert_eq!(top.len(), 2);
    for i in top {
        for p in s.tri_vertices(i) {
            assert!((3.0..=4.0).contains(&p.x), "{p}");
        }
    }
    // The spec's example: a 3 × 5 grid of spheres (grid size 3) at z = 10.
    let s =
        load_str("v vc =\n\tp 0 0 0\nxf -t 1 1 10 -a 3 -t 3 0 0 -a 5 -t 0 3 0\n\tsph vc .5\nxf\n")
            .unwrap();
    assert_eq!(s.num_triangles(), 15 * 224);
    assert!(
        (s.bbox.min - Vec3::new(0.5, 0.5, 9.5)).length() < 1e-5,
        "{:?}",
        s.bbox
    );
    assert!(
        (s.bbox.max - Vec3::new(7.5, 13.5, 10.5)).length() < 1e-5,
        "{:?}",
        s.bbox
    );
    // Rotations: a quarter turn about z maps the quad to x in [-1, 0].
    let s = load_str(&format!("{QUAD}xf -rz 90\nf a b c d\nxf\n")).unwrap();
    assert!((s.bbox.min - Vec3::new(-1.0, 0.0, 0.0)).length() < 1e-6);
    assert!((s.bbox.max - Vec3::new(0.0, 1.0, 0.0)).length() < 1e-6);
}

/// `i` resolves relative to the including file and applies its transform; arrays on `i`.
#[test]
fn include_with_transform_and_relative_path() {
    let dir = files(&[
        (
            "main.mgf",
            "i sub/part.mgf -s 2 -t 10 0 0\ni sub/part.mgf -a 2 -t 0 0 3\n",
        ),
        ("sub/part.mgf", "i quad.mgf\n"),
        ("sub/quad.mgf", &format!("{QUAD}f a b c d\n")),
    ]);
    let s = load(&dir.path().join("main.mgf"));
    assert_eq!(s.num_triangles(), 6);
    assert!((s.total_area() - 6.0).abs() < 1e-5);
    assert_eq!(s.bbox.min, Vec3::ZERO);
    assert_eq!(s.bbox.max, Vec3::new(12.0, 2.0, 3.0));
}

/// An include loop and a missing include are errors naming the file and line.
#[test]
fn include_loop_is_an_error() {
    let dir = files(&[("a.mgf", "# a\ni b.mgf\n"), ("b.mgf", "\n\ni a.mgf\n")]);
    let e = Scene::load(
        dir.path().join("a.mgf").to_str().unwrap(),
        &SceneOptions::default(),
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("b.mgf:3") && e.contains("loop"), "{e}");
    let e = load_str("i nowhere.mgf\n").unwrap_err().to_string();
    assert!(e.contains("t.mgf:1") && e.contains("nowhere.mgf"), "{e}");
    // A chain deeper than the limit is an error, not a stack overflow.
    let mut list: Vec<(String, String)> = (0..80)
        .map(|i| (format!("d{i}.mgf"), format!("i d{}.mgf\n", i + 1)))
        .collect();
    list.push(("d80.mgf".into(), format!("{QUAD}f a b c d\n")));
    let refs: Vec<(&str, &str)> = list.iter().map(|(a, b)| (a.as_str(), b.as_str())).collect();
    let dir = files(&refs);
    let e = Scene::load(
        dir.path().join("d0.mgf").to_str().unwrap(),
        &SceneOptions::default(),
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("deeper"), "{e}");
}

/// `fh` with a square hole: area = outer − hole, all triangles facing +z.
#[test]
fn face_with_hole() {
    let s = load_str(
        "m w =\nrd .5\nv o1 =\np 0 0 0\nv o2 =\np 4 0 0\nv o3 =\np 4 4 0\nv o4 =\np 0 4 0\n\
         v h1 =\np 1 1 0\nv h2 =\np 1 3 0\nv h3 =\np 3 3 0\nv h4 =\np 3 1 0\n\
         fh o1 o2 o3 o4 - h1 h2 h3 h4\n",
    )
    .unwrap();
    assert!((s.total_area() - 12.0).abs() < 1e-5, "{}", s.total_area());
    assert_eq!(s.num_triangles(), 8);
    assert!(s.normals.iter().all(|n| n.z > 0.99));
}

/// Mirroring (`-my`) reverses the vertex order so the mirrored face still faces +z.
#[test]
fn mirror_flips_winding() {
    let s = load_str(&format!("{QUAD}xf -my\nf a b c d\nxf\n")).unwrap();
    assert_eq!(s.bbox.min, Vec3::new(0.0, -1.0, 0.0));
    assert!(s.normals.iter().all(|n| n.z > 0.99), "{:?}", s.normals);
    // Without the mirror, the same face also faces +z; reversed order faces −z.
    let s = load_str(&format!("{QUAD}f d c b a\n")).unwrap();
    assert!(s.normals.iter().all(|n| n.z < -0.99));
    // A mirrored closed sphere still faces outwards.
    let s = load_str(&format!("{QUAD}xf -mx\nsph c 1\nxf\n")).unwrap();
    for i in 0..s.num_triangles() {
        let c = s.tri_centroid(i) - Vec3::new(-1.0, 1.0, 0.0);
        assert!(s.normals[i].dot(c) > 0.0);
    }
}

/// `sides` is recorded per material; two-sided is the default.
#[test]
fn sides_per_material() {
    let text = format!(
        "{QUAD}f a b c d\nm one =\nsides 1\nrd .3\nf a b c\nm two = one\nsides 2\nf a c d\n"
    );
    let dir = files(&[("t.mgf", &text)]);
    let m = mgf::load_with(&dir.path().join("t.mgf"), 4).unwrap();
    assert_eq!(m.two_sided, vec![true, false, true]);
    assert!(!m.all_two_sided());
    let names: Vec<_> = m.raw.materials.iter().map(|m| m.name.as_str()).collect();
    assert_eq!(names, ["white", "one", "two"]);
    let e = load_str(&format!("{QUAD}sides 3\n"))
        .unwrap_err()
        .to_string();
    assert!(e.contains(":11:"), "{e}");
}

/// A material name defined again with other values stays a material of its own, also when a
/// TOML scene merges the file's materials by name: only the lamp emits.
#[test]
fn redefined_material_names_stay_apart() {
    let text = format!("{QUAD}f a b c\nm lamp =\ned 100\nf a c d\nm lamp =\nrd .4\nf a b d\n");
    let dir = files(&[
        ("t.mgf", &text),
        ("s.toml", "name = \"s\"\n\n[[mesh]]\nfile = \"t.mgf\"\n"),
    ]);
    for f in ["t.mgf", "s.toml"] {
        let s = load(&dir.path().join(f));
        assert_eq!(s.materials.len(), 3, "{f}");
        assert_eq!(s.emitters().len(), 1, "{f}");
    }
}

/// The scene is two-sided (solved and path-traced with back faces, no `--two-sided` needed)
/// when every non-emitting material is `sides 2`; a one-sided emitter does not change that, a
/// one-sided reflector does, and then each surface has a back face as its material says.
#[test]
fn two_sided_scene_from_sides() {
    assert!(load_str(&format!("{QUAD}f a b c d\n")).unwrap().two_sided);
    let lamp = "m lamp =\nsides 1\ned 100\nf a c d\n";
    assert!(
        load_str(&format!("{QUAD}f a b c\n{lamp}"))
            .unwrap()
            .two_sided
    );
    let one = "m one =\nsides 1\nrd .3\nf a c d\n";
    let mixed = load_str(&format!("{QUAD}f a b c\n{one}")).unwrap();
    assert!(!mixed.two_sided);
    // Mixed: the `sides 2` surface keeps its back face, the `sides 1` one has none.
    let backs: Vec<bool> = (0..mixed.num_triangles())
        .map(|t| mixed.has_back(t, false))
        .collect();
    let named: Vec<&str> = (0..mixed.num_triangles())
        .map(|t| mixed.material_of(t).name.as_str())
        .collect();
    for (b, n) in backs.iter().zip(&named) {
        assert_eq!(*b, *n != "one", "{named:?} {backs:?}");
    }
    assert!((0..mixed.num_triangles()).all(|t| mixed.has_back(t, true)));
    // A scene description keeps each mesh file's sides: the mixed file beside a one-sided OBJ.
    let obj = "v 0 0 2\nv 1 0 2\nv 0 1 2\nf 1 2 3\n";
    let toml = "[[mesh]]\nfile = \"t.mgf\"\n[[mesh]]\nfile = \"o.obj\"\n";
    let dir = files(&[
        ("t.mgf", &format!("{QUAD}f a b c\n{one}")),
        ("o.obj", obj),
        ("s.toml", toml),
    ]);
    let desc = Scene::load(
        dir.path().join("s.toml").to_str().unwrap(),
        &SceneOptions::default(),
    )
    .unwrap();
    assert!(!desc.two_sided);
    let sides: Vec<(String, bool)> = (0..desc.num_triangles())
        .map(|t| (desc.material_of(t).name.clone(), desc.has_back(t, false)))
        .collect();
    assert_eq!(sides.iter().filter(|s| s.1).count(), 1, "{sides:?}");
    assert!(sides.iter().all(|(n, b)| *b == (n == "white")), "{sides:?}");
    // Built-in and OBJ scenes are one-sided unless asked.
    assert!(
        !Scene::load("cornell", &SceneOptions::default())
            .unwrap()
            .two_sided
    );
}

/// A concave polygon (a U of area 3 × 3 − 2 = 7) is ear-clipped exactly; a repeated closing vertex is
/// dropped.
#[test]
fn concave_polygon_area() {
    let pts = [
        (0, 0),
        (3, 0),
        (3, 3),
        (2, 3),
        (2, 1),
        (1, 1),
        (1, 3),
        (0, 3),
    ];
    let mut text = String::from("m w =\nrd .5\n");
    for (i, (x, y)) in pts.iter().enumerate() {
        text += &format!("v p{i} =\np {x} {y} 0\n");
    }
    text += "f p0 p1 p2 p3 p4 p5 p6 p7 p0\n";
    let s = load_str(&text).unwrap();
    assert!((s.total_area() - 7.0).abs() < 1e-6, "{}", s.total_area());
    assert_eq!(s.num_triangles(), 6);
    assert!(s.normals.iter().all(|n| n.z > 0.99));
}

/// Colours: ρ has luminance `rd`, emission = `ed` × colour / π, `cmix`, `cspec`, `cct`.
#[test]
fn colours_and_emission() {
    let s = load_str(&format!(
        "{QUAD}c red =\ncxy .45 .38\nm r =\nrd .4\nf a b c d\n\
         c\nm lamp =\ned 100\nxf -t 0 0 1\nf d c b a\nxf\n\
         c grey =\ncspec 400 700 1 1 1 1\nc warm =\ncct 3000\nc mix =\ncmix 1 red 1 grey\n\
         m x =\nrd .2\nxf -t 0 0 2\nf a b c d\nxf\n"
    ))
    .unwrap();
    let m = &s.materials;
    let lum = |v: Vec3| 0.2126 * v.x + 0.7152 * v.y + 0.0722 * v.z;
    assert!((lum(m[0].rho) - 0.4).abs() < 1e-4 && m[0].rho.x > m[0].rho.y);
    assert!((m[1].emission - Vec3::splat(100.0 / std::f32::consts::PI)).length() < 1e-3);
    assert!((luminance(s.emitted_power()) - 100.0).abs() < 1e-3);
    assert!((lum(m[2].rho) - 0.2).abs() < 1e-4 && m[2].rho.x > m[2].rho.z);
    let e = load_str(&format!("{QUAD}cmix 1 nothing\n"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("nothing"), "{e}");
}

/// Primitives: tessellation counts and orientation (outwards).
#[test]
fn primitives() {
    let s = load_str(&format!(
        "{QUAD}v z =\np 0 0 3\nn 0 0 1\nsph a 1\ncyl a .5 z\ncone a .5 z 0\nring z .5 1\n\
         torus z 1 2\nprism a b c d 2\n"
    ))
    .unwrap();
    assert_eq!(s.num_triangles(), 224 + 32 + 16 + 32 + 512 + 12);
    // The prism of a counter-clockwise square (normal +z) extends to z = −2, faces outwards.
    let n = s.num_triangles();
    for i in n - 12..n {
        let c = s.tri_centroid(i) - Vec3::new(0.5, 0.5, -1.0);
        assert!(s.normals[i].dot(c) > 0.0, "{i}");
    }
    assert_eq!(s.bbox.min.z, -2.0);
    // The specification's example: a unit cube in the positive octant, faces outwards; a
    // negative length puts it above the face (z ∈ [−1, 0]) facing inwards.
    let cube = "v cv0 =\n\tp 0 0 0\nv cv1 =\n\tp 0 1 0\nv cv2 =\n\tp 1 1 0\nv cv3 =\n\tp 1 0 0\n";
    for (len, sign) in [(1.0f32, 1.0f32), (-1.0, -1.0)] {
        let s = load_str(&format!("{cube}prism cv0 cv1 cv2 cv3 {len}\n")).unwrap();
        assert_eq!(s.num_triangles(), 12);
        assert_eq!(s.bbox.min, Vec3::new(0.0, 0.0, len.min(0.0)));
        assert_eq!(s.bbox.max, Vec3::new(1.0, 1.0, len.max(0.0)));
        let centre = Vec3::new(0.5, 0.5, 0.5 * len);
        for i in 0..12 {
            assert!(
                s.normals[i].dot(s.tri_centroid(i) - centre) * sign > 0.0,
                "{len} {i}"
            );
        }
    }
    // Ring faces its normal.
    for i in 224 + 48..224 + 80 {
        assert!(s.normals[i].z > 0.99);
    }
    assert!(load_str(&format!("{QUAD}ring a 0 1\n"))
        .unwrap_err()
        .to_string()
        .contains("normal"));
}

/// Malformed input: errors with file and line; unknown entities warn and load.
#[test]
fn errors_and_warnings() {
    let e = load_str("m w =\nrd .5\nv a =\np 0 x 0\n")
        .unwrap_err()
        .to_string();
    assert!(e.contains("t.mgf:4") && e.contains("bad number"), "{e}");
    for (text, line, what) in [
        (format!("{QUAD}f a b zz\n"), 11, "zz"),
        (format!("{QUAD}m nope\n"), 11, "nope"),
        (format!("{QUAD}xf -t 1 0 0\nf a b c\n"), 11, "xf"),
        (format!("{QUAD}f a b c\nxf\n"), 12, "xf"),
        (format!("{QUAD}xf -q 1\nxf\n"), 11, "-q"),
        (format!("{QUAD}sph a\n"), 11, "arguments"),
        (format!("{QUAD}rd 2\n"), 11, "rd"),
        (format!("{QUAD}o\n"), 11, "'o'"),
    ] {
        let e = load_str(&text).unwrap_err().to_string();
        assert!(
            e.contains(&format!("t.mgf:{line}")) && e.contains(what),
            "{text}: {e}"
        );
    }
    // Unknown entities (mgflib: warn and skip), including the malformed lines of the set.
    let s = load_str(&format!(
        "{QUAD}0 0 0\nfrobnicate 1 2\n/usr/local/lib/ray/x.cal\nies x.ies\nrs .1 .05\nts .1 0\n\
         f a b c d\n"
    ))
    .unwrap();
    assert_eq!(s.num_triangles(), 2);
}

/// Objects: nested `o` paths, the file stem outside any `o`; backslash continuation; templates.
#[test]
fn objects_templates_continuations() {
    let s = load_str(&format!(
        "{QUAD}f a b c d\no outer\no inner\nf a b \\\n  c d\no\nv e = c\nv\np 5 5 5\nf a b e\no\n"
    ))
    .unwrap();
    assert_eq!(s.objects, vec!["t", "outer/inner", "outer"]);
    assert_eq!(s.tri_object, vec![0, 0, 1, 1, 2]);
    assert_eq!(s.up, hirad::scene::UpAxis::Z);
}

/// A `.toml` scene description takes an `.mgf` mesh.
#[test]
fn toml_scene_takes_mgf_mesh() {
    let dir = files(&[
        ("q.mgf", &format!("{QUAD}f a b c d\n")),
        ("s.toml", "name = \"s\"\n\n[[mesh]]\nfile = \"q.mgf\"\n"),
    ]);
    let s = load(&dir.path().join("s.toml"));
    assert_eq!(s.num_triangles(), 2);
}
