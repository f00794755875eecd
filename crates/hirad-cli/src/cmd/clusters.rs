//! `hirad clusters SCENE`: build cluster hierarchies, time them and print their statistics
//! (`spec/clustering.md`); `--dump` writes the boxes as a wireframe, `--objects` the objects
//! `objr` recovers as a coloured mesh.

use crate::progress::Bars;
use crate::Global;
use hirad::cluster::dump::{self, Level};
use hirad::cluster::{ClusterConfig, ClusterStats, ClusterTree, Prims, Strategy};
use hirad::progress::Progress;
use hirad::Error;
use serde::Serialize;
use std::path::{Path, PathBuf};
use std::time::Instant;

#[derive(clap::Args, Debug)]
pub struct Args {
    /// Scene: a file path or a built-in name.
    pub scene: String,
    #[command(flatten)]
    pub load: super::info::LoadArgs,
    /// Strategies: `all` or a comma-separated list (kdt, obt, okdt, okdt-p, tf-oct, proxi, sah, objr).
    #[arg(long, default_value = "all")]
    pub clustering: String,
    /// OBT/OKDT/OKDT-P overlap parameter λ ≥ 0 (default 0.25).
    #[arg(long, allow_negative_numbers = true)]
    pub lambda: Option<f32>,
    /// OKDT-P: clusters with more surfaces attached directly are re-clustered (default 12).
    #[arg(long)]
    pub max_surfaces: Option<usize>,
    /// Benchmark: time `--repeat` builds (default 5) single-threaded and parallel, print JSON.
    #[arg(long)]
    pub bench: bool,
    /// Builds per strategy and mode; the median time is reported (default 5 with --bench,
    /// else 1).
    #[arg(long)]
    pub repeat: Option<usize>,
    /// Write the cluster boxes as a wireframe (.obj or .ply); with several strategies the
    /// strategy name is inserted before the extension [default: none].
    #[arg(long)]
    pub dump: Option<PathBuf>,
    /// Depth of the boxes to dump, or `all`.
    #[arg(long, default_value = "all")]
    pub level: String,
    /// Write the objects `objr` recovers as the scene's triangles coloured by object (.ply,
    /// .glb or .obj); `hirad render FILE --scene SCENE --image objects.png` draws them
    /// [default: none].
    #[arg(long)]
    pub objects: Option<PathBuf>,
}

/// One strategy's row of the report.
#[derive(Serialize, Debug)]
struct Row {
    #[serde(flatten)]
    stats: ClusterStats,
    /// Median single-threaded build time as a percentage of proxi's.
    #[serde(skip_serializing_if = "Option::is_none")]
    percent_of_proxi_single: Option<f64>,
    /// Median parallel build time as a percentage of proxi's.
    #[serde(skip_serializing_if = "Option::is_none")]
    percent_of_proxi_parallel: Option<f64>,
    /// Every timed single-threaded build, seconds.
    samples_single: Vec<f64>,
    /// Every timed parallel build, seconds.
    samples_parallel: Vec<f64>,
    /// Boxes written by `--dump`.
    #[serde(skip_serializing_if = "Option::is_none")]
    dump: Option<String>,
}

/// The whole report (`--json` / `--bench`).
#[derive(Serialize, Debug)]
struct Report {
    scene: String,
    triangles: usize,
    load_seconds: f64,
    /// Time to compute the builders' inputs (boxes, centroids), not part of build times.
    prims_seconds: f64,
    threads: usize,
    repeat: usize,
    config: ClusterConfig,
    strategies: Vec<Row>,
}

fn config_error(msg: String) -> anyhow::Error {
    Error::Config(msg).into()
}

fn median(v: &[f64]) -> f64 {
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    let n = s.len();
    if n == 0 {
        0.0
    } else if n % 2 == 1 {
        s[n / 2]
    } else {
        0.5 * (s[n / 2 - 1] + s[n / 2])
    }
}

