//! The study's report (`experiments.md` §6): Markdown and HTML with the tables and plots of
//! §1–5 and, for each of the paper's findings, what we measured and whether it was reproduced;
//! the sweeps read at fixed errors, and `objr`'s targets met or not when the study ran it.

use super::reach;
use super::records::{ClusterRecord, NoiseRecord, RayRecord, RunMeta, RunRecord, SolveRecord};
use super::score::{rises_above, Monotonicity};
use hirad_accel::cluster::Strategy;
use hirad_accel::ray::Boxes;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::fmt::Write as _;

/// One row of the volumetric-visibility experiment (§5).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct VolumeRow {
    /// Clustering strategy.
    pub strategy: Strategy,
    /// Solve time with volumetric visibility, seconds.
    pub volume_s: f64,
    /// Solve time with exact (ray-cast) visibility, seconds.
    pub exact_s: f64,
    /// RMS ΔE*uv of the volumetric image against the exact-visibility image.
    pub error: f64,
    /// First image of the volumetric solve, relative to the study directory.
    pub image: String,
}

/// Everything the report shows.
#[derive(Clone, Debug, Default)]
pub struct ReportData {
    /// The run the report describes.
    pub meta: RunMeta,
    /// Cluster statistics per strategy (§1).
    pub clusters: Vec<ClusterRecord>,
    /// Ray-casting tests per strategy (§2).
    pub rays: Vec<RayRecord>,
    /// Solves of the ε sweeps (§4).
    pub solves: Vec<SolveRecord>,
    /// The references' own noise per viewpoint.
    pub noise: Vec<NoiseRecord>,
    /// Volumetric-visibility rows (§5).
    pub volume: Vec<VolumeRow>,
    /// Plot and image files (relative paths) by section name.
    pub figures: BTreeMap<String, Vec<String>>,
    /// Wall time of this invocation, seconds (cached work not counted).
    pub wall_s: f64,
    /// Every invocation on the study's directory (a resumed study has several), oldest first.
    pub runs: Vec<RunRecord>,
    /// Unit-key prefixes the study was restricted to (`--only`; empty: every unit).
    pub only: Vec<String>,
}

impl ReportData {
    /// Wall time of the study: the sum over its invocations, or this invocation's when none
    /// was recorded.
    pub fn total_wall_s(&self) -> f64 {
        if self.runs.is_empty() {
            self.wall_s
        } else {
            self.runs.iter().map(|r| r.wall_s).sum()
        }
    }
}

/// Verdict on one of the paper's findings.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Finding {
    /// What the paper found.
    pub paper: String,
    /// What this study measured.
    pub ours: String,
    /// `Some(true)` reproduced, `Some(false)` not reproduced, `None` not measured.
    pub reproduced: Option<bool>,
}

fn verdict(r: Option<bool>) -> &'static str {
    match r {
        Some(true) => "yes",
        Some(false) => "no",
        None => "not measured",
    }
}

fn by<T>(v: &[T], s: Strategy, f: impl Fn(&T) -> Strategy) -> Option<&T> {
    v.iter().find(|r| f(r) == s)
}

/// Solve records grouped per strategy, sorted by decreasing ε.
pub fn curves(solves: &[SolveRecord]) -> BTreeMap<Strategy, Vec<&SolveRecord>> {
    let mut m: BTreeMap<Strategy, Vec<&SolveRecord>> = BTreeMap::new();
    for s in solves {
        m.entry(s.strategy).or_default().push(s);
    }
    for v in m.values_mut() {
        v.sort_by(|a, b| b.eps.total_cmp(&a.eps));
    }
    m
}

/// Each strategy's curve as `(x, error)` points, `x` read from each solve, largest ε first.
fn error_by(
    solves: &[SolveRecord],
    x: impl Fn(&SolveRecord) -> f64,
) -> BTreeMap<Strategy, Vec<(f64, f64)>> {
    curves(solves)
        .into_iter()
        .map(|(s, v)| (s, v.iter().map(|r| (x(r), r.error())).collect()))
        .collect()
}

/// Each strategy's error–ε curve as `(ε, error)` points, largest ε first.
fn error_eps(solves: &[SolveRecord]) -> BTreeMap<Strategy, Vec<(f64, f64)>> {
    error_by(solves, |r| r.eps)
}

/// Monotonicity of each strategy's error–ε curve.
pub fn monotonicity(solves: &[SolveRecord]) -> BTreeMap<Strategy, Monotonicity> {
    error_eps(solves)
        .into_iter()
        .map(|(s, pts)| (s, Monotonicity::of(&pts)))
        .collect()
}

/// The references' own noise: the mean over viewpoints (as a solve's error is) of the RMS
/// ΔE*uv between each reference and its second of another seed; `None` unless every viewpoint
/// of the solves has one.
pub fn reference_noise(d: &ReportData) -> Option<f64> {
    let views = d.solves.first().map_or(0, |r| r.errors.len());
    (views > 0 && d.noise.len() == views)
        .then(|| d.noise.iter().map(|n| n.delta_e).sum::<f64>() / views as f64)
}

