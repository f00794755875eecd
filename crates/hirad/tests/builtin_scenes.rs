//! Built-in generated scenes: counts, closure, orientation, dimensions, power, determinism.

use glam::Vec3;
use hirad::scene::{Scene, SceneOptions, UpAxis};
use std::collections::HashMap;

fn load(name: &str) -> Scene {
    Scene::load(name, &SceneOptions::default()).unwrap_or_else(|e| panic!("{name}: {e}"))
}

/// Every undirected edge (by vertex index) is used by exactly two triangles, once in each
/// direction (closed and consistently wound).
fn assert_closed_oriented(s: &Scene) {
    let mut edges: HashMap<(u32, u32), i32> = HashMap::new();
    for t in &s.triangles {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            *edges.entry((a.min(b), a.max(b))).or_default() += if a < b { 1 } else { 1000 };
        }
    }
    for (e, c) in &edges {
        assert_eq!(*c, 1001, "edge {e:?}: count code {c}");
    }
}

fn assert_inward(s: &Scene, centre: Vec3) {
    for i in 0..s.num_triangles() {
        let d = s.normals[i].dot(centre - s.tri_centroid(i));
        assert!(d > 0.0, "triangle {i} faces outwards ({d})");
    }
}

#[test]
fn furnace_cube_is_closed_and_faces_inwards() {
    let s = load("furnace");
    assert_eq!(s.num_triangles(), 192);
    assert_eq!(s.positions.len(), 6 * 16 + 2);
    assert_eq!(s.report.degenerate_dropped, 0);
    assert_closed_oriented(&s);
    assert_inward(&s, Vec3::ZERO);
    assert!((s.total_area() - 6.0).abs() < 1e-5);
    assert_eq!(s.bbox.min, Vec3::splat(-0.5));
    assert_eq!(s.bbox.max, Vec3::splat(0.5));
    for m in &s.materials {
        assert_eq!(m.rho, Vec3::splat(0.5));
        assert!(
            (m.emission * std::f32::consts::PI - Vec3::ONE)
                .abs()
                .max_element()
                < 1e-6
        );
    }
    // Φ = Σ π L_e A = 6 W per channel.
    assert!(
        (s.emitted_power() - glam::DVec3::splat(6.0))
            .abs()
            .max_element()
            < 1e-5
    );
    assert_eq!(s.default_camera().name, "default");

    let s8 = load("furnace:8");
    assert_eq!(s8.num_triangles(), 12 * 64);
    assert_closed_oriented(&s8);
    assert_inward(&s8, Vec3::ZERO);
    assert!(Scene::load("furnace:0", &SceneOptions::default()).is_err());
    assert!(Scene::load("furnace:x", &SceneOptions::default()).is_err());
}

#[test]
fn furnace_sphere_is_closed_and_faces_inwards() {
    let s = load("furnace-sphere");
    // 24 segments, 12 stacks: 2·24 pole triangles + 2·24·10 band triangles.
    assert_eq!(s.num_triangles(), 528);
    assert!((300..=1000).contains(&s.num_triangles()));
    assert_eq!(s.report.degenerate_dropped, 0);
    assert_closed_oriented(&s);
    assert_inward(&s, Vec3::ZERO);
    // Inscribed polyhedron: slightly less than the sphere's 4π r² = π.
    let a = s.total_area();
    assert!(
        a < std::f64::consts::PI && a > 0.97 * std::f64::consts::PI,
        "{a}"
    );
}

