//! `hirad study SCENE ...`: the paper's experiments end to end (`experiments.md` §1–6), and
//! `hirad study merge DIR...` to combine results computed on several machines; `--slurm` writes
//! (and `--submit` submits) the units as a Slurm job array (`study_slurm.rs`).

use crate::progress::{overall_bar, Bars};
use crate::Global;
use hirad::cluster::Strategy;
use hirad::radiosity::{ClusterEmission, Oracle, SolverConfig, VisibilityMode};
use hirad::ray::Boxes;
use hirad::study::run::{self, Study, StudyConfig};
use std::path::PathBuf;

#[derive(clap::Args, Debug)]
#[command(args_conflicts_with_subcommands = true)]
pub struct Args {
    #[command(subcommand)]
    pub sub: Option<Sub>,
    /// Scene: a file path or a built-in name.
    pub scene: Option<String>,
    /// Strategies: a comma-separated list or `all`.
    #[arg(long, default_value = "all")]
    pub clustering: String,
    /// Refinement oracle: bf or error.
    #[arg(long, default_value = "bf")]
    pub refine: String,
    /// Cluster emission: isotropic (the paper's model, default here) or directional.
    #[arg(long, default_value = "isotropic")]
    pub cluster_emission: String,
    /// Number of ε values of the sweep (geometric series of the relative ε, 0: no sweep).
    /// Default 8, or 0 with `--visibility volume` (that study is the §5 experiment).
    #[arg(long)]
    pub tolerances: Option<usize>,
    /// Explicit relative ε values, comma-separated (overrides --tolerances) [default: none].
    #[arg(long, value_delimiter = ',')]
    pub eps_list: Vec<f64>,
    /// Largest relative ε of the series [default: calibrated by probe solves so that 30–100% of
    /// the energy goes through cluster links].
    #[arg(long)]
    pub eps_hi: Option<f64>,
    /// Smallest relative ε of the series [default: calibrated with --eps-hi].
    #[arg(long)]
    pub eps_lo: Option<f64>,
    /// Visibility of the solves: rays or volume (volume also runs the §5 experiment:
    /// volumetric against exact visibility per strategy).
    #[arg(long, default_value = "rays")]
    pub visibility: String,
    /// Volume visibility: clusters smaller than this × the segment length act as volumes.
    #[arg(long, default_value_t = 0.1)]
    pub vol_ratio: f32,
    /// Viewpoints by camera name, comma-separated (default: every camera of the scene).
    #[arg(long, value_delimiter = ',')]
    pub viewpoints: Vec<String>,
    /// Image size of the renders, WxH.
    #[arg(long, default_value = "320x240")]
    pub size: String,
    /// Path-tracer samples per pixel of the reference images.
    #[arg(long, default_value_t = 256)]
    pub spp: u32,
    /// Skip the second reference per viewpoint (another seed) that measures the references'
    /// own noise, against which the report weighs the rises of the error curves.
    #[arg(long)]
    pub no_reference_noise: bool,
    /// Pairs of the ray-casting test (0 skips it).
    #[arg(long, default_value_t = 100_000)]
    pub pairs: usize,
    /// Boxes of the ray-casting test: tight (shrunk to their contents, long runs of a node's
    /// triangles split), nodes (shrunk, runs whole) or cluster (the strategies' own, as in the
    /// paper); see `raybench --boxes`.
    #[arg(long, default_value = "tight")]
    pub ray_boxes: String,
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Timed builds per strategy (median reported).
    #[arg(long, default_value_t = 5)]
    pub repeat: usize,
    /// Surfaces with a back face (polygon soups with inconsistent winding; implied by an MGF
    /// file whose non-emitting materials are all `sides 2`).
    #[arg(long)]
    pub two_sided: bool,
    /// Output directory.
    #[arg(long, default_value = "hirad-out/study")]
    pub out: PathBuf,
    /// Write report.md / report.html (tables, plots, the paper's findings next to ours).
    #[arg(long)]
    pub report: bool,
    /// Print one command per unit of work instead of running (for a batch scheduler); merge
    /// the output directories afterwards with `hirad study merge`.
    #[arg(long)]
    pub jobs: bool,
    /// Run only the units whose key starts with this (repeatable), e.g. `solve/okdt` [default:
    /// every unit].
    #[arg(long)]
    pub only: Vec<String>,
    #[command(flatten)]
    pub slurm: super::study_slurm::SlurmArgs,
}