/// Per strategy, the steps of its error–ε curve where the error rises by more than `tol`.
pub fn rises_above_noise(solves: &[SolveRecord], tol: f64) -> BTreeMap<Strategy, usize> {
    error_eps(solves)
        .into_iter()
        .map(|(s, pts)| (s, rises_above(&pts, tol)))
        .collect()
}

/// A curve counts as monotone when the error never rises as ε falls, or when it rises at most
/// once and Kendall's τ is at least 0.8 (one noisy step out of a clear trend).
pub fn is_monotone(m: &Monotonicity) -> bool {
    m.rises == 0 || (m.rises <= 1 && m.kendall_tau.is_some_and(|t| t >= 0.8))
}

/// Errors at which the sweeps are compared ([`reach::levels`], four of them), and per strategy
/// the seconds its sweep needs to reach each ([`reach::time_to`]; `None`: never reached).
pub fn time_to_levels(solves: &[SolveRecord]) -> (Vec<f64>, BTreeMap<Strategy, Vec<Option<f64>>>) {
    let te = error_by(solves, |r| r.solve_s);
    let levels = reach::levels(te.values().map(Vec::as_slice), 4);
    let times = te
        .iter()
        .map(|(&s, pts)| (s, levels.iter().map(|&e| reach::time_to(pts, e)).collect()))
        .collect();
    (levels, times)
}

/// One of `objr`'s targets, and whether this study met it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Target {
    /// What `objr` should do.
    pub target: String,
    /// What this study measured.
    pub measured: String,
    /// `Some(true)` met, `Some(false)` not met, `None` not measured.
    pub met: Option<bool>,
}

/// `objr`'s targets against the paper's strategies (issue "A clustering strategy that follows
/// objects"): no rise of its error–ε curve above the references' own noise, each error reached
/// in no more solve time than the fastest of the paper's strategies, a build of at most 3×
/// PROXI's. Empty when the study did not run `objr`.
pub fn objr_targets(d: &ReportData) -> Vec<Target> {
    let objr = Strategy::Objr;
    let has_solves = d.solves.iter().any(|r| r.strategy == objr);
    let cl = |s| by(&d.clusters, s, |r| r.strategy);
    if !has_solves && cl(objr).is_none() {
        return Vec::new();
    }
    let mut out = Vec::new();
    if has_solves {
        let noise = reference_noise(d);
        let (measured, met) = match noise {
            Some(n) => {
                let above = rises_above_noise(&d.solves, n);
                let k = above.get(&objr).copied().unwrap_or(0);
                let paper = above
                    .iter()
                    .filter(|(s, _)| s.is_paper())
                    .map(|(s, c)| format!("{s} {c}"))
                    .collect::<Vec<_>>()
                    .join(", ");
                (
                    format!(
                        "objr {k} rises above the references' own noise (ΔE*uv {n:.2}); the paper's strategies: {paper}"
                    ),
                    Some(k == 0),
                )
            }
            None => ("the references' own noise was not measured".into(), None),
        };
        out.push(Target {
            target: "objr's error–ε curve has no rise larger than the references' own noise".into(),
            measured,
            met,
        });
        let (levels, times) = time_to_levels(&d.solves);
        let lowest = curves(&d.solves)
            .get(&objr)
            .and_then(|v| v.iter().map(|r| r.error()).min_by(f64::total_cmp));
        let mut parts = Vec::new();
        let mut met = None;
        for (i, e) in levels.iter().enumerate() {
            let best = times
                .iter()
                .filter(|(s, _)| s.is_paper())
                .filter_map(|(&s, t)| t[i].map(|t| (s, t)))
                .min_by(|a, b| a.1.total_cmp(&b.1));
            let Some((bs, bt)) = best else { continue };
            let ot = times.get(&objr).and_then(|t| t[i]);
            // Missed by less than the references' own noise: not told apart, as a rise below
            // it is not counted.
            let unresolved = ot.is_none() && noise.zip(lowest).is_some_and(|(n, l)| l - e <= n);
            let ok = ot.is_some_and(|t| t <= bt) || unresolved;
            met = Some(met.unwrap_or(true) && ok);
            let never = || match lowest {
                Some(l) if unresolved => {
                    format!("never (lowest {l:.2}, within the references' own noise of it)")
                }
                Some(l) => format!("never (lowest {l:.2})"),
                None => "never".into(),
            };
            parts.push(format!(
                "at {e:.2}: objr {}, {bs} {bt:.2} s",
                ot.map_or_else(never, |t| format!("{t:.2} s"))
            ));
        }
        out.push(Target {
            target: "objr reaches each error in no more solve time than the fastest of the paper's strategies (an error it misses by less than the references' own noise is not told apart)".into(),
            measured: if parts.is_empty() {
                "no error reached by a paper strategy".into()
            } else {
                parts.join("; ")
            },
            met,
        });
    }
    let (measured, met) = match (cl(objr), cl(Strategy::Proxi)) {
        (Some(o), Some(p)) => {
            let r = o.build_ms / p.build_ms.max(1e-9);
            (
                format!(
                    "objr {:.1} ms, {r:.2}× proxi's {:.1} ms",
                    o.build_ms, p.build_ms
                ),
                Some(r <= 3.0),
            )
        }
        _ => (
            "not measured (no cluster statistics of objr and proxi)".into(),
            None,
        ),
    };
    out.push(Target {
        target: "objr's build takes at most 3× PROXI's".into(),
        measured,
        met,
    });
    out
}