#[test]
fn cornell_box_matches_the_measured_data() {
    let s = load("cornell");
    assert_eq!(s.num_triangles(), 32);
    assert_eq!(s.up, UpAxis::Y);
    let e = s.bbox.extent();
    assert!((e.x - 0.556).abs() < 1e-5, "{e}");
    assert!((e.y - 0.5488).abs() < 1e-5, "{e}");
    assert!((e.z - 0.5592).abs() < 1e-5, "{e}");
    assert!(s.bbox.min.abs().max_element() < 1e-6);
    let lights = s.emitters();
    assert_eq!(lights.len(), 2);
    let area: f64 = lights.iter().map(|&i| s.areas[i as usize] as f64).sum();
    assert!((area - 0.13 * 0.105).abs() < 1e-7, "{area}");
    for &i in &lights {
        assert!((s.normals[i as usize] - Vec3::NEG_Y).length() < 1e-6);
        assert!((s.tri_centroid(i as usize).y - 0.5487).abs() < 1e-6);
    }
    let le = glam::DVec3::new(17.0, 12.0, 4.0);
    let want = le * std::f64::consts::PI * 0.13 * 0.105;
    let got = s.emitted_power();
    assert!(
        (got - want).abs().max_element() < 1e-6 * want.max_element(),
        "{got} vs {want}"
    );
    let names: Vec<&str> = s.objects.iter().map(|o| o.as_str()).collect();
    for n in [
        "floor",
        "ceiling",
        "back_wall",
        "left_wall",
        "right_wall",
        "short_block",
    ] {
        assert!(names.contains(&n), "{n}");
    }
    let cam = s.default_camera();
    assert_eq!(cam.name, "default");
    assert_eq!(cam.eye, Vec3::new(0.278, 0.273, -0.8));
    assert_eq!(cam.target, Vec3::new(0.278, 0.273, 0.0));
    assert_eq!(cam.up, Vec3::Y);
    assert!((cam.fov_deg - 39.3).abs() < 1e-4);
    // Total area: walls, floor, ceiling ≈ 5 × 0.31, blocks and the light.
    let total = s.total_area();
    assert!((1.6..2.2).contains(&total), "{total}");
}

#[test]
fn unknown_names_fall_through() {
    assert!(hirad::scene::builtin::generate("no-such-scene")
        .unwrap()
        .is_none());
    assert!(hirad::scene::builtin::generate("cornel").unwrap().is_none());
    assert!(hirad::scene::builtin::generate("cornell:5").is_err());
    assert!(Scene::load("no-such-scene", &SceneOptions::default()).is_err());
    for n in hirad::scene::builtin::NAMES {
        assert!(hirad::scene::builtin::generate(n).unwrap().is_some(), "{n}");
    }
}

/// Signed volume of the triangles of object `o` (positive for closed outward surfaces).
fn signed_volume(s: &Scene, o: u32, origin: Vec3) -> f64 {
    let mut v = 0.0f64;
    for i in 0..s.num_triangles() {
        if s.tri_object[i] == o {
            let [a, b, c] = s.tri_vertices(i).map(|p| (p - origin).as_dvec3());
            v += a.dot(b.cross(c)) / 6.0;
        }
    }
    v
}

fn object_bbox(s: &Scene, o: u32) -> hirad::geom::Aabb {
    let mut bb = hirad::geom::Aabb::EMPTY;
    for i in 0..s.num_triangles() {
        if s.tri_object[i] == o {
            bb.grow_box(&s.tri_bbox(i));
        }
    }
    bb
}

