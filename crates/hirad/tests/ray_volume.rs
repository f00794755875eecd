//! Volumetric transmittance (Sillion 1995) through cluster trees.

use glam::Vec3;
use hirad::cluster::{BuildNode, BuildTree, ClusterConfig, ClusterTree, Prims, Strategy};
use hirad::geom::Aabb;
use hirad::ray::volume::{Endpoint, VolumeCaster, VolumeQuery};
use hirad::ray::{RayCaster, Segment};
use hirad::rng::SplitMix64;
use hirad::scene::{Material, RawScene, Scene, SceneOptions};

/// The spec's parameter range of a segment (`ray-casting test`).
const SPEC: (f32, f32) = (Segment::SPEC_TMIN, Segment::SPEC_TMAX);

fn scene_from(positions: Vec<Vec3>, triangles: Vec<[u32; 3]>) -> Scene {
    let n = triangles.len();
    let raw = RawScene {
        name: "test".into(),
        positions,
        triangles,
        tri_material: vec![0; n],
        tri_object: vec![0; n],
        materials: vec![Material::diffuse("m", Vec3::splat(0.5))],
        ..Default::default()
    };
    Scene::from_raw(raw, &SceneOptions::default()).unwrap()
}

/// Random unit vector.
fn unit(g: &mut SplitMix64) -> Vec3 {
    let z = 2.0 * g.next_f32() - 1.0;
    let phi = std::f32::consts::TAU * g.next_f32();
    let r = (1.0 - z * z).max(0.0).sqrt();
    Vec3::new(r * phi.cos(), r * phi.sin(), z)
}

/// `n` randomly oriented equilateral triangles of edge `edge`, centroids uniform in `region`.
fn random_polygons(g: &mut SplitMix64, n: usize, edge: f32, region: Aabb) -> Scene {
    let mut pos = Vec::with_capacity(3 * n);
    let mut tris = Vec::with_capacity(n);
    let r = edge / 3f32.sqrt();
    for i in 0..n {
        let c = region.min + Vec3::new(g.next_f32(), g.next_f32(), g.next_f32()) * region.extent();
        let nrm = unit(g);
        let u = nrm.any_orthonormal_vector();
        let v = nrm.cross(u);
        let a0 = std::f32::consts::TAU * g.next_f32();
        for k in 0..3 {
            let a = a0 + k as f32 * std::f32::consts::TAU / 3.0;
            pos.push(c + (u * a.cos() + v * a.sin()) * r);
        }
        let b = 3 * i as u32;
        tris.push([b, b + 1, b + 2]);
    }
    scene_from(pos, tris)
}

/// One node holding every surface.
fn single_node(scene: &Scene) -> ClusterTree {
    let mut b = BuildTree::default();
    b.root = b.push(BuildNode {
        bbox: scene.bbox,
        children: vec![],
        surfaces: (0..scene.num_triangles() as u32).collect(),
    });
    ClusterTree::from_build(
        b,
        scene.num_triangles(),
        Strategy::Sah,
        ClusterConfig::default(),
    )
}

/// Regular grid of `nx × ny × nz` cells over `region`, each cell a tight cluster of the
/// surfaces whose centroid it contains, under one root.
fn grid_tree(scene: &Scene, region: Aabb, dims: [usize; 3]) -> ClusterTree {
    let prims = Prims::from_scene(scene);
    let mut cells: Vec<Vec<u32>> = vec![Vec::new(); dims[0] * dims[1] * dims[2]];
    for (i, c) in prims.centroid.iter().enumerate() {
        let f = (*c - region.min) / region.extent();
        let ix = |a: usize| ((f[a] * dims[a] as f32) as usize).min(dims[a] - 1);
        cells[(ix(2) * dims[1] + ix(1)) * dims[0] + ix(0)].push(i as u32);
    }
    let mut b = BuildTree::default();
    let mut children = Vec::new();
    let mut root_box = Aabb::EMPTY;
    for cell in cells.into_iter().filter(|c| !c.is_empty()) {
        let mut bb = Aabb::EMPTY;
        for &s in &cell {
            bb.grow_box(&prims.bbox[s as usize]);
        }
        root_box.grow_box(&bb);
        children.push(b.push(BuildNode {
            bbox: bb,
            children: vec![],
            surfaces: cell,
        }));
    }
    b.root = b.push(BuildNode {
        bbox: root_box,
        children,
        surfaces: vec![],
    });
    let t = ClusterTree::from_build(
        b,
        scene.num_triangles(),
        Strategy::Sah,
        ClusterConfig::default(),
    );
    t.validate(&prims).unwrap();
    t
}