/// The paper's findings next to ours.
pub fn findings(d: &ReportData) -> Vec<Finding> {
    let mut out = Vec::new();
    let c = |s| by(&d.clusters, s, |r| r.strategy);
    // Branching factors.
    {
        let (t, p, o) = (c(Strategy::TfOct), c(Strategy::Proxi), c(Strategy::OkdtP));
        let (ours, rep) = match (t, p, o) {
            (Some(t), Some(p), Some(o)) => (
                format!(
                    "branching tf-oct {:.2}, okdt-p {:.2}, proxi {:.2}",
                    t.branching, o.branching, p.branching
                ),
                Some(t.branching > o.branching && o.branching > p.branching),
            ),
            _ => ("missing strategies".into(), None),
        };
        out.push(Finding {
            paper: "TF-OCT has the highest branching factor, PROXI the lowest, OKDT-P in between (§4.4, Fig. 6)".into(),
            ours,
            reproduced: rep,
        });
    }
    // Build times.
    {
        let p = c(Strategy::Proxi);
        let ratio = |s| {
            c(s).zip(p)
                .map(|(a, p)| 100.0 * a.build_ms / p.build_ms.max(1e-9))
        };
        let (ours, rep) = match (
            ratio(Strategy::TfOct),
            ratio(Strategy::Okdt),
            ratio(Strategy::OkdtP),
        ) {
            (Some(t), Some(o), Some(op)) => (
                format!("tf-oct {t:.1}%, okdt {o:.1}%, okdt-p {op:.1}% of proxi's build time"),
                Some(t < 1.0 && o < 1.0 && (20.0..=80.0).contains(&op)),
            ),
            _ => ("missing strategies".into(), None),
        };
        out.push(Finding {
            paper: "Top-down builds (TF-OCT, OKDT) take < 1% of PROXI's time; OKDT-P 20–80% (§5.2)"
                .into(),
            ours,
            reproduced: rep,
        });
    }
    // Ray casting.
    {
        // The paper's strategies.
        let rows: Vec<&RayRecord> = Strategy::ALL
            .iter()
            .filter(|&&s| s.is_paper())
            .filter_map(|&s| by(&d.rays, s, |r| r.strategy))
            .collect();
        let (ours, rep) = if rows.len() >= 2 {
            // Rates against each unit's own `sah` when every unit timed one (units may run at
            // other times or on other machines), else the rates themselves.
            let rel = rows.iter().all(|r| r.sah_mrays_per_s.is_some());
            let speed = |r: &RayRecord| match r.sah_mrays_per_s {
                Some(s) if rel => r.mrays_per_s / s.max(1e-12),
                _ => r.mrays_per_s,
            };
            let fastest = rows
                .iter()
                .max_by(|a, b| speed(a).total_cmp(&speed(b)))
                .unwrap();
            let desc = rows
                .iter()
                .map(|r| format!("{} {:.3}", r.strategy, speed(r)))
                .collect::<Vec<_>>()
                .join(", ");
            let unit = if rel { "of sah's rate" } else { "Mrays/s" };
            (
                format!(
                    "fastest of the paper's strategies: {} ({unit}: {desc})",
                    fastest.strategy
                ),
                Some(fastest.strategy == Strategy::OkdtP),
            )
        } else {
            ("not run".into(), None)
        };
        out.push(Finding {
            paper: "OKDT-P gives the fastest ray casting of the paper's strategies; lower branching casts faster (§4.4)".into(),
            ours,
            reproduced: rep,
        });
    }
    // Monotone curves.
    {
        let m = monotonicity(&d.solves);
        let (ours, rep) = if m.is_empty() {
            ("no sweep".into(), None)
        } else {
            let desc = m
                .iter()
                .map(|(s, x)| {
                    format!(
                        "{s}: {}/{} rises, τ={}",
                        x.rises,
                        x.steps,
                        x.kendall_tau
                            .map(|t| format!("{t:.2}"))
                            .unwrap_or("–".into())
                    )
                })
                .collect::<Vec<_>>()
                .join("; ");
            let monotone = m.values().filter(|x| is_monotone(x)).count();
            let soup = d.meta.scene_objects <= 1;
            let kind = if soup {
                "polygon soup (no object structure)"
            } else {
                "structured scene"
            };
            // Structured: reproduced when most curves are monotone; soup: when some are not.
            let rep = if soup {
                monotone < m.len()
            } else {
                2 * monotone > m.len()
            };
            // Rises the references' own noise could hide.
            let noisy = reference_noise(d)
                .map(|n| {
                    let above = rises_above_noise(&d.solves, n);
                    let clean = above.values().filter(|&&c| c == 0).count();
                    format!(
                        "; {clean} of {} without a rise above the references' own noise (ΔE*uv {n:.2})",
                        above.len()
                    )
                })
                .unwrap_or_default();
            (
                format!(
                    "{kind}: {monotone} of {} curves monotone ({desc}){noisy}",
                    m.len()
                ),
                Some(rep),
            )
        };
        out.push(Finding {
            paper: "Error decreases monotonically with ε on structured scenes (OFFICE, VRLAB); curves are erratic on polygon soups (AIRCRAFT, CAR) (§5.1, Figs. 2–3)".into(),
            ours,
            reproduced: rep,
        });
    }
    // Volumetric shadows.
    {
        let v = |s| by(&d.volume, s, |r| r.strategy);
        let order = [
            Strategy::Proxi,
            Strategy::OkdtP,
            Strategy::Okdt,
            Strategy::TfOct,
        ];
        let rows: Vec<&VolumeRow> = order.iter().filter_map(|&s| v(s)).collect();
        let (ours, rep) = if rows.len() == order.len() {
            let err_ok = rows.windows(2).all(|w| w[0].error <= w[1].error);
            let desc = rows
                .iter()
                .map(|r| format!("{} ΔE {:.2} in {:.2} s", r.strategy, r.error, r.volume_s))
                .collect::<Vec<_>>()
                .join(", ");
            (desc, Some(err_ok))
        } else {
            ("not run on this scene".into(), None)
        };
        out.push(Finding {
            paper: "Volumetric shadow quality PROXI > OKDT-P > OKDT > TF-OCT, times grow in the same order (§5.2, Fig. 5)".into(),
            ours,
            reproduced: rep,
        });
    }
    out
}