#[derive(clap::Subcommand, Debug)]
pub enum Sub {
    /// Merge the results of several study directories and write the report.
    Merge {
        /// Study directories to merge.
        #[arg(required = true)]
        dirs: Vec<PathBuf>,
        /// Directory to merge into (default: the first one).
        #[arg(long)]
        into: Option<PathBuf>,
    },
    /// The paper's findings across the studies of several scenes (one directory each), as
    /// `summary.md` and `summary.html`.
    Summary {
        /// Study directories, one per scene.
        #[arg(required = true)]
        dirs: Vec<PathBuf>,
        /// Output directory.
        #[arg(long, default_value = "hirad-out")]
        out: PathBuf,
    },
}

fn parse_size(s: &str) -> anyhow::Result<(u32, u32)> {
    let (w, h) = s
        .split_once(['x', 'X'])
        .ok_or_else(|| anyhow::anyhow!("--size must be WxH, got '{s}'"))?;
    let (w, h): (u32, u32) = (w.trim().parse()?, h.trim().parse()?);
    anyhow::ensure!(
        w > 0 && h > 0 && w <= 16384 && h <= 16384,
        "--size {s} out of range"
    );
    Ok((w, h))
}

fn config(a: &Args, scene: &str) -> anyhow::Result<StudyConfig> {
    let visibility = VisibilityMode::parse(&a.visibility)?;
    let solver = SolverConfig {
        refine: Oracle::parse(&a.refine)?,
        cluster_emission: ClusterEmission::parse(&a.cluster_emission)?,
        visibility: VisibilityMode::Rays,
        two_sided: a.two_sided,
        vol_ratio: a.vol_ratio,
        ..SolverConfig::default()
    };
    Ok(StudyConfig {
        scene: scene.to_string(),
        strategies: Strategy::parse_list(&a.clustering)?,
        solver,
        tolerances: a
            .tolerances
            .unwrap_or(if visibility == VisibilityMode::Volume {
                0
            } else {
                8
            }),
        eps_list: a.eps_list.clone(),
        eps_hi: a.eps_hi.unwrap_or(0.2),
        eps_lo: a.eps_lo.unwrap_or(0.002),
        eps_auto: a.eps_hi.is_none() && a.eps_lo.is_none(),
        viewpoints: a.viewpoints.clone(),
        size: parse_size(&a.size)?,
        reference_spp: a.spp,
        reference_noise: !a.no_reference_noise,
        ray_pairs: a.pairs,
        ray_boxes: Boxes::parse(&a.ray_boxes)?,
        seed: a.seed,
        build_repeats: a.repeat,
        volume: visibility == VisibilityMode::Volume,
        out: a.out.clone(),
        only: a.only.clone(),
        ..StudyConfig::default()
    })
}

fn report(out: &std::path::Path, wall_s: f64, quiet: bool) -> anyhow::Result<()> {
    let mut d = run::collect(out)?;
    d.wall_s = wall_s;
    let files = run::write_outputs(out, &mut d)?;
    if !quiet {
        for f in files {
            eprintln!("wrote {}", f.display());
        }
    }
    Ok(())
}

