//! Per-vertex radiosity meshes of a solution and the result files of `hirad solve`.
//!
//! The mesh is the leaf-element mesh: one triangle per leaf surface element (back faces of
//! two-sided solutions are separate triangles with reversed winding). Smooth output averages
//! the radiosity of the leaf elements meeting at a vertex, each weighted by its open share
//! (a leaf inside a solid or under a coplanar face does not darken its visible neighbours);
//! vertices are shared between leaves
//! of the same face side, material and plane orientation (normals equal to 1e-3), so creases
//! and material boundaries stay sharp. `flat` gives every leaf its own three vertices
//! (discontinuous, per-element colour). Colours are radiosity B (W/m²).

use super::solver::Solution;
use crate::scene::export::{write_colored_mesh, ColoredMesh};
use crate::scene::Scene;
use crate::Result;
use glam::{DVec3, Vec3};
use std::collections::HashMap;
use std::path::{Path, PathBuf};

/// The leaf-element mesh with per-vertex radiosity.
pub fn radiosity_mesh(sol: &Solution, scene: &Scene, flat: bool) -> ColoredMesh {
    let leaves = sol.leaves();
    let el = &sol.elements;
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
    mesh
}

/// Per-input-triangle radiosity (front faces), the coarse view of a solution.
pub fn triangle_radiosity(sol: &Solution) -> Vec<Vec3> {
    (0..sol.elements.num_tris)
        .map(|t| sol.triangle_radiosity(t, false).as_vec3())
        .collect()
}

/// Files written by [`write_outputs`].
#[derive(Clone, Debug, serde::Serialize)]
pub struct OutputFiles {
    pub glb: PathBuf,
    pub ply: PathBuf,
    pub stats: PathBuf,
    /// Images of the solution written by the caller (renderer), if any.
    pub images: Vec<PathBuf>,
}

/// Write `solution.glb`, `solution.ply` and `stats.json` into `dir`, atomically.
pub fn write_outputs(sol: &Solution, scene: &Scene, dir: &Path, flat: bool) -> Result<OutputFiles> {
    let mesh = radiosity_mesh(sol, scene, flat);
    let files = OutputFiles {
        glb: dir.join("solution.glb"),
        ply: dir.join("solution.ply"),
        stats: dir.join("stats.json"),
        images: Vec::new(),
    };
    write_colored_mesh(&files.glb, &mesh)?;
    write_colored_mesh(&files.ply, &mesh)?;
    crate::io::write_json_atomic(&files.stats, &sol.stats)?;
    Ok(files)
}