fn fig(md: &mut String, d: &ReportData, key: &str) {
    if let Some(files) = d.figures.get(key) {
        for f in files.iter().filter(|f| f.ends_with(".png")) {
            let _ = writeln!(md, "![{key}]({f})\n");
        }
    }
}

/// The report as Markdown.
pub fn markdown(d: &ReportData) -> String {
    let mut md = String::new();
    let m = &d.meta;
    let _ = writeln!(md, "# hirad study: `{}`\n", m.scene);
    let _ = writeln!(
        md,
        "hirad {} (commit {}), {} threads on {} ({} cores, {:.0} GB). Wall time of the study: {}.\n",
        m.hirad_version,
        m.git_commit,
        m.threads,
        m.machine,
        m.cores,
        m.memory_gb,
        match (d.total_wall_s(), d.runs.len()) {
            (w, _) if w <= 0.0 => "not recorded (merged results)".to_string(),
            (w, n) if n > 1 => format!("{w:.1} s over {n} invocations (see Runs)"),
            (w, _) => format!("{w:.1} s"),
        }
    );
    if !d.only.is_empty() {
        let _ = writeln!(
            md,
            "Only the units whose key starts with one of these were run: {}.\n",
            d.only
                .iter()
                .map(|k| format!("`{k}`"))
                .collect::<Vec<_>>()
                .join(", ")
        );
    }
    let _ = writeln!(md, "## Findings of the paper, and ours\n");
    let _ = writeln!(md, "| paper | ours | reproduced |\n|---|---|---|");
    for f in findings(d) {
        let _ = writeln!(
            md,
            "| {} | {} | {} |",
            f.paper,
            f.ours,
            verdict(f.reproduced)
        );
    }
    let targets = objr_targets(d);
    if !targets.is_empty() {
        let _ = writeln!(md, "\n## objr against its targets\n");
        let _ = writeln!(md, "| target | measured | met |\n|---|---|---|");
        for t in &targets {
            let _ = writeln!(md, "| {} | {} | {} |", t.target, t.measured, verdict(t.met));
        }
    }
    let _ = writeln!(md, "\n## 1. Cluster statistics and build time\n");
    let proxi_ms = by(&d.clusters, Strategy::Proxi, |r| r.strategy).map(|r| r.build_ms);
    let _ = writeln!(
        md,
        "| strategy | clusters | depth max | depth mean | surfaces/cluster | children/cluster | branching | overlap | empty space | bytes | build ms | % of proxi |\n|---|---|---|---|---|---|---|---|---|---|---|---|"
    );
    for r in &d.clusters {
        let pct = proxi_ms
            .map(|p| format!("{:.1}", 100.0 * r.build_ms / p.max(1e-9)))
            .unwrap_or("–".into());
        let _ =
            writeln!(
            md,
            "| {} | {} | {} | {:.2} | {:.2} | {:.2} | {:.2} | {:.3} | {:.3} | {} | {:.1} | {} |",
            r.strategy, r.clusters, r.depth_max, r.depth_mean, r.avg_surfaces, r.avg_children,
            r.branching, r.overlap, r.empty_space, r.tree_bytes, r.build_ms, pct
        );
    }
    md.push('\n');
    fig(&mut md, d, "clusters");
    fig(&mut md, d, "children");
    let _ = writeln!(md, "## 2. Ray-casting test\n");
    let boxes = d.rays.first().map(|r| r.boxes).unwrap_or_default();
    let _ = writeln!(
        md,
        "Batch occlusion, {} boxes ({}). \"vs sah\": against `sah` cast in the same unit, the two \
         taking turns every 16,384 segments, so that neither the machine's drift nor the \
         machine a unit ran on moves the ratio.\n",
        boxes.name(),
        match boxes {
            Boxes::Tight => {
                "each node's box shrunk to its contents, a node's own surfaces behind a box of \
                 their own, long runs of them split into pieces behind boxes of their own, a \
                 node with one child and no surfaces passed through, inner children pulled up \
                 into their parent's lanes (up to eight); each surface tested behind its \
                 node's box; `--ray-boxes cluster` for the strategies' own boxes"
            }
            Boxes::Nodes => {
                "each node's box shrunk to its contents, a node's own surfaces behind one box \
                 of their own, a node with one child and no surfaces passed through; each \
                 surface tested at its node"
            }
            Boxes::Cluster => "the strategies' own boxes, as in the paper",
        }
    );
    let sah = by(&d.rays, Strategy::Sah, |r| r.strategy).map(|r| r.mrays_per_s);
    let _ = writeln!(
        md,
        "| strategy | pairs | build ms | query ms | Mrays/s | vs sah | occluded | nodes/ray | triangles/ray |\n|---|---|---|---|---|---|---|---|---|"
    );
    for r in &d.rays {
        // The unit's own `sah` baseline (timed in turns with it), else the `sah` unit's rate.
        let rel = r
            .sah_mrays_per_s
            .or(sah)
            .map(|s| format!("{:.2}", r.mrays_per_s / s.max(1e-12)))
            .unwrap_or("–".into());
        let _ = writeln!(
            md,
            "| {} | {} | {:.1} | {:.1} | {:.3} | {} | {} | {:.1} | {:.1} |",
            r.strategy,
            r.pairs,
            r.build_ms,
            r.query_ms,
            r.mrays_per_s,
            rel,
            r.occluded,
            r.nodes_per_ray,
            r.tris_per_ray
        );
    }
    md.push('\n');
    fig(&mut md, d, "raytime");
    let _ = writeln!(md, "## 3–4. Time–error sweeps\n");
    let mono = monotonicity(&d.solves);
    let _ = writeln!(
        md,
        "| strategy | ε | solve s | elements | links | cluster energy % | RMS ΔE*uv |\n|---|---|---|---|---|---|---|"
    );
    for (_, rows) in curves(&d.solves) {
        for r in rows {
            let _ = writeln!(
                md,
                "| {} | {:.3e} | {:.3} | {} | {} | {:.1} | {:.3} |",
                r.strategy,
                r.eps,
                r.solve_s,
                r.elements,
                r.links,
                r.cluster_energy_pct,
                r.error()
            );
        }
    }
    let noise = reference_noise(d);
    let _ = writeln!(
        md,
        "\nMonotonicity (steps where the error rises as ε falls; Kendall τ between ε and error):\n"
    );
    match noise {
        Some(n) => {
            let per_view = d
                .noise
                .iter()
                .map(|r| format!("{} {:.3} (seed {})", r.viewpoint, r.delta_e, r.seed))
                .collect::<Vec<_>>()
                .join(", ");
            let _ = writeln!(
                md,
                "The references' own noise, RMS ΔE*uv of a second reference of another seed against each: {per_view}; mean {n:.3}. A rise below it is within what the references resolve.\n"
            );
        }
        None => {
            let _ = writeln!(md, "The references' own noise: not measured.\n");
        }
    }
    let above = noise.map(|n| rises_above_noise(&d.solves, n));
    let _ = writeln!(
        md,
        "| strategy | rises | largest rise | rises above the noise | steps | Kendall τ |\n|---|---|---|---|---|---|"
    );
    for (s, x) in &mono {
        let _ = writeln!(
            md,
            "| {s} | {} | {:.3} | {} | {} | {} |",
            x.rises,
            x.max_rise,
            above
                .as_ref()
                .and_then(|a| a.get(s))
                .map_or("–".into(), |c| c.to_string()),
            x.steps,
            x.kendall_tau
                .map(|t| format!("{t:.3}"))
                .unwrap_or("–".into())
        );
    }
    md.push('\n');
    let (levels, times) = time_to_levels(&d.solves);
    if !levels.is_empty() {
        let _ = writeln!(
            md,
            "Seconds each sweep needs to reach an error (its solves in order of solve time, interpolated in log time between the two around the error; –: never reached), at errors from the lowest any sweep starts at to the lowest any reaches:\n"
        );
        let head: Vec<String> = levels.iter().map(|e| format!("ΔE*uv {e:.2}")).collect();
        let _ = writeln!(
            md,
            "| strategy | {} |\n|---|{}",
            head.join(" | "),
            "---|".repeat(levels.len())
        );
        for (s, t) in &times {
            let cells: Vec<String> = t
                .iter()
                .map(|t| t.map_or("–".into(), |t| format!("{t:.2}")))
                .collect();
            let _ = writeln!(md, "| {s} | {} |", cells.join(" | "));
        }
        md.push('\n');
    }
    fig(&mut md, d, "time_error");
    fig(&mut md, d, "error_eps");
    if !d.volume.is_empty() {
        let _ = writeln!(md, "## 5. Approximate volumetric visibility\n");
        let _ = writeln!(
            md,
            "| strategy | volume s | exact s | speed-up | RMS ΔE*uv vs exact |\n|---|---|---|---|---|"
        );
        for r in &d.volume {
            let _ = writeln!(
                md,
                "| {} | {:.3} | {:.3} | {:.2} | {:.3} |",
                r.strategy,
                r.volume_s,
                r.exact_s,
                r.exact_s / r.volume_s.max(1e-12),
                r.error
            );
        }
        md.push('\n');
        for r in &d.volume {
            let _ = writeln!(md, "![{}]({})\n", r.strategy, r.image);
        }
        fig(&mut md, d, "volume");
    }
    if !d.runs.is_empty() {
        let _ = writeln!(md, "## Runs\n");
        let _ = writeln!(
            md,
            "Each invocation on this directory; a rerun skips the units already on disk.\n"
        );
        let _ = writeln!(
            md,
            "| # | started (unix s) | commit | wall s | computed | skipped | stale temp files removed | outcome |\n|---|---|---|---|---|---|---|---|"
        );
        for (i, r) in d.runs.iter().enumerate() {
            let _ = writeln!(
                md,
                "| {} | {:.0} | {} | {:.1} | {} | {} | {} | {} |",
                i + 1,
                r.started_unix,
                r.meta.git_commit,
                r.wall_s,
                r.computed.len(),
                r.skipped.len(),
                r.removed_temp,
                r.outcome
            );
        }
        md.push('\n');
    }
    md
}

