//! Isotropic clusters (spec/radiosity.md correctness test 5): a cluster of many randomly
//! oriented tiny patches receives and emits the power predicted by its projected area ΣA/4,
//! and the power a cluster receives is exactly what its surfaces get.

use glam::{DVec3, Vec3};
use hirad::cluster::{BuildNode, BuildTree, ClusterConfig, ClusterTree, Prims, Strategy};
use hirad::geom::Aabb;
use hirad::progress::NoProgress;
use hirad::radiosity::formfactor::point_to_polygon;
use hirad::radiosity::{solve, ClusterEmission, Reception, SolverConfig, VisibilityMode};
use hirad::rng::SplitMix64;
use hirad::scene::{Material, RawScene, Scene, SceneOptions};

mod radiosity_common;

const PATCHES: usize = 6000;

fn gauss(rng: &mut SplitMix64) -> f32 {
    let u1 = rng.next_f64().max(1e-12);
    let u2 = rng.next_f64();
    ((-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()) as f32
}

/// A cloud of `PATCHES` tiny randomly oriented triangles (material 0) around the origin and
/// a 0.2 m square (material 1) at height 5 facing down.
fn cloud_scene(cloud_emits: bool) -> Scene {
    let mut rng = SplitMix64::new(11);
    let mut raw = RawScene {
        name: "cloud".into(),
        objects: vec!["cloud".into(), "square".into()],
        materials: vec![
            Material {
                name: "patch".into(),
                rho: Vec3::ZERO,
                emission: if cloud_emits {
                    Vec3::splat(std::f32::consts::FRAC_1_PI)
                } else {
                    Vec3::ZERO
                },
            },
            Material {
                name: "square".into(),
                rho: Vec3::ZERO,
                emission: if cloud_emits {
                    Vec3::ZERO
                } else {
                    Vec3::splat(std::f32::consts::FRAC_1_PI)
                },
            },
        ],
        ..Default::default()
    };
    for _ in 0..PATCHES {
        let c = Vec3::new(gauss(&mut rng), gauss(&mut rng), gauss(&mut rng)) * 0.15;
        let b = raw.positions.len() as u32;
        for _ in 0..3 {
            let o = Vec3::new(gauss(&mut rng), gauss(&mut rng), gauss(&mut rng)) * 0.004;
            raw.positions.push(c + o);
        }
        raw.triangles.push([b, b + 1, b + 2]);
        raw.tri_material.push(0);
        raw.tri_object.push(0);
    }
    let b = raw.positions.len() as u32;
    let h = 5.0;
    raw.positions.extend([
        Vec3::new(-0.1, -0.1, h),
        Vec3::new(-0.1, 0.1, h),
        Vec3::new(0.1, 0.1, h),
        Vec3::new(0.1, -0.1, h),
    ]);
    raw.triangles.push([b, b + 1, b + 2]);
    raw.triangles.push([b, b + 2, b + 3]);
    raw.tri_material.extend([1, 1]);
    raw.tri_object.extend([1, 1]);
    Scene::from_raw(raw, &SceneOptions::default()).unwrap()
}

/// Root with the square's triangles attached directly and the cloud as a median-split binary
/// hierarchy (leaves of at most 8 patches).
fn cloud_tree(scene: &Scene) -> (ClusterTree, u32) {
    let prims = Prims::from_scene(scene);
    let mut b = BuildTree::default();
    fn build(b: &mut BuildTree, prims: &Prims, mut ids: Vec<u32>) -> u32 {
        let mut bbox = Aabb::EMPTY;
        for &i in &ids {
            bbox.grow_box(&prims.bbox[i as usize]);
        }
        if ids.len() <= 8 {
            return b.push(BuildNode {
                bbox,
                children: vec![],
                surfaces: ids,
            });
        }
        let ax = bbox.longest_axis();
        ids.sort_by(|&x, &y| {
            prims.centroid[x as usize][ax].total_cmp(&prims.centroid[y as usize][ax])
        });
        let right = ids.split_off(ids.len() / 2);
        let l = build(b, prims, ids);
        let r = build(b, prims, right);
        b.push(BuildNode {
            bbox,
            children: vec![l, r],
            surfaces: vec![],
        })
    }
    let cloud: Vec<u32> = (0..PATCHES as u32).collect();
    let c = build(&mut b, &prims, cloud);
    let n = scene.num_triangles() as u32;
    b.root = b.push(BuildNode {
        bbox: scene.bbox,
        children: vec![c],
        surfaces: vec![n - 2, n - 1],
    });
    let t = ClusterTree::from_build(
        b,
        scene.num_triangles(),
        Strategy::Sah,
        ClusterConfig::default(),
    );
    t.validate(&prims).unwrap();
    (t, 1)
}

fn cloud_area(scene: &Scene) -> f64 {
    scene.areas[..PATCHES].iter().map(|&a| a as f64).sum()
}

fn cloud_centroid(scene: &Scene) -> DVec3 {
    let mut c = DVec3::ZERO;
    for t in 0..PATCHES {
        c += scene.tri_centroid(t).as_dvec3() * scene.areas[t] as f64;
    }
    c / cloud_area(scene)
}

#[test]
fn cluster_receives_projected_area_quarter() {
    let scene = cloud_scene(false);
    let (tree, _) = cloud_tree(&scene);
    let n = scene.num_triangles();
    // Irradiance at the cloud centre on a plane facing each square triangle (E = 1).
    let c = cloud_centroid(&scene);
    let mut h_centre = 0.0;
    for t in [n - 2, n - 1] {
        let poly = scene.tri_vertices(t).map(|p| p.as_dvec3());
        let dir = (scene.tri_centroid(t).as_dvec3() - c).normalize();
        h_centre += point_to_polygon(c, dir, &poly, scene.normals[t].as_dvec3());
    }
    let sum_a = cloud_area(&scene);
    let predicted = h_centre * sum_a / 4.0;
    for mode in [Reception::Isotropic, Reception::Oriented] {
        let cfg = SolverConfig {
            eps: Some(1e9),
            cluster_receive: mode,
            cluster_emission: ClusterEmission::Isotropic,
            ..SolverConfig::default()
        };
        let sol = solve(&scene, &tree, &cfg, &NoProgress).unwrap();
        let received: f64 = (0..PATCHES as u32)
            .map(|t| scene.areas[t as usize] as f64 * sol.triangle_irradiance(t, false).x)
            .sum();
        // What the cluster links deliver, computed from the link list: H at the receiving
        // cluster times the reception weights of its surfaces.
        let el = &sol.elements;
        let mut via_links = 0.0;
        for l in &sol.links.links {
            if el.elems[l.recv as usize].is_cluster() && !el.elems[l.src as usize].is_cluster() {
                let h = l.k as f64 * el.b[l.src as usize].x;
                let d = (el.elems[l.src as usize].centroid - el.elems[l.recv as usize].centroid)
                    .normalize();
                let mut leaves = Vec::new();
                el.leaves_of(l.recv, &mut leaves);
                for s in leaves {
                    let e = &el.elems[s as usize];
                    let w = match mode {
                        Reception::Isotropic => 0.25,
                        Reception::Oriented => e.normal.dot(d).max(0.0) as f64,
                    };
                    // Points shut inside a solid or covered receive nothing (none here).
                    via_links += (e.area * el.open[s as usize]) as f64 * h * w;
                }
            }
        }
        let rel = (received - predicted).abs() / predicted;
        println!(
            "{mode:?}: received {received:.6e}, predicted H·ΣA/4 = {predicted:.6e} (rel {rel:.2e}), \
             through cluster links {via_links:.6e}, {} cluster-surface links",
            sol.stats.links_cs
        );
        assert_eq!(
            sol.stats.shut_triangles, 0,
            "a cloud of loose faces is not a solid"
        );
        assert!(
            sol.stats.links_cs >= 2,
            "the square must link to the cloud as a cluster"
        );
        assert!(
            (received - via_links).abs() <= 1e-9 * received,
            "surfaces got {received}, links delivered {via_links}"
        );
        match mode {
            Reception::Isotropic => assert!(rel < 1e-3, "isotropic reception {rel}"),
            Reception::Oriented => assert!(rel < 0.05, "oriented reception {rel}"),
        }
    }
}

#[test]
fn directional_cluster_receives_the_power_its_surfaces_would() {
    // A directional cluster receiver samples the irradiance on its own surfaces (importance
    // sampled by their hand-out weights) so that the oriented hand-out delivers the power the
    // surfaces would receive one by one: Σ A_k E_k with E_k the exact irradiance of each
    // randomly oriented patch (zero for those facing away). The patches shade each other
    // (about 15% at the cloud's centre), which the sum leaves out: no shadow rays.
    let scene = cloud_scene(false);
    let (tree, _) = cloud_tree(&scene);
    let n = scene.num_triangles();
    let mut exact = 0.0;
    for k in 0..PATCHES {
        let x = scene.tri_centroid(k).as_dvec3();
        let nk = scene.normals[k].as_dvec3();
        for t in [n - 2, n - 1] {
            let poly = scene.tri_vertices(t).map(|p| p.as_dvec3());
            exact +=
                scene.areas[k] as f64 * point_to_polygon(x, nk, &poly, scene.normals[t].as_dvec3());
        }
    }
    let cfg = SolverConfig {
        eps: Some(1e9),
        cluster_receive: Reception::Oriented,
        cluster_emission: ClusterEmission::Directional,
        visibility: VisibilityMode::None,
        ..SolverConfig::default()
    };
    let sol = solve(&scene, &tree, &cfg, &NoProgress).unwrap();
    let received: f64 = (0..PATCHES as u32)
        .map(|t| scene.areas[t as usize] as f64 * sol.triangle_irradiance(t, false).x)
        .sum();
    let rel = (received - exact).abs() / exact;
    println!(
        "directional reception: received {received:.6e}, exact Σ A_k E_k {exact:.6e} (rel {rel:.2e}), \
         {} cluster-surface links",
        sol.stats.links_cs
    );
    assert!(
        sol.stats.links_cs >= 2,
        "the square must link to the cloud as a cluster"
    );
    assert!(rel < 5e-3, "directional reception {rel}");
}

#[test]
fn cluster_emits_projected_area_quarter() {
    let scene = cloud_scene(true);
    let (tree, _) = cloud_tree(&scene);
    let n = scene.num_triangles();
    let cfg = SolverConfig {
        eps: Some(1e9),
        cluster_emission: ClusterEmission::Isotropic,
        ..SolverConfig::default()
    };
    let sol = solve(&scene, &tree, &cfg, &NoProgress).unwrap();
    // Isotropic point source of intensity I = Φ/(4π), Φ = ΣA·B (B = E = 1).
    let c = cloud_centroid(&scene);
    let intensity = cloud_area(&scene) / (4.0 * std::f64::consts::PI);
    let mut predicted = 0.0;
    let mut received = 0.0;
    for t in [n - 2, n - 1] {
        let d = c - scene.tri_centroid(t).as_dvec3();
        let cos = scene.normals[t].as_dvec3().dot(d.normalize());
        predicted += intensity * scene.areas[t] as f64 * cos / d.length_squared();
        received += scene.areas[t] as f64 * sol.triangle_irradiance(t as u32, false).x;
    }
    let rel = (received - predicted).abs() / predicted;
    println!("cluster emission: square receives {received:.6e}, I·Ω predicts {predicted:.6e} (rel {rel:.2e})");
    assert!(rel < 2e-3, "{rel}");
}

/// True projected area `Σ A_k max(0, n_k·d)` of the surfaces below cluster element `c`.
fn projected_area(el: &hirad::radiosity::element::Elements, c: u32, d: Vec3) -> f64 {
    let mut leaves = Vec::new();
    el.leaves_of(c, &mut leaves);
    leaves
        .iter()
        .map(|&s| {
            let e = &el.elems[s as usize];
            e.area as f64 * e.normal.dot(d).max(0.0) as f64
        })
        .sum()
}

static COVERS_NONE: hirad::radiosity::overlap::Covers = hirad::radiosity::overlap::Covers::EMPTY;

/// Kernel context of the isotropic model with one shadow ray (visibility is off in these tests).
fn isotropic_ctx<'a>(
    el: &'a hirad::radiosity::element::Elements,
    tree: &'a ClusterTree,
    vis: &'a hirad::radiosity::visibility::Visibility<'a>,
) -> hirad::radiosity::formfactor::KernelCtx<'a> {
    hirad::radiosity::formfactor::KernelCtx {
        elems: el,
        tree,
        vis,
        covers: &COVERS_NONE,
        n_rays: 1,
        seed: 1,
        emission: ClusterEmission::Isotropic,
        reception: Reception::Oriented,
        occlusion: true,
    }
}

