//! `hirad raybench`: the paper's ray-casting test (`experiments.md` §2). Random segments between
//! surface points are cast through each strategy's `ClusterTree`; prints build time, query time,
//! Mrays/s, occluded count, speed relative to `sah`, and mean nodes visited / triangle tests per
//! ray (counted in a separate pass, so the timed pass runs the uninstrumented code). The
//! strategies take turns during the timed passes, so that their ratios hold while the
//! machine's speed drifts.

use crate::Global;
use hirad::cluster::{ClusterConfig, ClusterTree, Strategy};
use hirad::progress::Progress;
use hirad::ray::embree::EmbreeCaster;
use hirad::ray::turns::TurnCaster;
use hirad::ray::{sample, turns, Boxes, RayCaster, RayStats};
use hirad::scene::SceneOptions;
use serde::Serialize;
use std::time::Instant;

#[derive(clap::Args, Debug)]
pub struct Args {
    /// Scene: a file path or a built-in name.
    pub scene: String,
    /// Strategies: comma-separated names or `all`.
    #[arg(long, default_value = "all")]
    pub clustering: String,
    /// Number of random segments.
    #[arg(long, default_value_t = 100_000)]
    pub pairs: usize,
    /// Seed of the SplitMix64 segment sampler.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Also time closest-hit queries with the same segments.
    #[arg(long)]
    pub closest: bool,
    /// Timed passes over the segments (the mean is reported). All strategies are built first
    /// and take turns every 16,384 segments within a pass (each turn after 1,024 untimed
    /// ones), so that the machine's speed drift weighs on each alike.
    #[arg(long, default_value_t = 3)]
    pub repeat: usize,
    /// Also count occluded segments by brute force (every triangle per segment; small scenes).
    #[arg(long)]
    pub brute: bool,
    /// Boxes the traversal tests: tight (every node's box shrunk to what lies below it, a
    /// node with one child and no triangles passed through, the triangles attached to an
    /// inner node behind a box of their own, long runs of them split into pieces behind
    /// boxes of their own, and inner children pulled up into their parent's lanes, up to
    /// eight), nodes (the tree's own nodes, runs not split) or cluster (the
    /// strategy's own boxes, e.g. the k-d cells of kdt/obt, and every node visited, its
    /// triangles tested whenever it is). Each triangle belongs to its node's box; same results.
    #[arg(long, default_value = "tight")]
    pub boxes: String,
    /// Also write the triangles and segments to FILE, for casting the same segments with
    /// another program (little-endian: u32 triangle count, 9 f32 per triangle in scene order,
    /// u32 segment count, 8 f32 per segment: origin, direction, tmin, tmax) [default: none]
    #[arg(long, value_name = "FILE")]
    pub export: Option<std::path::PathBuf>,
    /// Cast the segments of FILE (the format of `--export`, e.g. the shadow rays written by
    /// `hirad solve --export-rays`) instead of random ones; its triangles must be the
    /// scene's. `--pairs` and `--seed` are then ignored [default: none]
    #[arg(long, value_name = "FILE", conflicts_with = "export")]
    pub segments: Option<std::path::PathBuf>,
    /// Also time Embree 3 on the same segments, in turns with the strategies, for scale: its
    /// default build (`embree`) and its robust mode (`embree-robust`). Batch is
    /// `rtcOccluded1M` (streams of 256 flagged incoherent), single `rtcOccluded1`, closest
    /// `rtcIntersect1`. The library is loaded at run time (`libembree3.so.3`; Debian, Ubuntu:
    /// `apt-get install libembree3-3`).
    #[arg(long)]
    pub embree: bool,
}

/// Result of one strategy.
#[derive(Debug, Serialize)]
struct Row {
    strategy: String,
    clusters: usize,
    build_ms: f64,
    layout_ms: f64,
    query_ms: f64,
    /// Batch occlusion (`count_occluded`: several rays in flight per thread).
    mrays_per_s: f64,
    /// One query at a time (`occluded` per segment, as the solver casts its rays).
    single_mrays_per_s: f64,
    occluded: u64,
    /// Rays per second relative to `sah` (when `sah` is in the list).
    rel_sah: Option<f64>,
    nodes_per_ray: f64,
    boxes_per_ray: f64,
    tris_per_ray: f64,
    closest: Option<ClosestRow>,
}