/// The paper's findings across several studies (one per scene: a label, such as the study's
/// directory, and its [`ReportData`] from [`super::run::collect`]): a table of verdicts, study by
/// study (the paper's findings, then `objr`'s targets), then what we measured.
pub fn cross_scene(studies: &[(String, ReportData)]) -> String {
    let mut md = String::new();
    let _ = writeln!(md, "# hirad studies: the paper's findings across scenes\n");
    let names: Vec<String> = studies
        .iter()
        .map(|(l, d)| format!("{l} (`{}`)", d.meta.scene))
        .collect();
    let _ = writeln!(
        md,
        "| finding of the paper | {} |\n|---|{}",
        names.join(" | "),
        "---|".repeat(studies.len())
    );
    let all: Vec<Vec<Finding>> = studies.iter().map(|(_, d)| findings(d)).collect();
    let n = all.iter().map(Vec::len).max().unwrap_or(0);
    for i in 0..n {
        let paper = all
            .iter()
            .find_map(|f| f.get(i))
            .map(|f| f.paper.clone())
            .unwrap_or_default();
        let cells: Vec<&str> = all
            .iter()
            .map(|f| verdict(f.get(i).and_then(|f| f.reproduced)))
            .collect();
        let _ = writeln!(md, "| {paper} | {} |", cells.join(" | "));
    }
    let targets: Vec<Vec<Target>> = studies.iter().map(|(_, d)| objr_targets(d)).collect();
    let nt = targets.iter().map(Vec::len).max().unwrap_or(0);
    let target_name = |i: usize| {
        targets
            .iter()
            .find_map(|t| t.get(i))
            .map(|t| t.target.clone())
            .unwrap_or_default()
    };
    for i in 0..nt {
        let cells: Vec<&str> = targets
            .iter()
            .map(|t| verdict(t.get(i).and_then(|t| t.met)))
            .collect();
        let _ = writeln!(md, "| target: {} | {} |", target_name(i), cells.join(" | "));
    }
    let walls: Vec<String> = studies
        .iter()
        .map(|(_, d)| {
            let w = d.total_wall_s();
            if w > 0.0 {
                format!("{w:.0} s ({} invocation(s))", d.runs.len().max(1))
            } else {
                "not recorded".into()
            }
        })
        .collect();
    let _ = writeln!(md, "| wall time of the study | {} |", walls.join(" | "));
    let _ = writeln!(md, "\n## What we measured\n");
    for i in 0..n {
        if let Some(f) = all.iter().find_map(|f| f.get(i)) {
            let _ = writeln!(md, "**{}**\n", f.paper);
        }
        for ((l, _), f) in studies.iter().zip(&all) {
            if let Some(f) = f.get(i) {
                let _ = writeln!(md, "- {l}: {} — {}", f.ours, verdict(f.reproduced));
            }
        }
        md.push('\n');
    }
    for i in 0..nt {
        let _ = writeln!(md, "**target: {}**\n", target_name(i));
        for ((l, _), t) in studies.iter().zip(&targets) {
            if let Some(t) = t.get(i) {
                let _ = writeln!(md, "- {l}: {} — {}", t.measured, verdict(t.met));
            }
        }
        md.push('\n');
    }
    md
}