#[test]
fn anisotropy_bound_holds_and_flags_flat_clusters() {
    use hirad::radiosity::element::Elements;
    use hirad::radiosity::visibility::Visibility;
    use hirad::radiosity::VisibilityMode;
    // Every cluster of the random cloud against both square triangles: the true projected
    // area towards the receiver never exceeds the bound (1 + g)·ΣA/4, and a cloud of random
    // normals is nearly isotropic (g ≈ 1 for the whole cloud: its normal sum is nearly zero).
    let scene = cloud_scene(false);
    let (tree, cloud) = cloud_tree(&scene);
    let el = Elements::build(&scene, &tree, false);
    let vis = Visibility::new(&scene, &tree, VisibilityMode::None, 0.1).unwrap();
    let ctx = isotropic_ctx(&el, &tree, &vis);
    let n = scene.num_triangles() as u32;
    let mut checked = 0;
    let mut worst = 0.0f64;
    for c in 1..el.num_clusters {
        for t in [n - 2, n - 1] {
            let r = el.first_root + t;
            let g = ctx.anisotropy(r, c);
            let e = &el.elems[c as usize];
            let d = (el.elems[r as usize].centroid - e.centroid).normalize();
            let ratio = projected_area(&el, c, d) / (e.area as f64 / 4.0);
            assert!(
                ratio <= 1.0 + g + 1e-4,
                "cluster {c}: ratio {ratio} > 1 + {g}"
            );
            worst = worst.max(ratio - 1.0 - g);
            checked += 1;
        }
    }
    let g_cloud = ctx.anisotropy(el.first_root + n - 1, cloud);
    println!("{checked} cluster/receiver pairs within the bound (closest {worst:.3}); cloud g = {g_cloud:.3}");
    assert!(g_cloud <= 1.1, "{g_cloud}");
    assert_eq!(ctx.anisotropy(el.first_root, el.first_root + n - 1), 0.0);
}