#[test]
fn single_cluster_gives_exp_minus_kappa_l() {
    let mut g = SplitMix64::new(1);
    let region = Aabb::new(Vec3::ZERO, Vec3::ONE);
    let scene = random_polygons(&mut g, 1000, 0.1, region);
    let tree = single_node(&scene);
    let vc = VolumeCaster::new(&scene, &tree);
    let b = scene.bbox;
    let kappa = scene.total_area() / (4.0 * b.volume_f64());
    assert!((vc.kappa(0) as f64 - kappa).abs() < 1e-6 * kappa);
    // Along x through the middle: ℓ = x extent of the box (the segment is 20 long, the box
    // about 1: used as a volume for vol_ratio 0.1).
    let c = b.center();
    let p = Vec3::new(-5.0, c.y, c.z);
    let q = Vec3::new(15.0, c.y, c.z);
    let tau = vc.transmittance(p, q, 0.1, Endpoint::None, Endpoint::None);
    let want = (-kappa * b.extent().x as f64).exp();
    assert!((tau as f64 - want).abs() < 1e-5, "{tau} vs {want}");
    assert!(want < 0.9 && want > 0.05, "{want}");
    // Along the main diagonal: ℓ = |diagonal|.
    let d = b.max - b.min;
    let p = b.min - d * 5.0;
    let q = b.max + d * 5.0;
    let tau = vc.transmittance(p, q, 0.1, Endpoint::None, Endpoint::None);
    let want = (-kappa * d.length() as f64).exp();
    assert!((tau as f64 - want).abs() < 1e-5, "{tau} vs {want}");
    // A segment ending in the middle of the box starts among its surfaces: the cluster is
    // not a volume, its surfaces are tested exactly, as ray casting does.
    let rc = RayCaster::new(&scene, &tree);
    let p = Vec3::new(-19.0, c.y, c.z);
    let tau = vc.transmittance(p, c, 0.1, Endpoint::None, Endpoint::None);
    let occ = rc.occluded(p, c - p, Segment::SPEC_TMIN, Segment::SPEC_TMAX);
    assert_eq!(tau, if occ { 0.0 } else { 1.0 });
    // Missing the box: 1.
    let tau = vc.transmittance(
        Vec3::new(-5.0, 3.0, 0.5),
        Vec3::new(5.0, 3.0, 0.5),
        0.1,
        Endpoint::None,
        Endpoint::None,
    );
    assert_eq!(tau, 1.0);
    // The cluster holding an end point is never a volume: descending into the leaf tests its
    // surfaces exactly, which gives 0 or 1 and equals ray casting.
    let p = Vec3::new(-5.0, c.y, c.z);
    let q = Vec3::new(15.0, c.y, c.z);
    let occ = rc.occluded(p, q - p, Segment::SPEC_TMIN, Segment::SPEC_TMAX);
    let tau = vc.transmittance(p, q, 0.1, Endpoint::Cluster(0), Endpoint::None);
    assert_eq!(tau, 1.0, "excluded cluster contributes nothing");
    let tau = vc.transmittance(p, q, 0.1, Endpoint::Surface(0), Endpoint::None);
    assert_eq!(tau, if occ { 0.0 } else { 1.0 });
}