/// `FILE` for one strategy, `stem.strategy.ext` when several are dumped.
fn dump_path(path: &Path, s: Strategy, several: bool) -> PathBuf {
    if !several {
        return path.to_path_buf();
    }
    let stem = path
        .file_stem()
        .and_then(|x| x.to_str())
        .unwrap_or("clusters");
    let ext = path.extension().and_then(|x| x.to_str()).unwrap_or("obj");
    path.with_file_name(format!("{stem}.{}.{ext}", s.name()))
}

pub fn run(args: Args, g: &Global) -> anyhow::Result<()> {
    let strategies = Strategy::parse_list(&args.clustering)?;
    let mut cfg = ClusterConfig::default();
    if let Some(l) = args.lambda {
        if !(l.is_finite() && l >= 0.0) {
            return Err(config_error(format!("--lambda must be >= 0, got {l}")));
        }
        cfg.lambda = l;
    }
    if let Some(m) = args.max_surfaces {
        if m == 0 {
            return Err(config_error("--max-surfaces must be >= 1".into()));
        }
        cfg.max_surfaces = m;
    }
    let repeat = args.repeat.unwrap_or(if args.bench { 5 } else { 1 });
    if repeat == 0 {
        return Err(config_error("--repeat must be >= 1".into()));
    }
    let level: Level = args.level.parse()?;
    if let Some(p) = &args.dump {
        dump::Format::of_path(p)?;
    }
    if let Some(p) = &args.objects {
        let ext = p
            .extension()
            .and_then(|e| e.to_str())
            .map(str::to_ascii_lowercase);
        if !matches!(ext.as_deref(), Some("ply" | "glb" | "obj")) {
            return Err(config_error(format!(
                "{}: --objects writes .ply, .glb or .obj",
                p.display()
            )));
        }
    }

    let scene = super::load_scene(&args.scene, &args.load.options())?;
    let t0 = Instant::now();
    let prims = Prims::from_scene(&scene);
    let prims_seconds = t0.elapsed().as_secs_f64();
    let single = rayon::ThreadPoolBuilder::new().num_threads(1).build()?;

    let bars = Bars::new(g.quiet);
    bars.start("clusters", (strategies.len() * repeat * 2) as u64);
    let mut rows = Vec::with_capacity(strategies.len());
    for &s in &strategies {
        bars.message(s.name());
        let time = |tree: &mut Option<ClusterTree>| {
            let t = Instant::now();
            let built = ClusterTree::build_prims(&prims, s, &cfg);
            let dt = t.elapsed().as_secs_f64();
            *tree = Some(built);
            dt
        };
        let mut tree = None;
        let mut samples_single = Vec::with_capacity(repeat);
        let mut samples_parallel = Vec::with_capacity(repeat);
        for _ in 0..repeat {
            samples_single.push(single.install(|| time(&mut tree)));
            bars.inc(1);
            samples_parallel.push(time(&mut tree));
            bars.inc(1);
        }
        let tree = tree.expect("repeat >= 1");
        if let Err(e) = tree.validate(&prims) {
            anyhow::bail!("{s}: invalid tree: {e}");
        }
        let mut stats = ClusterStats::compute(&tree, &prims);
        stats.build_seconds_single = Some(median(&samples_single));
        stats.build_seconds_parallel = Some(median(&samples_parallel));
        let dumped = match &args.dump {
            Some(p) => {
                let path = dump_path(p, s, strategies.len() > 1);
                let n = dump::write_boxes(&path, &tree, level)?;
                tracing::info!("{s}: wrote {n} boxes to {}", path.display());
                Some(format!("{} ({n} boxes)", path.display()))
            }
            None => None,
        };
        rows.push(Row {
            stats,
            percent_of_proxi_single: None,
            percent_of_proxi_parallel: None,
            samples_single,
            samples_parallel,
            dump: dumped,
        });
    }
    bars.finish();
    if let Some(p) = &args.objects {
        let rec = hirad::cluster::objr::reconstruct(&prims);
        let mesh = hirad::cluster::objr::object_mesh(&prims, &rec);
        hirad::scene::export::write_colored_mesh_up(p, &mesh, scene.up)?;
        tracing::info!(
            "wrote {} objects ({} triangles) to {}",
            rec.num_objects,
            mesh.triangles.len(),
            p.display()
        );
    }

    if let Some(p) = rows
        .iter()
        .position(|r| r.stats.strategy == Strategy::Proxi.name())
    {
        let ps = rows[p].stats.build_seconds_single.unwrap_or(0.0);
        let pp = rows[p].stats.build_seconds_parallel.unwrap_or(0.0);
        for r in &mut rows {
            let pct =
                |t: Option<f64>, base: f64| t.filter(|_| base > 0.0).map(|t| 100.0 * t / base);
            r.percent_of_proxi_single = pct(r.stats.build_seconds_single, ps);
            r.percent_of_proxi_parallel = pct(r.stats.build_seconds_parallel, pp);
        }
    }

    let report = Report {
        scene: args.scene.clone(),
        triangles: scene.num_triangles(),
        load_seconds: scene.report.load_seconds,
        prims_seconds,
        threads: rayon::current_num_threads(),
        repeat,
        config: cfg,
        strategies: rows,
    };
    if g.json || args.bench {
        return super::print_json(&report);
    }
    print_table(&report);
    Ok(())
}