/// A 0.1 m square 10 m above the middle of the unit square at z = 0, facing down (object 1).
fn small_square_above(mat: u32) -> radiosity_common::Quad {
    radiosity_common::Quad {
        p: [
            Vec3::new(0.45, 0.45, 10.0),
            Vec3::new(0.45, 0.55, 10.0),
            Vec3::new(0.55, 0.55, 10.0),
            Vec3::new(0.55, 0.45, 10.0),
        ],
        mat,
        group: 1,
    }
}

#[test]
fn flat_cluster_facing_receiver_has_anisotropy_three() {
    use hirad::radiosity::element::Elements;
    use hirad::radiosity::visibility::Visibility;
    use hirad::radiosity::VisibilityMode;
    // A unit square (its own cluster, facing +z) and a small square 10 m above it facing down:
    // the flat cluster shows its full area (4× ΣA/4) straight up, so g = 3 up to the
    // direction cone of the two ends.
    let scene = radiosity_common::quads_scene(
        &[
            radiosity_common::square_z(0.0, true, 0, 0),
            small_square_above(0),
        ],
        vec![radiosity_common::emitter()],
    );
    let tree = radiosity_common::tree_by_object(&scene);
    let el = Elements::build(&scene, &tree, false);
    let vis = Visibility::new(&scene, &tree, VisibilityMode::None, 0.1).unwrap();
    let ctx = isotropic_ctx(&el, &tree, &vis);
    let flat = tree.surface_node[0];
    let top = el.first_root + 2;
    let g = ctx.anisotropy(top, flat);
    println!("flat cluster seen from above: g = {g:.4}");
    assert!((g - 3.0).abs() < 1e-3, "{g}");
}