#[test]
fn empty_and_degenerate_give_one() {
    let scene = scene_from(vec![Vec3::ZERO, Vec3::X, Vec3::Y], vec![[0, 1, 2]]);
    let mut tree = single_node(&scene);
    let vc = VolumeCaster::new(&scene, &tree);
    // A flat cluster (one triangle) is never a volume: a segment crossing it far from it is
    // blocked exactly where it meets the triangle (the model would let exp(−1/8) through).
    let across = |x: f32, y: f32| {
        vc.transmittance(
            Vec3::new(x, y, -10.0),
            Vec3::new(x, y, 10.0),
            0.1,
            Endpoint::None,
            Endpoint::None,
        )
    };
    assert_eq!(across(0.2, 0.2), 0.0);
    assert_eq!(across(0.8, 0.8), 1.0);
    // Zero-length segment.
    assert_eq!(
        vc.transmittance(Vec3::ONE, Vec3::ONE, 0.1, Endpoint::None, Endpoint::None),
        1.0
    );
    // A tree without nodes.
    tree.nodes.clear();
    let vc = VolumeCaster::new(&scene, &tree);
    assert_eq!(
        vc.transmittance(
            Vec3::new(0.2, 0.2, -1.0),
            Vec3::new(0.2, 0.2, 1.0),
            0.1,
            Endpoint::None,
            Endpoint::None
        ),
        1.0
    );
}

#[test]
fn symmetric_and_exact_at_zero_ratio() {
    let mut g = SplitMix64::new(5);
    let region = Aabb::new(Vec3::ZERO, Vec3::new(2.0, 2.0, 1.0));
    let scene = random_polygons(&mut g, 2000, 0.06, region);
    let tree = grid_tree(&scene, region, [6, 6, 3]);
    let vc = VolumeCaster::new(&scene, &tree);
    let rc = RayCaster::new(&scene, &tree);
    let mut queries = Vec::new();
    for _ in 0..400 {
        let p = Vec3::new(
            g.next_f32() * 4.0 - 1.0,
            g.next_f32() * 4.0 - 1.0,
            -1.0 - g.next_f32(),
        );
        let q = Vec3::new(
            g.next_f32() * 4.0 - 1.0,
            g.next_f32() * 4.0 - 1.0,
            2.0 + g.next_f32(),
        );
        queries.push(VolumeQuery {
            p,
            q,
            a: Endpoint::None,
            b: Endpoint::None,
        });
    }
    let mut partial = 0;
    for x in &queries {
        for ratio in [0.05f32, 0.1, 0.5] {
            let ab = vc.transmittance(x.p, x.q, ratio, x.a, x.b);
            let ba = vc.transmittance(x.q, x.p, ratio, x.b, x.a);
            assert!((ab - ba).abs() <= 1e-4 * ab.max(1e-3), "{ab} vs {ba}");
            assert!((0.0..=1.0).contains(&ab));
            partial += (ab > 0.0 && ab < 1.0) as u32;
        }
        // vol_ratio 0: exact ray-cast visibility.
        let exact = vc.transmittance(x.p, x.q, 0.0, x.a, x.b);
        let occ = rc.occluded(x.p, x.q - x.p, Segment::SPEC_TMIN, Segment::SPEC_TMAX);
        assert_eq!(exact, if occ { 0.0 } else { 1.0 });
    }
    assert!(partial > 300, "{partial}");
    // Batch equals sequential, for 1 and 2 threads.
    let seq: Vec<f32> = queries
        .iter()
        .map(|x| vc.transmittance(x.p, x.q, 0.1, x.a, x.b))
        .collect();
    for threads in [1, 2] {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        assert_eq!(pool.install(|| vc.transmittance_batch(&queries, 0.1)), seq);
    }
}