/// Result of Embree, timed in turns with the strategies.
#[derive(Debug, Serialize)]
struct EmbreeRow {
    /// `embree` or `embree-robust`.
    name: String,
    build_ms: f64,
    query_ms: f64,
    mrays_per_s: f64,
    single_mrays_per_s: f64,
    /// Batch count (Embree's default test is not watertight: it may differ from ours by a
    /// few segments that graze an edge or lie in a triangle's plane).
    occluded: u64,
    single_occluded: u64,
    /// `sah`'s batch and single rates over these (when `sah` is in the list).
    sah_batch_ratio: Option<f64>,
    sah_single_ratio: Option<f64>,
    closest_mrays_per_s: Option<f64>,
}

#[derive(Debug, Serialize)]
struct ClosestRow {
    query_ms: f64,
    mrays_per_s: f64,
    hits: u64,
    rel_sah: Option<f64>,
    nodes_per_ray: f64,
    tris_per_ray: f64,
}

#[derive(Debug, Serialize)]
struct Report {
    scene: String,
    triangles: usize,
    pairs: usize,
    /// Seed of the random segments (unused with `segments`).
    seed: u64,
    /// File the segments were read from (`--segments`), if any.
    segments: Option<std::path::PathBuf>,
    boxes: Boxes,
    threads: usize,
    hirad_version: &'static str,
    sample_ms: f64,
    brute_occluded: Option<u64>,
    counts_agree: bool,
    rows: Vec<Row>,
    /// With `--embree`.
    embree: Vec<EmbreeRow>,
}