#[test]
fn flat_cluster_emits_its_true_projected_area_when_directional() {
    // A unit emitting square (its own cluster, facing +z, E = 1) and a small black square
    // 10 m above it facing down, no refinement: the flat cluster sends the small square what the
    // unit square really sends (the point-to-polygon form factor from its centre, 1/(π·100)
    // about), where the isotropic model credits a quarter of it (ΣA/4).
    let top = small_square_above(1);
    let black = hirad::scene::Material {
        name: "black".into(),
        rho: Vec3::ZERO,
        emission: Vec3::ZERO,
    };
    let scene = radiosity_common::quads_scene(
        &[radiosity_common::square_z(0.0, true, 0, 0), top],
        vec![radiosity_common::emitter(), black],
    );
    let tree = radiosity_common::tree_by_object(&scene);
    let c = scene.tri_centroid(2).as_dvec3() * 0.5 + scene.tri_centroid(3).as_dvec3() * 0.5;
    let square: Vec<DVec3> = [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]]
        .iter()
        .map(|p| DVec3::new(p[0], p[1], 0.0))
        .collect();
    let exact = point_to_polygon(c, -DVec3::Z, &square, DVec3::Z);
    let mut got = Vec::new();
    for emission in [ClusterEmission::Directional, ClusterEmission::Isotropic] {
        let cfg = SolverConfig {
            eps: Some(1e9),
            shadow_rays: 16,
            cluster_emission: emission,
            ..SolverConfig::default()
        };
        let sol = solve(&scene, &tree, &cfg, &NoProgress).unwrap();
        assert!(
            sol.stats.links_cs + sol.stats.links_cc >= 1,
            "{emission:?}: no cluster link"
        );
        let h = 0.5 * (sol.triangle_irradiance(2, false).x + sol.triangle_irradiance(3, false).x);
        println!(
            "{emission:?}: irradiance {h:.6e}, exact {exact:.6e}, ratio {:.4}",
            h / exact
        );
        got.push(h / exact);
    }
    assert!((got[0] - 1.0).abs() < 0.01, "directional {}", got[0]);
    assert!((got[1] - 0.25).abs() < 0.005, "isotropic {}", got[1]);
}

