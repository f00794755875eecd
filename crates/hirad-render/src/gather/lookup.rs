//! The solution side of the final gather: a solution mesh matched to its scene
//! ([`SolutionLookup`]) and how a gather ray reads it ([`Lookup`]).

use crate::sample::surface_eps;
use glam::Vec3;
use hirad_accel::cluster::{ClusterConfig, ClusterTree, Strategy};
use hirad_accel::ray::RayCaster;
use hirad_core::{Error, Result};
use hirad_scene::export::ColoredMesh;
use hirad_scene::{Material, RawScene, Scene, SceneOptions};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// How a gather ray reads the solution at its hit.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub enum Lookup {
    /// Radiosity interpolated from the mesh's vertex values (as the per-vertex image).
    Vertex,
    /// The mean of the hit triangle's vertex values (the element constant; the default).
    #[default]
    Element,
}

impl Lookup {
    /// Parse `vertex` or `element`.
    pub fn parse(s: &str) -> Result<Lookup> {
        match s.trim().to_ascii_lowercase().as_str() {
            "vertex" => Ok(Lookup::Vertex),
            "element" => Ok(Lookup::Element),
            _ => Err(Error::Config(format!(
                "gather lookup: vertex or element, got '{s}'"
            ))),
        }
    }
}

/// Generic direction that splits the solution's triangles into two halves by the sign of
/// `normal · SPLIT`: two coinciding triangles facing opposite ways (the back-face copies of
/// two-sided solutions, or back-to-back surfaces) never share a half, so a look-up ray along a
/// normal finds the element facing it. No axis-aligned or common normal is perpendicular to it.
pub(super) const SPLIT: Vec3 = Vec3::new(0.267_261_24, 0.534_522_5, 0.801_783_7);

/// One half of the solution mesh, as a scene of its own with an accelerator.
pub(super) struct HalfMesh {
    pub(super) scene: Scene,
    pub(super) tree: ClusterTree,
    /// Per triangle: the radiosity at its three vertices.
    pub(super) colors: Vec<[Vec3; 3]>,
}

/// A solution mesh (leaf elements with per-vertex radiosity B, W/m²) matched to its scene and
/// prepared for look-ups by point.
///
/// [`SolutionLookup::new`] checks that the mesh's triangles lie on the scene's surfaces (one
/// short ray per triangle, which also tells a two-sided solution by its back-face copies) and
/// builds a ray accelerator over each half of it (split by the sign of the normal along a
/// generic direction, so that coinciding triangles facing opposite ways never share one). A
/// gather ray is cast against the scene (exact geometry and materials, as the path tracer's);
/// its hit point then finds its element by a short ray along the normal of the side it was hit
/// on, into the half of the mesh facing that way, and reads B interpolated from the vertices
/// (what the per-vertex image shows) or the triangle's mean ([`Lookup`]).
pub struct SolutionLookup {
    /// Triangles whose normal has a positive (index 0) or negative (1) component along
    /// [`SPLIT`].
    pub(super) halves: [Option<HalfMesh>; 2],
    /// Half length of the look-up rays (scene units).
    pub(super) delta: f32,
    /// Solution triangles on the front of a scene surface.
    pub front: usize,
    /// Solution triangles on the back of a scene surface only (back-face copies).
    pub back: usize,
    /// Solution triangles under which no scene surface was found.
    pub unmatched: usize,
    /// Solution triangles of zero area (left out).
    pub degenerate: usize,
}

