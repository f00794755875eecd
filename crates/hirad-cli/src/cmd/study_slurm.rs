//! `hirad study … --slurm [--submit]`: the study's unfinished units as a Slurm job array
//! (script from `hirad::study::run::slurm`), and the collection of the tasks' results when the
//! study is rerun or merged.

use hirad::study::run::slurm::{self, SlurmJob, SlurmOptions};
use hirad::study::run::{Job, Study, StudyConfig};
use hirad::study::store::Store;
use std::path::{Path, PathBuf};
use std::process::Command;

/// The flags of `--slurm`.
#[derive(clap::Args, Debug, Default)]
pub struct SlurmArgs {
    /// Write the unfinished units as a Slurm job array (DIR/slurm/study.sbatch, one task per
    /// unit, the references as a first job the others depend on) instead of running them.
    #[arg(long)]
    pub slurm: bool,
    /// With --slurm: submit the script with `sbatch` and print the job ids.
    #[arg(long, requires = "slurm")]
    pub submit: bool,
    /// With --slurm: the partition (sbatch --partition) [default: the cluster's].
    #[arg(long, requires = "slurm")]
    pub partition: Option<String>,
    /// With --slurm: time limit per task (sbatch --time, e.g. 2:00:00) [default: the cluster's].
    #[arg(long, requires = "slurm")]
    pub time: Option<String>,
    /// With --slurm: memory per task (sbatch --mem, e.g. 8G) [default: the cluster's].
    #[arg(long, requires = "slurm")]
    pub mem: Option<String>,
    /// With --slurm: CPUs per task, also its worker threads [default: the cluster's, 1].
    #[arg(long, requires = "slurm")]
    pub cpus: Option<u32>,
    /// With --slurm: the `hirad` binary the tasks run [default: this one].
    #[arg(long, requires = "slurm")]
    pub slurm_exe: Option<PathBuf>,
}

/// Merge the finished units of the study's Slurm tasks into its directory and, when there are
/// tasks, print where the units stand. Returns true when there were tasks.
pub fn collect(study: &Study, quiet: bool) -> anyhow::Result<bool> {
    if slurm::task_dirs(&study.cfg.out).is_empty() {
        return Ok(false);
    }
    let n = study.collect_tasks()?;
    let st = study.status(&study.plan()?);
    if !quiet || !st.missing().is_empty() {
        eprintln!("Slurm tasks: {n} new files collected; {}", st.summary());
    }
    Ok(true)
}

/// After `hirad study merge`: the units of the study in `dir` that are still missing (best
/// effort: skipped with a note when its scene cannot be loaded from here).
pub fn report_missing(dir: &Path) {
    let store = Store::new(dir);
    let Some(cfg) = store.get::<StudyConfig>("config") else {
        return;
    };
    // Its ε series would need probe solves: not for a merge.
    if cfg.eps_list.is_empty() && cfg.tolerances > 0 && cfg.eps_auto && !store.has("calibrate") {
        eprintln!("note: not checking for missing units: the study's ε range is not calibrated");
        return;
    }
    let progress = hirad::progress::NoProgress;
    let cancel = std::sync::atomic::AtomicBool::new(false);
    let r = Study::new(cfg, &progress, &cancel).and_then(|s| Ok(s.status(&s.plan()?)));
    match r {
        Ok(st) => eprintln!("{}", st.summary()),
        Err(e) => eprintln!("note: not checking for missing units: {e}"),
    }
}

/// Every argument of this invocation after `study`, without the ones that differ per task or
/// only concern this invocation.
fn task_args() -> Vec<String> {
    const WITH_VALUE: &[&str] = &[
        "--out",
        "--only",
        "--partition",
        "--time",
        "--mem",
        "--cpus",
        "--slurm-exe",
        "--threads",
    ];
    const FLAGS: &[&str] = &[
        "--slurm",
        "--submit",
        "--jobs",
        "--report",
        "--json",
        "-q",
        "--quiet",
        "--verbose",
    ];
    let mut args: Vec<String> = std::env::args().skip(1).collect();
    if let Some(i) = args.iter().position(|x| x == "study") {
        args.remove(i);
    }
    let mut out = Vec::new();
    let mut it = args.into_iter();
    while let Some(x) = it.next() {
        let name = x.split('=').next().unwrap_or("");
        if WITH_VALUE.contains(&name) {
            if !x.contains('=') {
                it.next();
            }
        } else if !(FLAGS.contains(&x.as_str())
            || (x.starts_with("-v") && x[1..].chars().all(|c| c == 'v')))
        {
            out.push(x);
        }
    }
    out
}