pub fn run(args: Args, g: &Global) -> anyhow::Result<()> {
    let strategies = Strategy::parse_list(&args.clustering)?;
    if args.pairs == 0 {
        return Err(hirad::Error::Config("--pairs must be at least 1".into()).into());
    }
    let repeat = args.repeat.max(1);
    let boxes = Boxes::parse(&args.boxes)?;
    let scene = super::load_scene(&args.scene, &SceneOptions::default())?;
    let t0 = Instant::now();
    let segs = match &args.segments {
        Some(p) => {
            let segs = sample::import_segments(p, &scene)?;
            if segs.is_empty() {
                return Err(hirad::Error::input(p, "no segments").into());
            }
            segs
        }
        None => sample::sample_segments(&scene, args.pairs, args.seed),
    };
    let sample_ms = t0.elapsed().as_secs_f64() * 1e3;
    if let Some(p) = &args.export {
        sample::export_segments(p, &scene, &segs)?;
    }
    let cfg = ClusterConfig::default();
    let bars = crate::progress::Bars::new(g.quiet || g.json);
    bars.start(
        "raybench",
        (2 * strategies.len() + repeat * segs.len().div_ceil(turns::TURN)) as u64,
    );
    // Every strategy's tree and layout first, all held at once, so that the timed passes can
    // take turns between them.
    let mut trees = Vec::with_capacity(strategies.len());
    for &st in &strategies {
        bars.message(&format!("building {st}"));
        let t0 = Instant::now();
        let tree = ClusterTree::build(&scene, st, &cfg);
        trees.push((tree, t0.elapsed().as_secs_f64() * 1e3));
        bars.inc(1);
    }
    let mut casters = Vec::with_capacity(strategies.len());
    for (st, (tree, _)) in strategies.iter().zip(&trees) {
        bars.message(&format!("laying out {st}"));
        let t0 = Instant::now();
        let rc = RayCaster::with_boxes(&scene, tree, boxes);
        casters.push((rc, t0.elapsed().as_secs_f64() * 1e3));
        bars.inc(1);
    }
    let embree = if args.embree {
        bars.message("building Embree");
        vec![
            EmbreeCaster::new(&scene, false)?,
            EmbreeCaster::new(&scene, true)?,
        ]
    } else {
        Vec::new()
    };
    bars.message("casting");
    let list: Vec<&dyn TurnCaster> = casters
        .iter()
        .map(|(rc, _)| rc as &dyn TurnCaster)
        .chain(embree.iter().map(|e| e as &dyn TurnCaster))
        .collect();
    let times = turns::time_in_turns(&list, &segs, repeat, args.closest, || bars.inc(1));
    let ms = |s: f64| s * 1e3 / repeat as f64;
    let rate = |s: f64| segs.len() as f64 / (ms(s) * 1e3);
    for (k, st) in strategies.iter().enumerate() {
        let (b, s) = (times.batch_occluded[k], times.single_occluded[k]);
        if b != s {
            return Err(anyhow::anyhow!(
                "{st}: single-ray occluded count {s} differs from the batch count {b}"
            ));
        }
    }
    let mut rows = Vec::new();
    let mut brute_occluded = None;
    for (k, ((rc, layout_ms), (tree, build_ms))) in casters.iter().zip(&trees).enumerate() {
        let st = strategies[k];
        let (query_ms, single_ms) = (ms(times.batch_s[k]), ms(times.single_s[k]));
        let occluded = times.batch_occluded[k];
        let (occ2, stats): (u64, RayStats) = rc.occluded_batch_stats(&segs);
        debug_assert_eq!(occ2, occluded);
        let closest = if args.closest {
            let q = ms(times.closest_s[k]);
            let (hits, cs) = rc.closest_batch_stats(&segs);
            Some(ClosestRow {
                query_ms: q,
                mrays_per_s: segs.len() as f64 / (q * 1e3),
                hits,
                rel_sah: None,
                nodes_per_ray: cs.nodes_per_ray(),
                tris_per_ray: cs.tris_per_ray(),
            })
        } else {
            None
        };
        if args.brute && brute_occluded.is_none() {
            use rayon::prelude::*;
            brute_occluded = Some(
                segs.par_iter()
                    .filter(|s| rc.occluded_brute(s.origin, s.dir, s.tmin, s.tmax))
                    .count() as u64,
            );
        }
        rows.push(Row {
            strategy: st.name().to_string(),
            clusters: tree.nodes.len(),
            build_ms: *build_ms,
            layout_ms: *layout_ms,
            query_ms,
            mrays_per_s: segs.len() as f64 / (query_ms * 1e3),
            single_mrays_per_s: segs.len() as f64 / (single_ms * 1e3),
            occluded,
            rel_sah: None,
            nodes_per_ray: stats.nodes_per_ray(),
            boxes_per_ray: stats.boxes_per_ray(),
            tris_per_ray: stats.tris_per_ray(),
            closest,
        });
    }
    bars.finish();
    let sah = rows.iter().find(|r| r.strategy == "sah");
    let embree: Vec<EmbreeRow> = embree
        .iter()
        .enumerate()
        .map(|(j, e)| {
            let k = strategies.len() + j;
            let (batch, single) = (rate(times.batch_s[k]), rate(times.single_s[k]));
            EmbreeRow {
                name: if e.robust { "embree-robust" } else { "embree" }.into(),
                build_ms: e.build_s * 1e3,
                query_ms: ms(times.batch_s[k]),
                mrays_per_s: batch,
                single_mrays_per_s: single,
                occluded: times.batch_occluded[k],
                single_occluded: times.single_occluded[k],
                sah_batch_ratio: sah.map(|r| r.mrays_per_s / batch),
                sah_single_ratio: sah.map(|r| r.single_mrays_per_s / single),
                closest_mrays_per_s: args.closest.then(|| rate(times.closest_s[k])),
            }
        })
        .collect();
    if let Some(sah) = rows.iter().position(|r| r.strategy == "sah") {
        let base = rows[sah].mrays_per_s;
        let cbase = rows[sah].closest.as_ref().map(|c| c.mrays_per_s);
        for r in &mut rows {
            r.rel_sah = Some(r.mrays_per_s / base);
            if let (Some(c), Some(cb)) = (r.closest.as_mut(), cbase) {
                c.rel_sah = Some(c.mrays_per_s / cb);
            }
        }
    }
    let first = rows.first().map(|r| r.occluded);
    let mut counts_agree = rows.iter().all(|r| Some(r.occluded) == first);
    if let Some(b) = brute_occluded {
        counts_agree &= first == Some(b);
    }
    if !counts_agree {
        let list: Vec<String> = rows
            .iter()
            .map(|r| format!("{}={}", r.strategy, r.occluded))
            .chain(brute_occluded.map(|b| format!("brute={b}")))
            .collect();
        eprintln!(
            "warning: occluded counts differ between strategies: {}",
            list.join(", ")
        );
    }
    let report = Report {
        scene: scene.name.clone(),
        triangles: scene.num_triangles(),
        pairs: segs.len(),
        seed: args.seed,
        segments: args.segments.clone(),
        boxes,
        threads: rayon::current_num_threads(),
        hirad_version: hirad::VERSION,
        sample_ms,
        brute_occluded,
        counts_agree,
        rows,
        embree,
    };
    if g.json {
        return super::print_json(&report);
    }
    print_table(&report);
    Ok(())
}

