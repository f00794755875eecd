//! Per-vertex radiosity meshes of a solution and the result files of `hirad solve`.
//!
//! The mesh is the leaf-element mesh: one triangle per leaf surface element (back faces of
//! two-sided solutions are separate triangles with reversed winding), except leaves wholly
//! under a coplanar face that owns the place ([`Solution::under_face`]: a duplicated face
//! under its original): what shows there is that face, and a second, unlit face in the same
//! place would fight it in any viewer's depth test. Smooth output averages
//! the radiosity of the leaf elements meeting at a vertex, each weighted by its open share
//! (a leaf inside a solid or under a coplanar face does not darken its visible neighbours),
//! then fits the vertex values so that every leaf keeps its radiosity as its mean, drawing a
//! leaf around its centroid where the fit alone cannot (`keep_leaf_means`); vertices are
//! shared between leaves of the same face side, material and plane orientation (normals
//! equal to 1e-3), so creases and material boundaries stay sharp. `flat` gives every leaf its
//! own three vertices (discontinuous, per-element colour). Colours are radiosity B (W/m²).

use super::solver::Solution;
use glam::{DVec3, Vec3};
use hirad_core::Result;
use hirad_scene::export::{write_colored_mesh_up, ColoredMesh};
use hirad_scene::Scene;
use std::collections::HashMap;
use std::path::{Path, PathBuf};

/// The leaf-element mesh with per-vertex radiosity.
pub fn radiosity_mesh(sol: &Solution, scene: &Scene, flat: bool) -> ColoredMesh {
    leaf_mesh(sol, scene, flat).0
}

/// [`radiosity_mesh`] and, per mesh triangle, its leaf element.
fn leaf_mesh(sol: &Solution, scene: &Scene, flat: bool) -> (ColoredMesh, Vec<u32>) {
    let el = &sol.elements;
    let leaves: Vec<u32> = sol
        .leaves()
        .into_iter()
        .filter(|id| sol.under_face.binary_search(id).is_err())
        .collect();
    let mut mesh = ColoredMesh::default();
    // Per vertex: Σ w·B, Σ w (open shares), Σ B and the count (when every leaf is shut).
    let mut sums: Vec<(DVec3, f64, DVec3, u32)> = Vec::new();
    let mut index: HashMap<([u32; 3], u32, bool, [i32; 3]), u32> = HashMap::new();
    for &id in &leaves {
        let e = &el.elems[id as usize];
        let b = el.b[id as usize];
        let mat = scene.tri_material[e.tri as usize];
        let nq = (e.normal * 1000.0).round().as_ivec3().to_array();
        let mut tri = [0u32; 3];
        for (k, &p) in e.verts.iter().enumerate() {
            let v = if flat {
                mesh.positions.push(p);
                sums.push(Default::default());
                (mesh.positions.len() - 1) as u32
            } else {
                let key = (p.to_array().map(f32::to_bits), mat, e.back, nq);
                *index.entry(key).or_insert_with(|| {
                    mesh.positions.push(p);
                    sums.push(Default::default());
                    (mesh.positions.len() - 1) as u32
                })
            };
            let w = el.open[id as usize] as f64;
            let s = &mut sums[v as usize];
            s.0 += b * w;
            s.1 += w;
            s.2 += b;
            s.3 += 1;
            tri[k] = v;
        }
        mesh.triangles.push(tri);
    }
    mesh.colors = sums
        .into_iter()
        .map(|(sw, w, s, n)| {
            if w > 1e-6 {
                (sw / w).as_vec3()
            } else {
                (s / n.max(1) as f64).as_vec3()
            }
        })
        .collect();
    let mut leaf_of = leaves.clone();
    if !flat {
        keep_leaf_means(&mut mesh, &mut leaf_of, &leaves, el);
    }
    (mesh, leaf_of)
}