/// A slab of many small, randomly oriented polygons, clustered in tight grid cells: the mean
/// volumetric estimate follows the ray-cast unoccluded fraction. With κ = ΣA/(4V) (the spec's
/// value) the ray-cast fraction of two-sided random polygons is close to `τ²` (mean projected
/// area A/2 instead of A/4); asserted within 0.03 absolute, and τ itself is clearly larger.
#[test]
fn dense_slab_matches_ray_cast_fraction() {
    let mut g = SplitMix64::new(9);
    let region = Aabb::new(Vec3::ZERO, Vec3::new(1.0, 1.0, 0.25));
    // ΣA ≈ 6000 · 3.9e-4 = 2.3 over V = 0.25: κ ≈ 2.3, vertical optical depth ≈ 0.58.
    let scene = random_polygons(&mut g, 6000, 0.03, region);
    let tree = grid_tree(&scene, region, [16, 16, 4]);
    let vc = VolumeCaster::new(&scene, &tree);
    let rc = RayCaster::new(&scene, &tree);
    let n = 20_000;
    let mut unoccluded = 0u32;
    let mut sum_tau = 0f64;
    let mut sum_tau2 = 0f64;
    for _ in 0..n {
        // Steep segments through the inner part of the slab (no side effects).
        let x = 0.25 + 0.5 * g.next_f32();
        let y = 0.25 + 0.5 * g.next_f32();
        let dx = (g.next_f32() - 0.5) * 0.2;
        let dy = (g.next_f32() - 0.5) * 0.2;
        let p = Vec3::new(x - dx, y - dy, -2.0);
        let q = Vec3::new(x + dx, y + dy, 2.25);
        let tau = vc.transmittance(p, q, 0.1, Endpoint::None, Endpoint::None) as f64;
        sum_tau += tau;
        sum_tau2 += tau * tau;
        unoccluded += !rc.occluded(p, q - p, Segment::SPEC_TMIN, Segment::SPEC_TMAX) as u32;
    }
    let frac = unoccluded as f64 / n as f64;
    let mean_tau = sum_tau / n as f64;
    let mean_tau2 = sum_tau2 / n as f64;
    println!("ray-cast unoccluded {frac:.4}, mean τ {mean_tau:.4}, mean τ² {mean_tau2:.4}");
    assert!(frac > 0.2 && frac < 0.6, "{frac}");
    assert!((frac - mean_tau2).abs() < 0.03, "{frac} vs τ² {mean_tau2}");
    assert!(mean_tau > frac + 0.1, "{mean_tau} vs {frac}");
}