/// Write `DIR/slurm/study.sbatch` and `units.txt` for the units not done yet; with
/// `--submit`, submit them and print the job ids.
pub fn write_and_submit(a: &super::study::Args, study: &Study, quiet: bool) -> anyhow::Result<()> {
    let s = &a.slurm;
    // The ε series is fixed here (calibrating if needed) and passed to every task.
    let eps = study.eps()?;
    let jobs = study.plan()?;
    let st = study.status(&jobs);
    let todo: Vec<&Job> = jobs
        .iter()
        .filter(|j| !st.done.contains(&j.key()))
        .collect();
    if todo.is_empty() {
        eprintln!("every unit is done; nothing to submit");
        return Ok(());
    }
    let out = std::fs::canonicalize(&a.out)?;
    let slurm_dir = out.join("slurm");
    if s.submit {
        refuse_if_queued(&slurm_dir)?;
    }
    let (refs, rest): (Vec<&Job>, Vec<&Job>) = todo
        .into_iter()
        .partition(|j| matches!(j, Job::Reference(_)));
    let mut args = task_args();
    if !eps.is_empty() && a.eps_list.is_empty() {
        let list: Vec<String> = eps.iter().map(|e| format!("{e:e}")).collect();
        args.push("--eps-list".into());
        args.push(list.join(","));
    }
    let exe = match &s.slurm_exe {
        Some(p) => std::path::absolute(p)?,
        None => std::env::current_exe()?,
    };
    let stem = Path::new(&study.cfg.scene)
        .file_stem()
        .map(|n| n.to_string_lossy().to_string())
        .unwrap_or_else(|| "study".into());
    let job = SlurmJob {
        exe,
        args,
        out: out.clone(),
        workdir: std::env::current_dir()?,
        name: format!("hirad-{stem}"),
        units: refs.iter().chain(rest.iter()).map(|j| j.key()).collect(),
        references: refs.len(),
    };
    let opts = SlurmOptions {
        partition: s.partition.clone(),
        time: s.time.clone(),
        mem: s.mem.clone(),
        cpus: s.cpus,
    };
    std::fs::create_dir_all(slurm_dir.join("logs"))?;
    hirad::io::write_bytes_atomic(
        &slurm_dir.join("units.txt"),
        (job.units.join("\n") + "\n").as_bytes(),
    )?;
    let path = slurm::script_path(&out);
    hirad::io::write_bytes_atomic(&path, slurm::script(&job, &opts).as_bytes())?;
    let (sub_refs, sub_rest) = slurm::submissions(&job);
    if !s.submit {
        println!("{}", path.display());
        if !quiet {
            eprintln!(
                "{} units ({} references); submit with:",
                job.units.len(),
                job.references
            );
            if let Some(r) = &sub_refs {
                eprintln!("  refs=$(sbatch {})", r.join(" "));
            }
            if let Some(r) = &sub_rest {
                eprintln!("  sbatch {}", r.join(" ").replace("{refs}", "$refs"));
            }
            eprintln!(
                "then rerun this command without --slurm (or `hirad study merge`) to collect"
            );
        }
        return Ok(());
    }
    let mut ids = Vec::new();
    let ref_id = match sub_refs {
        Some(r) => {
            let id = sbatch(&r)?;
            println!("{id} references ({})", job.references);
            ids.push(id.clone());
            Some(id)
        }
        None => None,
    };
    if let Some(r) = sub_rest {
        let r: Vec<String> = r
            .into_iter()
            .map(|x| x.replace("{refs}", ref_id.as_deref().unwrap_or("")))
            .collect();
        let id = sbatch(&r)?;
        println!("{id} units ({})", job.units.len() - job.references);
        ids.push(id);
    }
    let mut log = std::fs::read_to_string(slurm_dir.join("jobs.txt")).unwrap_or_default();
    for id in &ids {
        log.push_str(id);
        log.push('\n');
    }
    hirad::io::write_bytes_atomic(&slurm_dir.join("jobs.txt"), log.as_bytes())?;
    if !quiet {
        eprintln!(
            "submitted {} units; logs in {}; rerun without --slurm to collect",
            job.units.len(),
            slurm_dir.join("logs").display()
        );
    }
    Ok(())
}

/// Run `sbatch ARGS` (with `--parsable`) and return the job id.
fn sbatch(args: &[String]) -> anyhow::Result<String> {
    let o = Command::new("sbatch")
        .args(args)
        .output()
        .map_err(|e| anyhow::anyhow!("cannot run sbatch: {e} (is Slurm installed here?)"))?;
    anyhow::ensure!(
        o.status.success(),
        "sbatch {} failed: {}",
        args.join(" "),
        String::from_utf8_lossy(&o.stderr).trim()
    );
    let text = String::from_utf8_lossy(&o.stdout);
    // `--parsable` prints `id` or `id;cluster`.
    let id = text.trim().split(';').next().unwrap_or("").to_string();
    anyhow::ensure!(!id.is_empty(), "sbatch printed no job id");
    Ok(id)
}

/// An error when jobs submitted earlier for this study are still queued or running (their
/// units would run twice); nothing is checked when `squeue` is not available.
fn refuse_if_queued(slurm_dir: &Path) -> anyhow::Result<()> {
    let ids: Vec<String> = std::fs::read_to_string(slurm_dir.join("jobs.txt"))
        .unwrap_or_default()
        .lines()
        .map(str::to_string)
        .collect();
    if ids.is_empty() {
        return Ok(());
    }
    let Ok(o) = Command::new("squeue")
        .args(["-h", "-o", "%A", "-j", &ids.join(",")])
        .output()
    else {
        return Ok(());
    };
    let active: Vec<String> = String::from_utf8_lossy(&o.stdout)
        .lines()
        .map(str::to_string)
        .collect();
    anyhow::ensure!(
        active.is_empty(),
        "jobs of this study are still queued or running ({}); wait for them or scancel them, \
         then resubmit",
        active.join(", ")
    );
    Ok(())
}