/// The report as a standalone HTML page.
pub fn html(md: &str, title: &str) -> String {
    let parser = pulldown_cmark::Parser::new_ext(md, pulldown_cmark::Options::ENABLE_TABLES);
    let mut body = String::new();
    pulldown_cmark::html::push_html(&mut body, parser);
    format!(
        "<!DOCTYPE html>\n<html><head><meta charset=\"utf-8\"><title>{title}</title>\n<style>body{{font-family:sans-serif;max-width:1100px;margin:2em auto}}table{{border-collapse:collapse}}td,th{{border:1px solid #aaa;padding:2px 6px;text-align:right}}img{{max-width:100%}}</style></head><body>\n{body}</body></html>\n"
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn srec(s: Strategy, eps: f64, err: f64) -> SolveRecord {
        SolveRecord {
            meta: RunMeta::default(),
            strategy: s,
            refine: "bf".into(),
            visibility: "rays".into(),
            eps,
            solve_s: 1.0 / eps,
            elements: 1,
            links: 1,
            cluster_energy_pct: 50.0,
            errors: vec![err],
            images: vec![],
        }
    }

    #[test]
    fn monotonicity_finding_depends_on_scene_kind() {
        // kdt monotone, okdt with two rises (erratic).
        let mut solves = Vec::new();
        for (i, e) in [0.8, 0.4, 0.2, 0.1].into_iter().enumerate() {
            solves.push(srec(Strategy::Kdt, e, 10.0 - i as f64));
            solves.push(srec(Strategy::Okdt, e, [5.0, 6.0, 4.0, 4.5][i]));
        }
        let mut d = ReportData {
            solves,
            ..Default::default()
        };
        d.meta.scene_objects = 40;
        let f = &findings(&d)[3];
        // 1 of 2 monotone is not a majority on a structured scene.
        assert_eq!(f.reproduced, Some(false), "{f:?}");
        assert!(f.ours.contains("1 of 2 curves monotone"));
        d.meta.scene_objects = 1;
        assert_eq!(findings(&d)[3].reproduced, Some(true));
        let m = monotonicity(&d.solves);
        assert_eq!(m[&Strategy::Okdt].rises, 2);
        assert!((m[&Strategy::Okdt].max_rise - 1.0).abs() < 1e-12);
        assert!(is_monotone(&m[&Strategy::Kdt]));
        assert!(markdown(&d).contains("The references' own noise: not measured."));
        // okdt's rises (1.0 and 0.5) against the references' own noise.
        let nrec = |v: &str, delta_e| NoiseRecord {
            meta: RunMeta::default(),
            viewpoint: v.into(),
            seed: 2,
            delta_e,
            seconds: 1.0,
            image: String::new(),
        };
        d.noise = vec![nrec("default", 0.75)];
        assert_eq!(reference_noise(&d), Some(0.75));
        assert_eq!(rises_above_noise(&d.solves, 0.75)[&Strategy::Okdt], 1);
        assert!(findings(&d)[3]
            .ours
            .ends_with("; 1 of 2 without a rise above the references' own noise (ΔE*uv 0.75)"));
        let md = markdown(&d);
        assert!(md.contains("| okdt | 2 | 1.000 | 1 | 3 |"), "{md}");
        assert!(md.contains("default 0.750 (seed 2); mean 0.750"), "{md}");
        d.noise = vec![nrec("default", 1.5)];
        assert!(findings(&d)[3]
            .ours
            .contains("; 2 of 2 without a rise above"));
        // A viewpoint without its noise: the mean over viewpoints is not known.
        d.noise.clear();
        assert_eq!(reference_noise(&d), None);
    }

    fn crec(s: Strategy, branching: f64, build_ms: f64) -> ClusterRecord {
        ClusterRecord {
            meta: RunMeta::default(),
            strategy: s,
            clusters: 10,
            depth_max: 3,
            depth_mean: 2.0,
            avg_surfaces: 3.0,
            avg_children: 2.0,
            branching,
            overlap: 0.1,
            empty_space: 1.0,
            tree_bytes: 100,
            build_ms,
        }
    }

    #[test]
    fn findings_judge_branching_and_build_time() {
        let d = ReportData {
            clusters: vec![
                crec(Strategy::TfOct, 6.0, 0.5),
                crec(Strategy::Okdt, 2.5, 0.8),
                crec(Strategy::OkdtP, 4.0, 50.0),
                crec(Strategy::Proxi, 3.0, 100.0),
            ],
            ..Default::default()
        };
        let f = findings(&d);
        assert_eq!(f[0].reproduced, Some(true), "{:?}", f[0]);
        assert_eq!(f[1].reproduced, Some(true), "{:?}", f[1]);
        assert_eq!(f[2].reproduced, None);
        assert_eq!(f[3].reproduced, None, "no sweep");
        let md = markdown(&d);
        assert!(md.contains("| okdt-p | 10 |"));
        assert!(md.contains("| 50.0 |"), "{md}");
        let h = html(&md, "t");
        assert!(h.contains("<table>") && h.contains("<td>okdt-p</td>"));
        // Across scenes: one column per study, one row per finding.
        let mut soup = ReportData::default();
        soup.meta.scene = "soup".into();
        let mut d = d;
        d.meta.scene = "office".into();
        let x = cross_scene(&[("a".into(), d), ("b".into(), soup)]);
        assert!(x.contains("| a (`office`) | b (`soup`) |"), "{x}");
        assert!(x.contains("(§4.4, Fig. 6) | yes | not measured |"), "{x}");
        assert_eq!(x.matches("\n| ").count(), 1 + 5 + 1, "{x}");
    }

    #[test]
    fn objr_targets_compare_it_with_the_fastest_paper_strategy() {
        // Times 1/ε: objr 1.25, 2.5, 5, 10 s; okdt 1.25 … 10 s and tf-oct 2.5 … 20 s.
        let mut solves = Vec::new();
        for (i, e) in [0.8, 0.4, 0.2, 0.1].into_iter().enumerate() {
            solves.push(srec(Strategy::Objr, e, [8.0, 4.0, 2.0, 1.0][i]));
            solves.push(srec(Strategy::Okdt, e, [8.0, 6.0, 4.0, 3.0][i]));
            solves.push(srec(Strategy::TfOct, e / 2.0, [9.0, 4.0, 3.0, 2.5][i]));
            // sah is not a paper strategy: faster than objr, it does not count.
            solves.push(srec(Strategy::Sah, 2.0 * e, [4.0, 2.0, 1.0, 0.5][i]));
        }
        let mut d = ReportData {
            solves,
            clusters: vec![
                crec(Strategy::Objr, 3.0, 25.0),
                crec(Strategy::Proxi, 3.0, 10.0),
            ],
            ..Default::default()
        };
        let t = objr_targets(&d);
        assert_eq!(t.len(), 3);
        assert_eq!(t[0].met, None, "no noise measured");
        // Levels from 4 (sah's first error) to 0.5 (sah's last).
        let (levels, times) = time_to_levels(&d.solves);
        assert_eq!(levels.len(), 4);
        assert!((levels[0] - 4.0).abs() < 1e-12 && (levels[3] - 0.5).abs() < 1e-12);
        // At 4: objr 2.5 s, okdt 5 s, tf-oct 5 s (its second solve).
        assert!((times[&Strategy::Objr][0].unwrap() - 2.5).abs() < 1e-12);
        assert!((times[&Strategy::Okdt][0].unwrap() - 5.0).abs() < 1e-12);
        assert_eq!(times[&Strategy::Okdt][3], None);
        assert_eq!(t[1].met, Some(true), "{:?}", t[1]);
        assert!(
            t[1].measured.starts_with("at 4.00: objr 2.50 s, "),
            "{:?}",
            t[1]
        );
        assert_eq!(t[2].met, Some(true), "{:?}", t[2]);
        assert!(
            t[2].measured.contains("2.50× proxi's 10.0 ms"),
            "{:?}",
            t[2]
        );
        // objr's solves 2.2× slower: the paper's strategies are first at 4.
        for r in d.solves.iter_mut().filter(|r| r.strategy == Strategy::Objr) {
            r.solve_s *= 2.2;
        }
        d.clusters[0].build_ms = 31.0;
        let t = objr_targets(&d);
        assert_eq!(t[1].met, Some(false), "{:?}", t[1]);
        assert_eq!(t[2].met, Some(false), "{:?}", t[2]);
        // A level objr never reaches, which okdt does: not met, and objr's lowest said.
        let mut e = d.clone();
        e.solves.retain(|r| r.strategy != Strategy::Sah);
        for r in e.solves.iter_mut().filter(|r| r.strategy == Strategy::Objr) {
            r.solve_s /= 2.2;
            r.errors[0] = r.errors[0].max(3.5);
        }
        let t = objr_targets(&e);
        assert_eq!(t[1].met, Some(false), "{:?}", t[1]);
        assert!(
            t[1].measured
                .ends_with("at 2.50: objr never (lowest 3.50), tf-oct 20.00 s"),
            "{:?}",
            t[1]
        );
        // The same miss by less than the references' own noise is not told apart.
        e.noise = vec![NoiseRecord {
            meta: RunMeta::default(),
            viewpoint: "default".into(),
            seed: 2,
            delta_e: 1.0,
            seconds: 1.0,
            image: String::new(),
        }];
        let t = objr_targets(&e);
        assert_eq!(t[1].met, Some(true), "{:?}", t[1]);
        let within =
            "objr never (lowest 3.50, within the references' own noise of it), tf-oct 20.00 s";
        assert!(t[1].measured.ends_with(within), "{:?}", t[1]);
        e.noise[0].delta_e = 0.9;
        assert_eq!(objr_targets(&e)[1].met, Some(false));
        let md = markdown(&d);
        assert!(md.contains("## objr against its targets"), "{md}");
        assert!(
            md.contains("| strategy | ΔE*uv 4.00 | ΔE*uv 2.00 | ΔE*uv 1.00 | ΔE*uv 0.50 |"),
            "{md}"
        );
        assert!(md.contains("| okdt | 5.00 | – | – | – |"), "{md}");
        let x = cross_scene(&[("a".into(), d)]);
        assert!(
            x.contains("| target: objr's build takes at most 3× PROXI's | no |"),
            "{x}"
        );
        // Without objr, no targets.
        let d = ReportData {
            clusters: vec![crec(Strategy::Proxi, 3.0, 10.0)],
            ..Default::default()
        };
        assert!(objr_targets(&d).is_empty());
        assert!(!markdown(&d).contains("against its targets"));
    }
}