#[test]
fn office_has_furniture_lights_and_consistent_faces() {
    use hirad::scene::builtin::office;
    let s = load("office");
    eprintln!(
        "office: {} triangles, {} objects, {} materials",
        s.num_triangles(),
        s.objects.len(),
        s.materials.len()
    );
    assert_eq!(s.num_triangles(), 8354);
    assert!((5_000..=10_000).contains(&s.num_triangles()));
    assert_eq!(s.report.degenerate_dropped, 0);
    assert_eq!(s.up, UpAxis::Z);
    // Room 8 × 6 × 3 m, +Z up; the window reveals reach 0.25 m beyond the +Z (now −Y) wall.
    assert!(
        (s.bbox.min - Vec3::new(0.0, -6.25, 0.0))
            .abs()
            .max_element()
            < 1e-5,
        "{:?}",
        s.bbox
    );
    assert!(
        (s.bbox.max - Vec3::new(8.0, 0.0, 3.0)).abs().max_element() < 1e-5,
        "{:?}",
        s.bbox
    );
    assert!(s.objects.len() > 300, "{}", s.objects.len());
    assert!(s.materials.len() >= 20);
    // Ceiling lights: two triangles each, facing down, of the documented size and radiance.
    let lights = s.emitters();
    assert_eq!(lights.len(), 2 * office::NUM_LIGHTS);
    for &i in &lights {
        assert!((s.normals[i as usize] - Vec3::NEG_Z).length() < 1e-5);
    }
    let (w, d) = office::LIGHT_SIZE;
    let a = (office::NUM_LIGHTS as f32 * w * d) as f64;
    let want = office::LIGHT_EMISSION.as_dvec3() * std::f64::consts::PI * a;
    assert!((s.emitted_power() - want).abs().max_element() < 1e-4 * want.max_element());
    // Room surfaces face into the room.
    let centre = Vec3::new(4.0, -3.0, 1.5);
    let mut room_tris = 0;
    for i in 0..s.num_triangles() {
        let name = &s.objects[s.tri_object[i] as usize];
        if ["floor", "ceiling"].contains(&name.as_str()) || name.starts_with("wall_") {
            assert!(s.normals[i].dot(centre - s.tri_centroid(i)) > 0.0, "{name}");
            room_tris += 1;
        }
    }
    assert_eq!(
        room_tris,
        2 * (2 * 16 * 12 + 2 * 12 * 6 + 2 * 16 * 6) - 2 * 27
    );
    // Furniture is made of closed outward solids: positive volume; a book or archive box is
    // one box, whose signed volume equals its bounding box volume.
    let mut books = 0;
    for (o, name) in s.objects.iter().enumerate() {
        let o = o as u32;
        let bb = object_bbox(&s, o);
        let v = signed_volume(&s, o, bb.center());
        let furniture = [
            "book_",
            "box_",
            "desk_",
            "chair_",
            "monitor_",
            "keyboard_",
            "mug_",
        ]
        .iter()
        .any(|p| name.starts_with(p));
        if furniture || name.starts_with("bookcase_") || name.starts_with("ceiling_light") {
            assert!(v > 0.0, "{name}: volume {v}");
        }
        if name.starts_with("book_") || name.starts_with("box_") {
            let e = bb.extent().as_dvec3();
            let bv = e.x * e.y * e.z;
            assert!((v - bv).abs() < 1e-3 * bv, "{name}: {v} vs {bv}");
            books += 1;
        }
    }
    assert!(books > 250, "{books}");
    let cam = s.default_camera();
    assert_eq!(cam.up, Vec3::Z);
    assert!(cam.eye.z > 1.0 && cam.eye.z < 3.0);
}

#[test]
fn same_seed_same_scene() {
    for name in [
        "furnace",
        "cornell",
        "office",
        "office@7",
        "soup:20000",
        "trees:2",
        "trees@9",
    ] {
        let a = load(name);
        let b = load(name);
        assert_eq!(a.positions, b.positions, "{name}");
        assert_eq!(a.triangles, b.triangles, "{name}");
        assert_eq!(a.tri_material, b.tri_material, "{name}");
        assert_eq!(a.tri_object, b.tri_object, "{name}");
        assert_eq!(a.materials, b.materials, "{name}");
    }
    assert_ne!(load("office").positions, load("office@7").positions);
    assert_ne!(load("soup:20000").positions, load("soup:20000@1").positions);
    assert_ne!(load("trees").positions, load("trees@1").positions);
}

/// Mean distance between the centroids of consecutive triangles, and between triangles a
/// fixed large stride apart (a proxy for random pairs).
fn consecutive_vs_random_distance(s: &Scene) -> (f64, f64) {
    let n = s.num_triangles();
    let c: Vec<Vec3> = (0..n).map(|i| s.tri_centroid(i)).collect();
    let mut near = 0.0f64;
    let mut far = 0.0f64;
    for i in 0..n - 1 {
        near += c[i].distance(c[i + 1]) as f64;
        far += c[i].distance(c[(i + n / 2 + 7) % n]) as f64;
    }
    (near / (n - 1) as f64, far / (n - 1) as f64)
}