#[test]
fn directional_projected_area_expansion() {
    use hirad::radiosity::element::Elements;
    use hirad::radiosity::formfactor::SH2_ERROR;
    // The order-2 expansion of Σ A_k max(0, n_k·d): within 3/32·ΣA of the truth in every
    // direction, its mean over the sphere is the isotropic ΣA/4, and for the cloud of random
    // normals it stays near ΣA/4.
    let scene = cloud_scene(false);
    let (tree, cloud) = cloud_tree(&scene);
    let el = Elements::build(&scene, &tree, false);
    let mut rng = SplitMix64::new(9);
    let mut worst = 0.0f64;
    let mut checked = 0;
    for c in 0..el.num_clusters {
        let a = el.elems[c as usize].area as f64;
        if a <= 0.0 {
            continue;
        }
        let o = el.orient[c as usize];
        let mut mean = 0.0;
        let m = 4000;
        for _ in 0..m {
            let d = Vec3::new(gauss(&mut rng), gauss(&mut rng), gauss(&mut rng)).normalize();
            let p = o.projected_area(a, d.as_dvec3());
            let t = projected_area(&el, c, d);
            worst = worst.max((p - t).abs() / a);
            assert!(
                (p - t).abs() <= SH2_ERROR * a + 1e-5 * a,
                "cluster {c}: {p} vs {t}"
            );
            mean += p;
            checked += 1;
        }
        mean /= m as f64;
        // Clamping at zero only adds; Monte Carlo noise of 4,000 directions.
        assert!(
            mean >= 0.24 * a && mean < 0.27 * a,
            "cluster {c}: mean {mean} of {a}"
        );
    }
    let a = el.elems[cloud as usize].area as f64;
    let o = el.orient[cloud as usize];
    for d in [DVec3::X, DVec3::Y, DVec3::Z, -DVec3::X] {
        let p = o.projected_area(a, d) / (a / 4.0);
        assert!((p - 1.0).abs() < 0.15, "cloud towards {d}: {p}");
    }
    println!("{checked} directions: largest error {worst:.4}·ΣA (bound {SH2_ERROR:.4})");
}

