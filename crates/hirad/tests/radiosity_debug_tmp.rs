use hirad::cluster::{ClusterConfig, ClusterTree, Strategy};
use hirad::progress::NoProgress;
use hirad::radiosity::{solve, SolverConfig, Oracle};
use hirad::scene::{Scene, SceneOptions};
#[test]
fn dbg() {
    let scene = Scene::load("furnace", &SceneOptions::default()).unwrap();
    for s in [Strategy::Kdt, Strategy::Sah] {
    let tree = ClusterTree::build(&scene, s, &ClusterConfig::default());
    for (o, e, ma) in [(Oracle::Bf, 0.0015, 1e-3), (Oracle::Bf, 0.0015, 4e-3), (Oracle::Bf, 0.001, 4e-3)] {
        let t = std::time::Instant::now();
        let cfg = SolverConfig { eps_rel: e, refine: o, min_area_rel: ma, ..SolverConfig::default() };
        let sol = solve(&scene, &tree, &cfg, &NoProgress).unwrap();
        let errs: Vec<f64> = sol.elements.roots().map(|r| (sol.elements.b[r as usize].x - 2.0).abs() / 2.0).collect();
        let mx = errs.iter().cloned().fold(0.0, f64::max);
        let mean = errs.iter().sum::<f64>() / errs.len() as f64;
        println!("{s}  {o:?} eps_rel {e} ma {ma}: max {:.2}% mean {:.2}% links {} ss {} cs {} cc {} cluster% {:.1} t {:.2}s", mx*100.0, mean*100.0, sol.stats.links, sol.stats.links_ss, sol.stats.links_cs, sol.stats.links_cc, sol.stats.cluster_energy_percent, t.elapsed().as_secs_f64());
    }
    }
}