pub fn run(a: Args, g: &Global) -> anyhow::Result<()> {
    if let Some(Sub::Summary { dirs, out }) = &a.sub {
        let mut studies = Vec::new();
        for d in dirs {
            anyhow::ensure!(
                d.join("config.json").is_file(),
                "{} is not a study directory (no config.json)",
                d.display()
            );
            let label = d
                .file_name()
                .map(|n| n.to_string_lossy().to_string())
                .unwrap_or_else(|| d.display().to_string());
            studies.push((label, run::collect(d)?));
        }
        let md = hirad::study::report::cross_scene(&studies);
        let p = out.join("summary.md");
        hirad::io::write_bytes_atomic(&p, md.as_bytes())?;
        let h = out.join("summary.html");
        hirad::io::write_bytes_atomic(
            &h,
            hirad::study::report::html(&md, "hirad studies: findings across scenes").as_bytes(),
        )?;
        if !g.quiet {
            eprintln!("wrote {} and {}", p.display(), h.display());
        }
        return Ok(());
    }
    if let Some(Sub::Merge { dirs, into }) = &a.sub {
        let into = into.clone().unwrap_or_else(|| dirs[0].clone());
        let n = run::merge(&into, dirs)?;
        eprintln!("merged {n} results into {}", into.display());
        super::study_slurm::report_missing(&into);
        return report(&into, 0.0, g.quiet);
    }
    let scene = a.scene.clone().ok_or_else(|| {
        // A usage error (exit 2), like the parser's own.
        hirad::Error::Config("a scene is required (or `hirad study merge DIR...`)".into())
    })?;
    let cfg = config(&a, &scene)?;
    let cancel = super::cancel_on_ctrl_c(Some(
        "\ninterrupted: finishing nothing half-written; rerun to resume",
    ));
    let multi = indicatif::MultiProgress::new();
    let bars = Bars::in_multi(g.quiet, multi.clone());
    let t0 = std::time::Instant::now();
    let study = Study::new(cfg, &bars, &cancel)?;
    // Units finished by Slurm tasks join the study; what is missing is reported.
    super::study_slurm::collect(&study, g.quiet)?;
    if a.slurm.slurm {
        return super::study_slurm::write_and_submit(&a, &study, g.quiet);
    }
    if a.jobs {
        // The ε series is fixed here (calibrating if needed) and passed to every job.
        let eps = study.eps()?;
        let jobs = study.plan()?;
        let exe = std::env::args().next().unwrap_or_else(|| "hirad".into());
        let mut base: Vec<String> = std::env::args().skip(1).filter(|x| x != "--jobs").collect();
        if !eps.is_empty() && a.eps_list.is_empty() {
            let list: Vec<String> = eps.iter().map(|e| format!("{e:e}")).collect();
            base.push(format!("--eps-list {}", list.join(",")));
        }
        // Every job writes into its own directory; merge them afterwards.
        if let Some(i) = base.iter().position(|x| x == "--out") {
            base.drain(i..(i + 2).min(base.len()));
        }
        for (i, j) in jobs.iter().enumerate() {
            let key = j.key();
            let dir = a.out.join(format!("job-{i:04}"));
            let quiet = if base.iter().any(|x| x == "-q" || x == "--quiet") {
                ""
            } else {
                " -q"
            };
            println!(
                "{exe} {} --out {} --only {key}{quiet}",
                base.join(" "),
                dir.display()
            );
        }
        eprintln!(
            "{} jobs; afterwards: {exe} study merge {}/job-* --into {}",
            jobs.len(),
            a.out.display(),
            a.out.display()
        );
        return Ok(());
    }
    if study.removed_temp > 0 && !g.quiet {
        eprintln!(
            "removed {} temporary file(s) left by a killed run",
            study.removed_temp
        );
    }
    let overall = overall_bar(&multi, g.quiet, 0, "study");
    let r = study.run_all(&mut |j, i, n| {
        overall.set_length(n as u64);
        overall.set_position(i as u64);
        overall.set_message(j.key());
    });
    let rec = match r {
        Ok(rec) => rec,
        Err(e) => {
            overall.abandon();
            if matches!(e, hirad::Error::Interrupted) {
                eprintln!(
                    "stopped; finished units are on disk in {}; rerun the same command to resume",
                    a.out.display()
                );
                std::process::exit(130);
            }
            return Err(e.into());
        }
    };
    overall.finish_and_clear();
    if !g.quiet {
        eprintln!(
            "{} units computed, {} done earlier and skipped",
            rec.computed.len(),
            rec.skipped.len()
        );
    }
    let wall = t0.elapsed().as_secs_f64();
    if a.report || g.json {
        report(&a.out, wall, g.quiet)?;
    }
    if g.json {
        let d = run::collect(&a.out)?;
        return super::print_json(&hirad::study::report::findings(&d));
    }
    if !g.quiet {
        eprintln!(
            "study of {scene} done in {wall:.1} s; results in {}",
            a.out.display()
        );
    }
    Ok(())
}