fn print_table(r: &Report) {
    println!(
        "{}: {} triangles, {} thread(s), median of {} build(s)",
        r.scene, r.triangles, r.threads, r.repeat
    );
    println!(
        "{:<8} {:>9} {:>5} {:>6} {:>7} {:>6} {:>7} {:>6} {:>7} {:>9} {:>10} {:>7} {:>9} {:>9} {:>7}",
        "strategy",
        "clusters",
        "dmax",
        "dmean",
        "surf/c",
        "max",
        "child/c",
        "max",
        "branch",
        "overlap",
        "empty",
        "B/surf",
        "t1 ms",
        "tN ms",
        "%proxi"
    );
    for row in &r.strategies {
        let s = &row.stats;
        println!(
            "{:<8} {:>9} {:>5} {:>6.2} {:>7.2} {:>6} {:>7.2} {:>6} {:>7.2} {:>9.3} {:>10.3} {:>7.1} {:>9.1} {:>9.1} {:>7}",
            s.strategy,
            s.clusters,
            s.depth_max,
            s.depth_mean,
            s.surfaces_per_cluster_avg,
            s.surfaces_per_cluster_max,
            s.children_per_cluster_avg,
            s.children_per_cluster_max,
            s.branching_factor,
            s.overlap,
            s.empty_space_ratio,
            s.bytes_per_surface,
            1e3 * s.build_seconds_single.unwrap_or(0.0),
            1e3 * s.build_seconds_parallel.unwrap_or(0.0),
            row.percent_of_proxi_parallel
                .map(|p| format!("{p:.1}"))
                .unwrap_or_else(|| "-".into()),
        );
        for n in &s.notes {
            println!("         note: {n}");
        }
        if let Some(d) = &row.dump {
            println!("         dump: {d}");
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn median_and_dump_names() {
        assert_eq!(median(&[3.0, 1.0, 2.0]), 2.0);
        assert_eq!(median(&[4.0, 1.0, 3.0, 2.0]), 2.5);
        assert_eq!(median(&[]), 0.0);
        let p = Path::new("out/boxes.ply");
        assert_eq!(
            dump_path(p, Strategy::TfOct, false),
            PathBuf::from("out/boxes.ply")
        );
        assert_eq!(
            dump_path(p, Strategy::TfOct, true),
            PathBuf::from("out/boxes.tf-oct.ply")
        );
    }
}