#[test]
fn soup_is_a_shuffled_soup_of_the_requested_size() {
    use hirad::scene::builtin::soup;
    let t0 = std::time::Instant::now();
    let s = load("soup");
    eprintln!(
        "soup: {} triangles, {} vertices, generated and validated in {:.2} s (dev profile)",
        s.num_triangles(),
        s.positions.len(),
        t0.elapsed().as_secs_f64()
    );
    assert_eq!(s.num_triangles(), SOUP_TRIANGLES);
    assert!((s.num_triangles() as f64 / 200_000.0 - 1.0).abs() < 0.02);
    assert_eq!(s.report.degenerate_dropped, 0);
    // No object structure.
    assert_eq!(s.objects.len(), 1);
    assert!(s.tri_object.iter().all(|&o| o == 0));
    // Shuffled: consecutive triangles are as far apart as random pairs; so are the vertices
    // of consecutive triangles in the vertex array.
    let (near, far) = consecutive_vs_random_distance(&s);
    eprintln!("soup: consecutive centroid distance {near:.2} m, random pairs {far:.2} m");
    assert!(near > 0.8 * far, "{near} vs {far}");
    let nv = s.positions.len() as f64;
    let spread: f64 = s
        .triangles
        .iter()
        .map(|t| (t.iter().max().unwrap() - t.iter().min().unwrap()) as f64)
        .sum::<f64>()
        / s.num_triangles() as f64;
    assert!(spread > 0.2 * nv, "mean index spread {spread} of {nv}");
    // Hall of 8 bays (48 × 12 × 24 m), +Y up.
    let bays = soup::bays_for(200_000);
    assert_eq!(bays, 8);
    let e = s.bbox.extent();
    assert!(
        (e - Vec3::new(48.0, 12.0, 24.0)).abs().max_element() < 1e-4,
        "{e}"
    );
    assert_eq!(s.up, UpAxis::Y);
    // Emitters: the light panels, facing down, of the documented total area and power.
    let lights = s.emitters();
    let (w, d) = soup::LIGHT_SIZE;
    let area = (bays as usize * soup::LIGHTS_PER_BAY) as f64 * (w * d) as f64;
    let got: f64 = lights.iter().map(|&i| s.areas[i as usize] as f64).sum();
    assert!((got - area).abs() < 1e-4 * area, "{got} vs {area}");
    for &i in &lights {
        assert!((s.normals[i as usize] - Vec3::NEG_Y).length() < 1e-5);
    }
    let want = soup::LIGHT_EMISSION.as_dvec3() * std::f64::consts::PI * area;
    assert!((s.emitted_power() - want).abs().max_element() < 1e-4 * want.max_element());
    // Consistent winding: the hall faces inwards (−volume) and the solids outwards (+volume),
    // the open light panels contribute nothing about an origin in their plane.
    let origin = Vec3::new(0.0, soup::LIGHT_Y, 0.0);
    let mut v = 0.0f64;
    for i in 0..s.num_triangles() {
        let [a, b, c] = s.tri_vertices(i).map(|p| (p - origin).as_dvec3());
        v += a.dot(b.cross(c)) / 6.0;
    }
    let hall = 48.0 * 12.0 * 24.0;
    assert!(
        v > -hall && v < -0.8 * hall,
        "signed volume {v}, hall {hall}"
    );

    let small = load("soup:20000");
    assert_eq!(small.num_triangles(), SOUP20K_TRIANGLES);
    assert!((small.num_triangles() as f64 / 20_000.0 - 1.0).abs() < 0.03);
    assert!(Scene::load("soup:0", &SceneOptions::default()).is_err());
}

const SOUP_TRIANGLES: usize = 200_012;
const SOUP20K_TRIANGLES: usize = 19_766;
const TREES_TRIANGLES: usize = 60_376;