#[test]
fn end_point_clusters_are_excluded() {
    // Three dense clusters on a line: A around x = 0, M around x = 5, B around x = 10.
    let mut g = SplitMix64::new(3);
    let mut pos = Vec::new();
    let mut tris = Vec::new();
    let mut groups = Vec::new();
    for cx in [0.0f32, 5.0, 10.0] {
        let region = Aabb::new(
            Vec3::new(cx - 0.5, -0.5, -0.5),
            Vec3::new(cx + 0.5, 0.5, 0.5),
        );
        let s = random_polygons(&mut g, 200, 0.05, region);
        let base = pos.len() as u32;
        let first = tris.len() as u32;
        pos.extend(s.positions.iter().copied());
        tris.extend(s.triangles.iter().map(|t| t.map(|v| v + base)));
        groups.push(first..tris.len() as u32);
    }
    let scene = scene_from(pos, tris);
    let prims = Prims::from_scene(&scene);
    let mut b = BuildTree::default();
    let mut children = Vec::new();
    for gr in &groups {
        let mut bb = Aabb::EMPTY;
        for s in gr.clone() {
            bb.grow_box(&prims.bbox[s as usize]);
        }
        children.push(b.push(BuildNode {
            bbox: bb,
            children: vec![],
            surfaces: gr.clone().collect(),
        }));
    }
    b.root = b.push(BuildNode {
        bbox: scene.bbox,
        children,
        surfaces: vec![],
    });
    let tree = ClusterTree::from_build(
        b,
        scene.num_triangles(),
        Strategy::Sah,
        ClusterConfig::default(),
    );
    let vc = VolumeCaster::new(&scene, &tree);
    // Node ids: root 0, then A, M, B in order.
    let (a, m, bb) = (1u32, 2u32, 3u32);
    let p = Vec3::new(0.0, 0.01, 0.02);
    let q = Vec3::new(10.0, -0.01, 0.0);
    let depth_m = vc
        .optical_depth(
            p,
            q,
            SPEC,
            0.5,
            (Endpoint::Cluster(a), Endpoint::Cluster(bb)),
        )
        .unwrap();
    // Only M counts: κ_M times the length inside M's padded (here: real) box.
    let mb = tree.nodes[m as usize].bbox;
    let t0 = (mb.min.x - p.x) / (q.x - p.x);
    let t1 = (mb.max.x - p.x) / (q.x - p.x);
    let want = vc.kappa(m) as f64 * ((t1 - t0) * (q - p).length()) as f64;
    assert!((depth_m - want).abs() < 1e-4 * want, "{depth_m} vs {want}");
    // Without exclusions the end clusters still contain the end points: they are descended
    // and their surfaces tested exactly (the segment starts among them), so the depth is M's
    // alone, or a surface of A or B blocks the segment.
    let all = vc.optical_depth(p, q, SPEC, 0.5, (Endpoint::None, Endpoint::None));
    assert!(all.is_none_or(|d| (d - depth_m).abs() < 1e-9), "{all:?}");
    // A segment that crosses A from outside takes it as a volume: A adds the depth of its
    // whole width.
    let far = Vec3::new(-20.0, p.y, p.z);
    let crossing = vc
        .optical_depth(far, q, SPEC, 0.5, (Endpoint::None, Endpoint::Cluster(bb)))
        .unwrap();
    assert!(crossing > depth_m * 1.5, "{crossing} vs {depth_m}");
    // Root is the ancestor of the end clusters: never a volume even with a huge ratio.
    let big = vc
        .optical_depth(
            p,
            q,
            SPEC,
            100.0,
            (Endpoint::Cluster(a), Endpoint::Cluster(bb)),
        )
        .unwrap();
    assert!((big - depth_m).abs() < 1e-9);
    // Surface end points: their clusters are descended, tested exactly, except the surfaces
    // themselves. The segment then either hits something in A or B (τ = 0) or gets M only.
    let sa = groups[0].start;
    let sb = groups[2].start;
    let pa = scene.tri_centroid(sa as usize);
    let pb = scene.tri_centroid(sb as usize);
    let d = vc.optical_depth(
        pa,
        pb,
        SPEC,
        0.5,
        (Endpoint::Surface(sa), Endpoint::Surface(sb)),
    );
    if let Some(d) = d {
        assert!(d > 0.0 && d < depth_m * 2.0);
    }
}

/// Appends `n × n` quads (two triangles each) tiling the parallelogram `o + s·u + t·w`,
/// `s, t ∈ [0, 1]`, each shrunk by `gap` of its cell on every side; with `gap` 0 the tiles
/// share their corner vertices (one connected surface).
fn push_tiles(
    (o, u, w): (Vec3, Vec3, Vec3),
    n: usize,
    gap: f32,
    pos: &mut Vec<Vec3>,
    tris: &mut Vec<[u32; 3]>,
) {
    let at = |s: f32, t: f32| o + u * s + w * t;
    if gap == 0.0 {
        let base = pos.len() as u32;
        for j in 0..=n {
            for i in 0..=n {
                pos.push(at(i as f32 / n as f32, j as f32 / n as f32));
            }
        }
        let id = |i: usize, j: usize| base + (j * (n + 1) + i) as u32;
        for j in 0..n {
            for i in 0..n {
                let q = [id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1)];
                tris.push([q[0], q[1], q[2]]);
                tris.push([q[0], q[2], q[3]]);
            }
        }
        return;
    }
    for j in 0..n {
        for i in 0..n {
            let (s0, t0) = ((i as f32 + gap) / n as f32, (j as f32 + gap) / n as f32);
            let (s1, t1) = (
                (i as f32 + 1.0 - gap) / n as f32,
                (j as f32 + 1.0 - gap) / n as f32,
            );
            let b = pos.len() as u32;
            pos.extend([at(s0, t0), at(s1, t0), at(s1, t1), at(s0, t1)]);
            tris.push([b, b + 1, b + 2]);
            tris.push([b, b + 2, b + 3]);
        }
    }
}

