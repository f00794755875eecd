//! Helpers shared by the reference tests: a ray caster over a scene and the path-traced image of
//! a scene from its default camera, and the CIELUV error of a solution mesh against it (for the
//! solver-vs-reference test on the Cornell box: solve, export the `ColoredMesh`, call
//! [`solution_error`]).

#![allow(dead_code)]

use hirad::cluster::{ClusterConfig, ClusterTree, Strategy};
use hirad::metrics::{compare, ImageError};
use hirad::progress::NoProgress;
use hirad::ray::RayCaster;
use hirad::render::{
    render_reference, render_solution, CameraView, Image, RasterOptions, ReferenceOptions,
    ReferenceStats,
};
use hirad::scene::export::ColoredMesh;
use hirad::scene::{Scene, SceneOptions};

/// Load a scene (built-in name or path).
pub fn scene(name: &str) -> Scene {
    Scene::load(name, &SceneOptions::default()).unwrap()
}

/// The scene's default camera at `width × height`.
pub fn view(scene: &Scene, width: u32, height: u32) -> CameraView {
    let mut v = CameraView::from_camera(&scene.default_camera());
    v.width = width;
    v.height = height;
    v
}

/// Path-traced reference of `scene` seen from `view`.
pub fn reference(
    scene: &Scene,
    view: &CameraView,
    opts: &ReferenceOptions,
) -> (Image, ReferenceStats) {
    let tree = ClusterTree::build(scene, Strategy::Sah, &ClusterConfig::default());
    let caster = RayCaster::new(scene, &tree);
    render_reference(scene, &caster, view, opts, &NoProgress).unwrap()
}

/// Error of a radiosity solution (per-vertex B, drawn as B/π with 4×4 supersampling, close to
/// the path tracer's box-filtered pixels at the edges of the bright light) against a
/// path-traced reference image from the same view.
pub fn solution_error(mesh: &ColoredMesh, view: &CameraView, reference: &Image) -> ImageError {
    let opts = RasterOptions {
        supersample: 4,
        ..Default::default()
    };
    let img = render_solution(mesh, view, &opts).unwrap();
    compare(&img, reference).unwrap()
}