#[test]
fn trees_have_sun_sky_leaves_and_ground() {
    use hirad::scene::builtin::trees;
    let s = load("trees");
    eprintln!(
        "trees: {} triangles, {} objects",
        s.num_triangles(),
        s.objects.len()
    );
    assert_eq!(s.num_triangles(), TREES_TRIANGLES);
    assert!((40_000..=100_000).contains(&s.num_triangles()));
    assert_eq!(s.report.degenerate_dropped, 0);
    assert!(s.emitters().is_empty());
    let sun = s.sun.expect("sun");
    assert!((sun.direction.length() - 1.0).abs() < 1e-6);
    assert!((sun.direction.y - 45f32.to_radians().sin()).abs() < 1e-5);
    assert_eq!(sun.irradiance, Vec3::splat(800.0));
    assert_eq!(s.sky, Some(trees::SKY_RADIANCE));
    assert_eq!(s.up, UpAxis::Y);
    let n = trees::DEFAULT_TREES as usize;
    assert_eq!(s.objects.len(), n + 1);
    // Ground: 2·80² triangles facing up covering 40 × 40 m.
    let ground: Vec<usize> = (0..s.num_triangles())
        .filter(|&i| s.tri_object[i] == 0)
        .collect();
    assert_eq!(ground.len(), 2 * 80 * 80);
    let ga: f64 = ground.iter().map(|&i| s.areas[i] as f64).sum();
    assert!((ga - 1600.0).abs() < 1e-2, "{ga}");
    assert!(ground.iter().all(|&i| s.normals[i] == Vec3::Y));
    // Leaves: LEAVES_PER_TREE diamonds per tree, above the ground, small.
    let leaf = s.materials.iter().position(|m| m.name == "leaf").unwrap() as u32;
    let leaves: Vec<usize> = (0..s.num_triangles())
        .filter(|&i| s.tri_material[i] == leaf)
        .collect();
    assert_eq!(leaves.len(), 2 * n * trees::LEAVES_PER_TREE as usize);
    for &i in &leaves {
        assert!(s.tri_bbox(i).min.y > 1.0);
        assert!(s.areas[i] < 0.2 * 0.13 / 2.0 + 1e-6);
    }
    // Leaf orientations are random: the mean normal is short.
    let mean: Vec3 = leaves.iter().map(|&i| s.normals[i]).sum::<Vec3>() / leaves.len() as f32;
    assert!(mean.length() < 0.05, "{mean}");
    // Everything stands on the ground plane within the 40 m square.
    assert!(s.bbox.min.y > -1e-4 && s.bbox.max.y < 12.0);
    assert!((s.bbox.min.x + 20.0).abs() < 1e-4 && (s.bbox.max.z - 20.0).abs() < 1e-4);
    let three = load("trees:3");
    assert_eq!(three.objects.len(), 4);
    assert!(Scene::load("trees:0", &SceneOptions::default()).is_err());
}

proptest::proptest! {
    #![proptest_config(proptest::prelude::ProptestConfig::with_cases(6))]

    /// Any size and seed: about the requested count, nothing degenerate, one object, valid.
    #[test]
    fn soup_of_any_size_and_seed(n in 4_000u64..150_000, seed in 0u64..1_000_000) {
        let s = load(&format!("soup:{n}@{seed}"));
        let got = s.num_triangles() as f64;
        proptest::prop_assert!((got / n as f64 - 1.0).abs() < 0.05, "{} for {}", got, n);
        proptest::prop_assert_eq!(s.report.degenerate_dropped, 0);
        proptest::prop_assert_eq!(s.objects.len(), 1);
        proptest::prop_assert!(!s.emitters().is_empty());
    }

    /// Any seed: office and trees keep their structure and have no degenerate triangles.
    #[test]
    fn office_and_trees_of_any_seed(seed in 0u64..1_000_000, n in 1u32..10) {
        let o = load(&format!("office@{seed}"));
        proptest::prop_assert!((5_000..=10_000).contains(&o.num_triangles()));
        proptest::prop_assert_eq!(o.report.degenerate_dropped, 0);
        proptest::prop_assert_eq!(o.emitters().len(), 12);
        let t = load(&format!("trees:{n}@{seed}"));
        proptest::prop_assert_eq!(t.report.degenerate_dropped, 0);
        proptest::prop_assert_eq!(t.objects.len(), n as usize + 1);
        let leaves = 2 * n as usize * hirad::scene::builtin::trees::LEAVES_PER_TREE as usize;
        proptest::prop_assert!(t.num_triangles() > leaves + 2 * 80 * 80);
        proptest::prop_assert!(t.bbox.min.y > -1e-4);
    }
}
