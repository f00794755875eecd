//! What a study directory yields: its records collected ([`collect`]) and written out as CSV
//! tables, plots, `report.md`, `report.html` and `results.json` ([`write_outputs`]).

use super::StudyConfig;
use crate::plot::{strategy_color, BarPlot, LinePlot, Series};
use crate::records::{ClusterRecord, NoiseRecord, RayRecord, RunMeta, RunRecord, SolveRecord};
use crate::report::{self, ReportData, VolumeRow};
use crate::store::Store;
use hirad_accel::cluster::Strategy;
use hirad_core::Result;
use std::path::PathBuf;

/// Collect every record in a study directory into the report's data.
pub fn collect(out: &std::path::Path) -> Result<ReportData> {
    let store = Store::new(out);
    let cfg: StudyConfig = store.get("config").unwrap_or_default();
    let mut d = ReportData {
        meta: RunMeta::current(&cfg.scene),
        only: cfg.only.clone(),
        ..Default::default()
    };
    let order = |s: Strategy| Strategy::ALL.iter().position(|&x| x == s).unwrap_or(99);
    for k in store.keys("clusters") {
        if let Some(r) = store.get::<ClusterRecord>(&k) {
            d.meta = r.meta.clone();
            d.clusters.push(r);
        }
    }
    d.clusters.sort_by_key(|r| order(r.strategy));
    for k in store.keys("raybench") {
        if let Some(r) = store.get::<RayRecord>(&k) {
            d.rays.push(r);
        }
    }
    d.rays.sort_by_key(|r| order(r.strategy));
    for k in store.keys("solve") {
        if let Some(r) = store.get::<SolveRecord>(&k) {
            d.solves.push(r);
        }
    }
    for k in store.keys("noise") {
        if let Some(r) = store.get::<NoiseRecord>(&k) {
            d.noise.push(r);
        }
    }
    for k in store.keys("volume") {
        if let Some(r) = store.get::<VolumeRow>(&k) {
            d.volume.push(r);
        }
    }
    d.volume.sort_by_key(|r| order(r.strategy));
    for k in store.keys("runs") {
        if let Some(r) = store.get::<RunRecord>(&k) {
            d.runs.push(r);
        }
    }
    d.runs
        .sort_by(|a, b| a.started_unix.total_cmp(&b.started_unix));
    Ok(d)
}

