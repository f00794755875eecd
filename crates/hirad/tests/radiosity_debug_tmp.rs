mod radiosity_common;
use hirad::progress::NoProgress;
use hirad::radiosity::{solve, SolverConfig, VisibilityMode};
use hirad::scene::{Scene, SceneOptions};
use radiosity_common::*;
use std::collections::HashMap;
#[test]
fn dbg() {
    let scene = Scene::load("furnace:2", &SceneOptions::default()).unwrap();
    let tree = tree_by_object(&scene);
    let cfg = SolverConfig { eps: Some(1e-6), min_area: Some(1.0), shadow_rays: 64, visibility: VisibilityMode::None, tol_converge: 1e-7, max_iters: 3, ..SolverConfig::default() };
    let sol = solve(&scene, &tree, &cfg, &NoProgress).unwrap();
    let el = &sol.elements;
    let mut m = HashMap::new();
    for l in &sol.links.links { m.insert((l.recv, l.src), l.k as f64); }
    let mut worst = (0.0, 0, 0);
    let mut col = vec![0.0; el.len()]; let mut row = vec![0.0; el.len()];
    for (&(i, j), &k) in &m {
        let ai = el.elems[i as usize].area as f64; let aj = el.elems[j as usize].area as f64;
        col[j as usize] += ai * k / aj; row[i as usize] += k;
        let kb = m.get(&(j, i)).copied().unwrap_or(-1.0);
        let d = (ai * k - aj * kb).abs() / (ai * k);
        if d > worst.0 { worst = (d, i, j); }
    }
    println!("worst recip {:?} k {:?} kb {:?}", worst, m[&(worst.1, worst.2)], m.get(&(worst.2, worst.1)));
    let r: Vec<u32> = el.roots().collect();
    println!("rows {:?}", r.iter().take(6).map(|&i| row[i as usize]).collect::<Vec<_>>());
    println!("cols {:?}", r.iter().take(6).map(|&i| col[i as usize]).collect::<Vec<_>>());
    let e = &el.elems[worst.1 as usize]; let f = &el.elems[worst.2 as usize];
    println!("{:?} {:?}\n{:?} {:?}", e.verts, e.normal, f.verts, f.normal);
}