/// A point far from the origin in a random direction.
fn far_point(g: &mut SplitMix64) -> Vec3 {
    Vec3::splat(0.5) + unit(g) * 20.0
}

/// The walls of a closed box, each a connected 4 × 4 tiling, in 3 × 3 × 3 grid cells: the
/// cells hold pieces of walls that meet at an edge or a corner (not flat, but one object), so
/// none is a medium and light from inside never gets out, where the model would let
/// `exp(−κℓ)` through every cell.
#[test]
fn closed_box_is_opaque_from_inside() {
    let (mut pos, mut tris) = (Vec::new(), Vec::new());
    let (o, x, y, z) = (Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::Z);
    for face in [
        (o, y, x),
        (z, x, y),
        (o, x, z),
        (y, z, x),
        (o, z, y),
        (x, y, z),
    ] {
        push_tiles(face, 4, 0.0, &mut pos, &mut tris);
    }
    let scene = scene_from(pos, tris);
    let region = Aabb::new(Vec3::ZERO, Vec3::ONE);
    let tree = grid_tree(&scene, region, [3, 3, 3]);
    let vc = VolumeCaster::new(&scene, &tree);
    let rc = RayCaster::new(&scene, &tree);
    let mut g = SplitMix64::new(11);
    for _ in 0..2000 {
        let p = Vec3::new(g.next_f32(), g.next_f32(), g.next_f32()) * 0.6 + Vec3::splat(0.2);
        let q = far_point(&mut g);
        assert!(rc.occluded(p, q - p, SPEC.0, SPEC.1));
        for ratio in [0.1f32, 0.5] {
            assert_eq!(
                vc.transmittance(p, q, ratio, Endpoint::None, Endpoint::None),
                0.0
            );
        }
    }
}

/// A tilted plane of 8 × 8 separate tiles with gaps in 4 × 4 × 4 grid cells: the tiles are
/// small objects, but each cell is flat, so segments crossing it far away are blocked exactly
/// where ray casting blocks them (the model would give every one `0 < τ < 1`).
#[test]
fn flat_clusters_are_exact() {
    let n = Vec3::new(1.0, 2.0, 3.0).normalize();
    let u = n.any_orthonormal_vector();
    let w = n.cross(u);
    let (mut pos, mut tris) = (Vec::new(), Vec::new());
    let o = Vec3::splat(0.5) - (u + w) * 0.5;
    push_tiles((o, u, w), 8, 0.15, &mut pos, &mut tris);
    let scene = scene_from(pos, tris);
    let region = scene.bbox;
    let tree = grid_tree(&scene, region, [4, 4, 4]);
    let vc = VolumeCaster::new(&scene, &tree);
    let rc = RayCaster::new(&scene, &tree);
    let mut g = SplitMix64::new(12);
    let (mut hit, mut miss) = (0, 0);
    for _ in 0..2000 {
        let c = o + u * (0.1 + 0.8 * g.next_f32()) + w * (0.1 + 0.8 * g.next_f32());
        let d = (n + unit(&mut g) * 0.5).normalize() * 20.0;
        let (p, q) = (c - d, c + d);
        let occ = rc.occluded(p, q - p, SPEC.0, SPEC.1);
        let tau = vc.transmittance(p, q, 0.5, Endpoint::None, Endpoint::None);
        assert_eq!(tau, if occ { 0.0 } else { 1.0 });
        if occ {
            hit += 1;
        } else {
            miss += 1;
        }
    }
    assert!(hit > 500 && miss > 300, "{hit} {miss}");
}