/// Makes the smooth mesh keep each leaf's radiosity as its mean (the mean of a linear
/// interpolant over a triangle is that of its vertex values). Vertex averages alone spread
/// a leaf's neighbours over it: a lit leaf beside shadowed or hidden ones is drawn too dark
/// over its whole area, which on coarse meshes darkens what the camera sees. First
/// [`FIT_SWEEPS`] Jacobi sweeps move each vertex by the open-area-weighted mean residual
/// `B − v̄` of its leaves (a least-squares fit, values kept ≥ 0); then a leaf still more than
/// [`MEAN_TOL`] off is drawn as three triangles around its centroid, whose value `3B − 2·v̄`
/// makes its mean exact (clamped at 0, so a leaf can stay brighter, never darker).
fn keep_leaf_means(
    mesh: &mut ColoredMesh,
    leaf_of: &mut Vec<u32>,
    leaves: &[u32],
    el: &super::element::Elements,
) {
    let mut split = 0usize;
    // Fit weights: each leaf's open area.
    let w: Vec<f32> = leaves
        .iter()
        .enumerate()
        .map(|(t, &id)| triangle_area(mesh, mesh.triangles[t]) * el.open[id as usize])
        .collect();
    for _ in 0..FIT_SWEEPS {
        let mut acc = vec![(Vec3::ZERO, 0.0f32); mesh.colors.len()];
        for (t, &id) in leaves.iter().enumerate() {
            let tri = mesh.triangles[t];
            let r = el.b[id as usize].as_vec3() - vertex_mean(mesh, tri);
            for v in tri {
                acc[v as usize].0 += r * w[t];
                acc[v as usize].1 += w[t];
            }
        }
        for (c, (r, a)) in mesh.colors.iter_mut().zip(acc) {
            if a > 0.0 {
                *c = (*c + r / a).max(Vec3::ZERO);
            }
        }
    }
    for (t, &id) in leaves.iter().enumerate() {
        let tri = mesh.triangles[t];
        let b = el.b[id as usize].as_vec3();
        let vm = vertex_mean(mesh, tri);
        let scale = b.max_element().max(vm.max_element());
        if (vm - b).abs().max_element() <= MEAN_TOL * scale {
            continue;
        }
        let c = (3.0 * b - 2.0 * vm).max(Vec3::ZERO);
        let p = tri.map(|v| mesh.positions[v as usize]).iter().sum::<Vec3>() / 3.0;
        let ci = mesh.positions.len() as u32;
        mesh.positions.push(p);
        mesh.colors.push(c);
        mesh.triangles[t] = [tri[0], tri[1], ci];
        mesh.triangles.push([tri[1], tri[2], ci]);
        mesh.triangles.push([tri[2], tri[0], ci]);
        leaf_of.extend([id; 2]);
        split += 1;
    }
    tracing::debug!(
        "radiosity mesh: {split} of {} leaves drawn around their centroid to keep their mean",
        leaves.len()
    );
}

/// Mean of the vertex values of `tri`: the mean of their linear interpolant over it.
fn vertex_mean(mesh: &ColoredMesh, tri: [u32; 3]) -> Vec3 {
    tri.map(|v| mesh.colors[v as usize]).iter().sum::<Vec3>() / 3.0
}

fn triangle_area(mesh: &ColoredMesh, tri: [u32; 3]) -> f32 {
    let p = tri.map(|v| mesh.positions[v as usize]);
    0.5 * (p[1] - p[0]).cross(p[2] - p[0]).length()
}

/// Jacobi sweeps of the least-squares fit of the vertex values to the leaves' means.
const FIT_SWEEPS: usize = 10;

/// Relative tolerance on a leaf's mean in the smooth mesh (see [`keep_leaf_means`]).
const MEAN_TOL: f32 = 0.01;

/// Per-input-triangle radiosity (front faces), the coarse view of a solution.
pub fn triangle_radiosity(sol: &Solution) -> Vec<Vec3> {
    (0..sol.elements.num_tris)
        .map(|t| sol.triangle_radiosity(t, false).as_vec3())
        .collect()
}