fn opt(x: Option<f64>, prec: usize) -> String {
    x.map(|v| format!("{v:.prec$}"))
        .unwrap_or_else(|| "-".into())
}

fn print_table(r: &Report) {
    let source = match &r.segments {
        Some(f) => format!("{} segments from {}", r.pairs, f.display()),
        None => format!("{} pairs, seed {}", r.pairs, r.seed),
    };
    println!(
        "scene {} ({} triangles), {source}, {} boxes, {} thread(s), sampling {:.1} ms",
        r.scene,
        r.triangles,
        r.boxes.name(),
        r.threads,
        r.sample_ms
    );
    if let Some(b) = r.brute_occluded {
        println!("brute-force occluded: {b}");
    }
    println!(
        "{:<13} {:>9} {:>10} {:>9} {:>10} {:>8} {:>8} {:>9} {:>7} {:>8} {:>8} {:>8}",
        "strategy",
        "clusters",
        "build ms",
        "layout ms",
        "query ms",
        "Mrays/s",
        "single",
        "occluded",
        "vs sah",
        "nodes/ray",
        "boxes/ray",
        "tris/ray"
    );
    for x in &r.rows {
        println!(
            "{:<13} {:>9} {:>10.1} {:>9.1} {:>10.1} {:>8.3} {:>8.3} {:>9} {:>7} {:>8.1} {:>8.1} {:>8.1}",
            x.strategy,
            x.clusters,
            x.build_ms,
            x.layout_ms,
            x.query_ms,
            x.mrays_per_s,
            x.single_mrays_per_s,
            x.occluded,
            opt(x.rel_sah, 2),
            x.nodes_per_ray,
            x.boxes_per_ray,
            x.tris_per_ray
        );
    }
    for e in &r.embree {
        println!(
            "{:<13} {:>9} {:>10.1} {:>9} {:>10.1} {:>8.3} {:>8.3} {:>9} {:>7}",
            e.name,
            "-",
            e.build_ms,
            "-",
            e.query_ms,
            e.mrays_per_s,
            e.single_mrays_per_s,
            e.occluded,
            opt(e.sah_batch_ratio.map(|x| 1.0 / x), 2)
        );
    }
    // `sah`'s closest-hit rate, the baseline of Embree's closest-hit ratios.
    let sah_closest = r
        .rows
        .iter()
        .find(|x| x.strategy == "sah")
        .and_then(|x| Some(x.closest.as_ref()?.mrays_per_s));
    for e in &r.embree {
        if let (Some(b), Some(s)) = (e.sah_batch_ratio, e.sah_single_ratio) {
            let c = e
                .closest_mrays_per_s
                .zip(sah_closest)
                .map(|(c, sc)| format!(", closest {:.2}", sc / c))
                .unwrap_or_default();
            println!("sah / {}: batch {b:.2}, single {s:.2}{c}", e.name);
        }
    }
    if r.rows.iter().any(|x| x.closest.is_some()) {
        println!();
        println!(
            "{:<13} {:>10} {:>8} {:>9} {:>7} {:>8} {:>8}",
            "closest", "query ms", "Mrays/s", "hits", "vs sah", "nodes/ray", "tris/ray"
        );
        for x in &r.rows {
            if let Some(c) = &x.closest {
                println!(
                    "{:<13} {:>10.1} {:>8.3} {:>9} {:>7} {:>8.1} {:>8.1}",
                    x.strategy,
                    c.query_ms,
                    c.mrays_per_s,
                    c.hits,
                    opt(c.rel_sah, 2),
                    c.nodes_per_ray,
                    c.tris_per_ray
                );
            }
        }
        for e in &r.embree {
            if let Some(c) = e.closest_mrays_per_s {
                println!(
                    "{:<13} {:>10} {:>8.3} {:>9} {:>7}",
                    e.name,
                    "-",
                    c,
                    "-",
                    opt(sah_closest.map(|s| c / s), 2)
                );
            }
        }
    }
    if !r.counts_agree {
        println!("WARNING: occluded counts are not identical across strategies");
    }
}