/// Write CSV tables, plots, `report.md` and `report.html` for a study directory.
pub fn write_outputs(out: &std::path::Path, d: &mut ReportData) -> Result<Vec<PathBuf>> {
    let mut files = Vec::new();
    let plots = out.join("plots");
    // Fig. 6: clusters, children per cluster, ray-casting time per strategy.
    if !d.clusters.is_empty() {
        let bars = |title: &str, y: &str, f: &dyn Fn(&ClusterRecord) -> f64| BarPlot {
            title: title.into(),
            y_label: y.into(),
            log_y: false,
            bars: d
                .clusters
                .iter()
                .map(|r| (r.strategy.to_string(), strategy_color(r.strategy), f(r)))
                .collect(),
        };
        let scene = &d.meta.scene;
        let f1 = bars(
            &format!("Clusters per strategy ({scene})"),
            "clusters",
            &|r| r.clusters as f64,
        )
        .write(&plots.join("clusters"))?;
        let f2 = bars(
            &format!("Children per cluster ({scene})"),
            "children / cluster (mean over clusters)",
            &|r| r.avg_children,
        )
        .write(&plots.join("children"))?;
        d.figures.insert("clusters".into(), rel(out, &f1));
        d.figures.insert("children".into(), rel(out, &f2));
        files.extend(f1);
        files.extend(f2);
    }
    if !d.rays.is_empty() {
        // Log scale when the strategies differ by orders of magnitude (kdt on large scenes).
        let q: Vec<f64> = d
            .rays
            .iter()
            .map(|r| r.query_ms)
            .filter(|v| *v > 0.0)
            .collect();
        let spread =
            q.iter().cloned().fold(0.0, f64::max) / q.iter().cloned().fold(f64::INFINITY, f64::min);
        let f = BarPlot {
            title: format!(
                "Ray-casting test: {} segments ({})",
                d.rays[0].pairs, d.meta.scene
            ),
            y_label: "query time (ms)".into(),
            log_y: spread > 30.0,
            bars: d
                .rays
                .iter()
                .map(|r| {
                    (
                        r.strategy.to_string(),
                        strategy_color(r.strategy),
                        r.query_ms,
                    )
                })
                .collect(),
        }
        .write(&plots.join("raytime"))?;
        d.figures.insert("raytime".into(), rel(out, &f));
        files.extend(f);
    }
    if !d.solves.is_empty() {
        let curves = report::curves(&d.solves);
        let series = |f: &dyn Fn(&SolveRecord) -> (f64, f64)| -> Vec<Series> {
            curves
                .iter()
                .map(|(s, v)| Series {
                    name: s.to_string(),
                    color: strategy_color(*s),
                    points: v.iter().map(|r| f(r)).collect(),
                })
                .collect()
        };
        let f2 = LinePlot {
            title: format!("Time vs error ({})", d.meta.scene),
            x_label: "solve time (s)".into(),
            y_label: "RMS ΔE*uv".into(),
            log_x: true,
            log_y: true,
            series: series(&|r| (r.solve_s, r.error())),
        }
        .write(&plots.join("time_error"))?;
        let f3 = LinePlot {
            title: format!("Error vs ε ({})", d.meta.scene),
            x_label: "ε (relative)".into(),
            y_label: "RMS ΔE*uv".into(),
            log_x: true,
            log_y: false,
            series: series(&|r| (r.eps, r.error())),
        }
        .write(&plots.join("error_eps"))?;
        d.figures.insert("time_error".into(), rel(out, &f2));
        d.figures.insert("error_eps".into(), rel(out, &f3));
        files.extend(f2);
        files.extend(f3);
    }
    // CSV tables.
    let scene = &d.meta.scene;
    files.push(write_csv(
        &out.join("sweep.csv"),
        "scene,strategy,refine,visibility,eps_rel,solve_s,elements,links,cluster_energy_pct,rms_delta_e",
        d.solves.iter().map(|r| {
            format!(
                "{scene},{},{},{},{:e},{:.6},{},{},{:.3},{:.6}",
                r.strategy, r.refine, r.visibility, r.eps, r.solve_s, r.elements, r.links,
                r.cluster_energy_pct, r.error()
            )
        }),
    )?);
    files.push(write_csv(
        &out.join("clusters.csv"),
        "scene,strategy,clusters,depth_max,depth_mean,avg_surfaces,avg_children,branching,overlap,empty_space,tree_bytes,build_ms",
        d.clusters.iter().map(|r| {
            format!(
                "{scene},{},{},{},{:.4},{:.4},{:.4},{:.4},{:.6},{:.6},{},{:.4}",
                r.strategy, r.clusters, r.depth_max, r.depth_mean, r.avg_surfaces,
                r.avg_children, r.branching, r.overlap, r.empty_space, r.tree_bytes, r.build_ms
            )
        }),
    )?);
    files.push(write_csv(
        &out.join("raybench.csv"),
        "scene,strategy,pairs,seed,boxes,build_ms,query_ms,mrays_per_s,occluded,nodes_per_ray,tris_per_ray,sah_mrays_per_s",
        d.rays.iter().map(|r| {
            format!(
                "{scene},{},{},{},{},{:.4},{:.4},{:.6},{},{:.3},{:.3},{}",
                r.strategy,
                r.pairs,
                r.seed,
                r.boxes.name(),
                r.build_ms,
                r.query_ms,
                r.mrays_per_s,
                r.occluded,
                r.nodes_per_ray,
                r.tris_per_ray,
                r.sah_mrays_per_s.map(|x| format!("{x:.6}")).unwrap_or_default()
            )
        }),
    )?);
    let md = report::markdown(d);
    let p = out.join("report.md");
    hirad_core::io::write_bytes_atomic(&p, md.as_bytes())?;
    files.push(p);
    let p = out.join("report.html");
    hirad_core::io::write_bytes_atomic(
        &p,
        report::html(&md, &format!("hirad study: {}", d.meta.scene)).as_bytes(),
    )?;
    files.push(p);
    let p = out.join("results.json");
    hirad_core::io::write_json_atomic(
        &p,
        &serde_json::json!({
            "meta": d.meta, "clusters": d.clusters, "raybench": d.rays, "solves": d.solves,
            "volume": d.volume, "noise": d.noise, "reference_noise": report::reference_noise(d),
            "findings": report::findings(d),
            "wall_s": d.total_wall_s(), "runs": d.runs,
            "monotonicity": report::monotonicity(&d.solves).into_iter().map(|(s, m)| (s.to_string(), m)).collect::<std::collections::BTreeMap<_, _>>(),
        }),
    )?;
    files.push(p);
    Ok(files)
}

/// Write a CSV file atomically: the header line, then one line per row.
fn write_csv(
    path: &std::path::Path,
    header: &str,
    rows: impl Iterator<Item = String>,
) -> Result<PathBuf> {
    let mut csv = format!("{header}\n");
    for r in rows {
        csv.push_str(&r);
        csv.push('\n');
    }
    hirad_core::io::write_bytes_atomic(path, csv.as_bytes())?;
    Ok(path.to_path_buf())
}

fn rel(base: &std::path::Path, files: &[PathBuf]) -> Vec<String> {
    files
        .iter()
        .map(|f| {
            f.strip_prefix(base)
                .unwrap_or(f)
                .to_string_lossy()
                .replace('\\', "/")
        })
        .collect()
}