#[test]
fn an_open_members_stratum_is_the_part_of_the_cluster_one_sample_stands_for() {
    use hirad::radiosity::cluster_model::facing_weight;
    use hirad::radiosity::element::{Elements, Kind};
    use hirad::radiosity::visibility::Visibility;
    // For every cluster of the random cloud as receiver, up to eight surfaces below it and four
    // targets: the stratum is the lowest of the surface and its ancestors below the receiver
    // whose hand-out weight Σ A_k w_k towards the square reaches the target (the receiver's
    // child above the surface when none does), and its weight is the brute-force sum over the
    // leaves below it.
    let scene = cloud_scene(false);
    let (tree, _) = cloud_tree(&scene);
    let el = Elements::build(&scene, &tree, false);
    let vis = Visibility::new(&scene, &tree, VisibilityMode::None, 0.1).unwrap();
    let ctx = hirad::radiosity::formfactor::KernelCtx {
        emission: ClusterEmission::Directional,
        ..isotropic_ctx(&el, &tree, &vis)
    };
    let src = el.first_root + scene.num_triangles() as u32 - 1;
    let se = &el.elems[src as usize];
    let weight = |id: u32| {
        let mut leaves = Vec::new();
        el.leaves_of(id, &mut leaves);
        leaves
            .iter()
            .map(|&s| {
                let e = &el.elems[s as usize];
                e.area as f64 * facing_weight(e.centroid, e.normal, se.centroid, se.normal)
            })
            .sum::<f64>()
    };
    let mut checked = 0;
    let mut rng = SplitMix64::new(7);
    for recv in 0..el.num_clusters {
        let mut members = Vec::new();
        el.leaves_of(recv, &mut members);
        for _ in 0..members.len().min(8) {
            let m = members[(rng.next_u64() % members.len() as u64) as usize];
            for n in [1.0, 4.0, 16.0, 1e3] {
                let target = weight(recv) / n;
                let (at, w) = ctx.hand_out_stratum(recv, m, src, target);
                // The chain from the surface up to the receiver's child.
                let mut chain = vec![m];
                while el.elems[*chain.last().unwrap() as usize].parent != recv {
                    chain.push(el.elems[*chain.last().unwrap() as usize].parent);
                }
                let want = *chain
                    .iter()
                    .find(|&&c| weight(c) >= target)
                    .unwrap_or(chain.last().unwrap());
                assert_eq!(at, want, "receiver {recv}, surface {m}, target {target}");
                assert!(el.elems[at as usize].kind == Kind::Cluster || at == m);
                let rel = (w - weight(at)).abs() / weight(at).max(1e-30);
                assert!(rel < 1e-9, "weight {w} against {}", weight(at));
                checked += 1;
            }
        }
    }
    assert!(checked > 100, "{checked} strata checked");
    println!("{checked} strata checked");
}