/// Files written by [`write_outputs`].
#[derive(Clone, Debug, serde::Serialize)]
pub struct OutputFiles {
    /// The radiosity mesh as glTF (`solution.glb`).
    pub glb: PathBuf,
    /// The radiosity mesh as PLY with vertex colours (`solution.ply`).
    pub ply: PathBuf,
    /// The statistics (`stats.json`).
    pub stats: PathBuf,
    /// Images of the solution written by the caller (renderer), if any.
    pub images: Vec<PathBuf>,
}

/// Write `solution.glb`, `solution.ply` and `stats.json` into `dir`, atomically (the `.glb` of
/// a Z-up scene turned to glTF's +Y up by a root node, its mesh in the scene's coordinates).
pub fn write_outputs(sol: &Solution, scene: &Scene, dir: &Path, flat: bool) -> Result<OutputFiles> {
    let mesh = radiosity_mesh(sol, scene, flat);
    let files = OutputFiles {
        glb: dir.join("solution.glb"),
        ply: dir.join("solution.ply"),
        stats: dir.join("stats.json"),
        images: Vec::new(),
    };
    write_colored_mesh_up(&files.glb, &mesh, scene.up)?;
    write_colored_mesh_up(&files.ply, &mesh, scene.up)?;
    // The process peak so far includes the mesh files.
    let mut stats = sol.stats.clone();
    stats.memory.vm_hwm_bytes = crate::stats::vm_hwm_bytes().or(stats.memory.vm_hwm_bytes);
    hirad_core::io::write_json_atomic(&files.stats, &stats)?;
    Ok(files)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{solve, SolverConfig};
    use hirad_accel::cluster::{ClusterConfig, ClusterTree, Strategy};
    use hirad_core::progress::NoProgress;
    use hirad_scene::SceneOptions;

    /// The smooth mesh draws every leaf with its own radiosity as the mean over its area: the
    /// linear interpolant's mean over a triangle is the mean of its vertex values, summed over
    /// the leaf's triangles by area (plain vertex averages fail it).
    #[test]
    fn smooth_mesh_keeps_every_leaf_mean() {
        let scene = Scene::load("office", &SceneOptions::default()).unwrap();
        let tree = ClusterTree::build(&scene, Strategy::Proxi, &ClusterConfig::default());
        let cfg = SolverConfig::preset("fast").unwrap();
        let sol = solve(&scene, &tree, &cfg, &NoProgress).unwrap();
        let (mesh, leaf_of) = leaf_mesh(&sol, &scene, false);
        let mut acc: HashMap<u32, (DVec3, f64)> = HashMap::new();
        for (&tri, &l) in mesh.triangles.iter().zip(&leaf_of) {
            let a = triangle_area(&mesh, tri) as f64;
            let m = vertex_mean(&mesh, tri).as_dvec3();
            let e = acc.entry(l).or_default();
            e.0 += m * a;
            e.1 += a;
        }
        // Every leaf is drawn but those under another face.
        let leaves = sol.leaves();
        let drawn = |id: u32| sol.under_face.binary_search(&id).is_err();
        assert!(leaves.iter().all(|&id| acc.contains_key(&id) == drawn(id)));
        let (mut err, mut total, mut darker) = (0.0f64, 0.0f64, 0usize);
        for (&id, &(s, a)) in &acc {
            let b = sol.elements.b[id as usize];
            let mean = s / a.max(1e-300);
            let scale = b.max_element().max(mean.max_element());
            // Darker than the leaf only by rounding; brighter only where the centroid value
            // was clamped at zero.
            darker += ((b - mean).max_element() > 1.01 * MEAN_TOL as f64 * scale) as usize;
            let open = a * sol.elements.open[id as usize] as f64;
            err += (mean - b).abs().element_sum() * open;
            total += b.element_sum() * open;
        }
        assert_eq!(darker, 0, "leaves drawn darker than their radiosity");
        assert!(
            err < 2e-3 * total,
            "mean error {:.2e} of Σ A·B",
            err / total
        );
    }
}
