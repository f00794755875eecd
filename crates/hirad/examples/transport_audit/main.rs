//! Where a solution's light goes wrong, measured against brute force on the same scene.
//!
//! `cargo run --release -p hirad --example transport_audit -- SCENE [MODE] [options]` solves
//! SCENE, then compares the solution with an independent estimate, by MODE: `irradiance`
//! (path tracer, per object), `self` (one gather on the solution's own radiosity), `image`
//! (the camera's view), `leaves`, `leaf`, `links`, `objlinks` (per leaf and per link against
//! brute force), `shut`, `shutcheck` (light emitted into solids) and `coverage` (pairs of
//! points carried by no link or by several). Modes and flags: docs/transport-audit.md.
mod coverage;
mod elements;
mod estimate;
mod image;
mod irradiance;
mod leaf;
mod leaves;
mod links;
mod opts;
mod shut;
mod table;

use hirad::cluster::{ClusterConfig, ClusterTree, Strategy};
use hirad::progress::NoProgress;
use hirad::radiosity::solve;
use hirad::ray::RayCaster;
use hirad::scene::{Scene, SceneOptions};

fn main() {
    let o = opts::parse();
    let scene = Scene::load(&o.scene, &SceneOptions::default()).expect("scene");
    let strategy = Strategy::parse(&o.clustering).expect("clustering");
    let tree = ClusterTree::build(&scene, strategy, &ClusterConfig::default());
    let cfg = o.solver_config();
    if o.mode == "shutcheck" {
        return shut::shut_check(&o, &scene, &tree, &RayCaster::new(&scene, &tree));
    }
    let t = std::time::Instant::now();
    let sol = solve(&scene, &tree, &cfg, &NoProgress).expect("solve");
    let p = &sol.stats.power;
    println!(
        "solve {:.1} s; emitted {:.2} W, emitted − absorbed {:.2} W (channel sums)",
        t.elapsed().as_secs_f64(),
        p.emitted,
        p.escaping
    );
    let caster = RayCaster::new(&scene, &tree);
    match o.mode.as_str() {
        "irradiance" => irradiance::irradiance(&o, &scene, &tree, &caster, &sol),
        "self" => irradiance::self_consistency(&o, &scene, &tree, &caster, &sol),
        "links" => links::links(&o, &scene, &tree, &caster, &sol),
        "image" => image::image(&o, &scene, &caster, &sol),
        "leaves" => leaves::leaves(&o, &scene, &tree, &caster, &sol),
        "shut" => shut::shut(&o, &scene, &tree, &caster, &sol),
        "leaf" => leaf::leaf_links(&o, &scene, &tree, &caster, &sol),
        "objlinks" => leaf::object_links(&o, &scene, &tree, &caster, &sol),
        "coverage" => coverage::coverage(&o, &scene, &tree, &caster, &sol),
        m => panic!("unknown mode {m}"),
    }
}