impl SolutionLookup {
    /// Match the solution mesh `mesh` to `scene` (whose ray caster is `caster`) and build the
    /// look-up structures. Fails when most of the mesh lies on no surface of the scene (a
    /// solution of another scene).
    pub fn new(
        mesh: &ColoredMesh,
        scene: &Scene,
        caster: &RayCaster,
        lookup: Lookup,
    ) -> Result<Self> {
        let nv = mesh.positions.len();
        if mesh.colors.len() != nv {
            return Err(Error::Config(format!(
                "solution mesh has {} colours for {nv} vertices",
                mesh.colors.len()
            )));
        }
        if let Some(t) = mesh
            .triangles
            .iter()
            .find(|t| t.iter().any(|&v| v as usize >= nv))
        {
            return Err(Error::Config(format!(
                "solution triangle {t:?} uses a vertex out of range ({nv} vertices)"
            )));
        }
        let delta = 5.0 * surface_eps(scene);
        // Per triangle: 0 front of a scene surface, 1 back only, 2 degenerate, 3 on no surface.
        let class: Vec<u8> = mesh
            .triangles
            .par_iter()
            .map(|t| {
                let [a, b, c] = t.map(|v| mesh.positions[v as usize]);
                let cr = (b - a).cross(c - a);
                let area = 0.5 * cr.length();
                if area.is_nan() || area <= 0.0 || !cr.normalize_or_zero().is_normalized() {
                    return 2;
                }
                let n = cr.normalize();
                let centroid = (a + b + c) / 3.0;
                let facing_away = |tri: u32| scene.normals[tri as usize].dot(n) <= 0.0;
                for k in [1.0f32, 20.0] {
                    let o = centroid + n * (delta * k);
                    let span = (0.0, 2.0 * delta * k);
                    if caster.occluded_except(o, -n, span, &facing_away) {
                        return 0;
                    }
                    if caster.occluded(o, -n, span.0, span.1) {
                        return 1;
                    }
                }
                3
            })
            .collect();
        let count = |s: u8| class.iter().filter(|&&x| x == s).count();
        let (front, back, degenerate, unmatched) = (count(0), count(1), count(2), count(3));
        let good = mesh.triangles.len() - degenerate;
        if good == 0 || unmatched * 2 > good {
            return Err(Error::Config(format!(
                "the solution does not fit the scene: {unmatched} of {good} solution triangles \
                 lie on no surface of '{}'",
                scene.name
            )));
        }
        if unmatched > 0 {
            tracing::warn!(
                "gather: {unmatched} of {good} solution triangles lie on no surface of the scene"
            );
        }
        let mut halves: [Option<HalfMesh>; 2] = [None, None];
        for (h, slot) in halves.iter_mut().enumerate() {
            let triangles: Vec<[u32; 3]> = mesh
                .triangles
                .iter()
                .zip(&class)
                .filter(|&(t, &c)| {
                    if c == 2 {
                        return false;
                    }
                    let [a, b, c] = t.map(|v| mesh.positions[v as usize]);
                    ((b - a).cross(c - a).dot(SPLIT) > 0.0) == (h == 0)
                })
                .map(|(t, _)| *t)
                .collect();
            if triangles.is_empty() {
                continue;
            }
            let colors: Vec<[Vec3; 3]> = triangles
                .iter()
                .map(|t| {
                    let c = t.map(|v| mesh.colors[v as usize]);
                    match lookup {
                        Lookup::Vertex => c,
                        Lookup::Element => [(c[0] + c[1] + c[2]) / 3.0; 3],
                    }
                })
                .collect();
            let n = triangles.len();
            let raw = RawScene {
                name: format!("{} solution half {h}", scene.name),
                positions: mesh.positions.clone(),
                triangles,
                tri_material: vec![0; n],
                tri_object: vec![0; n],
                objects: Vec::new(),
                materials: vec![Material::diffuse("solution", Vec3::ZERO)],
                up: scene.up,
                ..Default::default()
            };
            let sub = Scene::from_raw(raw, &SceneOptions::default())?;
            if sub.num_triangles() != n {
                return Err(Error::Config(format!(
                    "solution half {h}: {} of {n} triangles kept",
                    sub.num_triangles()
                )));
            }
            let tree = ClusterTree::build(&sub, Strategy::Sah, &ClusterConfig::default());
            *slot = Some(HalfMesh {
                scene: sub,
                tree,
                colors,
            });
        }
        Ok(SolutionLookup {
            halves,
            delta,
            front,
            back,
            unmatched,
            degenerate,
        })
    }

    /// True when the solution has back-face elements (a two-sided solve): at least a quarter
    /// of its triangles lie on the back of a scene surface only. (A one-sided solve has such
    /// triangles only where the scene has back-to-back surfaces.)
    pub fn has_back_faces(&self) -> bool {
        self.back * 4 >= self.front + self.back
    }
}
