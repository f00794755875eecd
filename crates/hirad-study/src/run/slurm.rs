//! A study's units as a Slurm job array (`hirad study … --slurm`): the sbatch script
//! ([`script`], a pure function of the units and options), the submission commands, and the
//! collection of the tasks' directories back into the study ([`Study::collect_tasks`],
//! [`Study::status`]).
//!
//! Layout below the study directory `DIR` (on a filesystem shared by the nodes):
//! `slurm/study.sbatch` (the script; array task `i` runs its `i`-th unit, references first;
//! the list is in the script, so that sbatch's copy of it holds when the script is rewritten),
//! `slurm/units.txt` (the same list), `slurm/logs/<job>_<task>.out`, and one study directory per
//! task, `slurm/units/<key with / as __>` ([`task_dir`]), as a study directory holds one
//! process at a time. The references are a first submission of the script; the other units
//! a second one that depends on it (`afterok`) and copies the finished references into its
//! task directory. A rerun without `--slurm`, or `hirad study merge`, merges the task
//! directories into `DIR` and reports what is missing; `--slurm` again lists only that.

use super::plan::Job;
use super::Study;
use crate::records::RunRecord;
use crate::store::Store;
use hirad_core::Result;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// Resources asked for each array task (`None`: the cluster's default).
#[derive(Clone, Debug, Default)]
pub struct SlurmOptions {
    /// `--partition`.
    pub partition: Option<String>,
    /// `--time`, e.g. `1:00:00`.
    pub time: Option<String>,
    /// `--mem`, e.g. `4G`.
    pub mem: Option<String>,
    /// `--cpus-per-task` (also the task's worker threads).
    pub cpus: Option<u32>,
}

/// What the script runs: `exe study <args> --out <task dir> --only <key> -q` per unit.
#[derive(Clone, Debug)]
pub struct SlurmJob {
    /// Absolute path of the `hirad` binary on the nodes.
    pub exe: PathBuf,
    /// The study's arguments after `study` (scene first), without `--out` and `--only`.
    pub args: Vec<String>,
    /// The study directory, absolute.
    pub out: PathBuf,
    /// Working directory of the tasks (relative scene paths are read from there), absolute.
    pub workdir: PathBuf,
    /// Name of the jobs in the queue.
    pub name: String,
    /// Keys of the units to run, references first.
    pub units: Vec<String>,
    /// How many of `units` are references (the first submission).
    pub references: usize,
}

/// `s` quoted for a POSIX shell (unchanged when it needs no quoting).
pub fn sh_quote(s: &str) -> String {
    let plain = !s.is_empty()
        && s.chars()
            .all(|c| c.is_ascii_alphanumeric() || "-_./=:,+@%".contains(c));
    if plain {
        s.to_string()
    } else {
        format!("'{}'", s.replace('\'', r"'\''"))
    }
}

/// `s` as one argument of an `#SBATCH` line, which sbatch splits itself (not a shell): in
/// double quotes, `"` and `\\` escaped, when it holds white space, quotes, a backslash or
/// `#` (which ends the line's arguments outside quotes); unchanged otherwise.
pub fn sbatch_quote(s: &str) -> String {
    if s.is_empty() || s.chars().any(|c| c.is_whitespace() || "\"'\\#".contains(c)) {
        format!("\"{}\"", s.replace('\\', "\\\\").replace('"', "\\\""))
    } else {
        s.to_string()
    }
}

/// The directory of the task that runs unit `key` in study directory `out`.
pub fn task_dir(out: &Path, key: &str) -> PathBuf {
    out.join("slurm").join("units").join(key.replace('/', "__"))
}

/// The script's path in study directory `out`.
pub fn script_path(out: &Path) -> PathBuf {
    out.join("slurm").join("study.sbatch")
}

/// `sbatch` arguments of the two submissions: the references (`None` when there are none)
/// and the other units (`None` when there are none); the second depends on the first, whose
/// id replaces `{refs}`.
pub fn submissions(job: &SlurmJob) -> (Option<Vec<String>>, Option<Vec<String>>) {
    let script = script_path(&job.out).display().to_string();
    let (r, n) = (job.references, job.units.len());
    let refs = (r > 0).then(|| {
        vec![
            "--parsable".into(),
            format!("--array=0-{}", r - 1),
            script.clone(),
        ]
    });
    let rest = (n > r).then(|| {
        let mut v = vec!["--parsable".to_string(), format!("--array={r}-{}", n - 1)];
        if r > 0 {
            v.push("--dependency=afterok:{refs}".into());
            v.push("--kill-on-invalid-dep=yes".into());
        }
        v.push(script.clone());
        v
    });
    (refs, rest)
}

/// The sbatch script of a study's units (written to [`script_path`]).
pub fn script(job: &SlurmJob, opts: &SlurmOptions) -> String {
    let q = |p: &Path| sh_quote(&p.display().to_string());
    let mut s = String::from("#!/bin/bash\n");
    let _ = writeln!(
        s,
        "# hirad study as a Slurm job array, written by `hirad study … --slurm`: {} units,\n\
         # {} of them references. Array task i runs units[i].\n\
         # Submit (what --submit does):",
        job.units.len(),
        job.references
    );
    let (refs, rest) = submissions(job);
    if let Some(r) = &refs {
        let _ = writeln!(s, "#   refs=$(sbatch {})", r.join(" "));
    }
    if let Some(r) = &rest {
        let _ = writeln!(s, "#   sbatch {}", r.join(" ").replace("{refs}", "$refs"));
    }
    let _ = writeln!(
        s,
        "# Collect: rerun the same `hirad study` command without --slurm, or\n\
         #   hirad study merge {}",
        q(&job.out)
    );
    let _ = writeln!(s, "#SBATCH --job-name={}", sbatch_quote(&job.name));
    let _ = writeln!(
        s,
        "#SBATCH --output={}",
        sbatch_quote(&job.out.join("slurm/logs/%A_%a.out").display().to_string())
    );
    let _ = writeln!(
        s,
        "#SBATCH --chdir={}",
        sbatch_quote(&job.workdir.display().to_string())
    );
    let _ = writeln!(s, "#SBATCH --ntasks=1");
    if let Some(c) = opts.cpus {
        let _ = writeln!(s, "#SBATCH --cpus-per-task={c}");
    }
    for (flag, v) in [
        ("partition", &opts.partition),
        ("time", &opts.time),
        ("mem", &opts.mem),
    ] {
        if let Some(v) = v {
            let _ = writeln!(s, "#SBATCH --{flag}={}", sbatch_quote(v));
        }
    }
    let _ = writeln!(s, "set -euo pipefail\nunits=(");
    for u in &job.units {
        let _ = writeln!(s, "  {}", sh_quote(u));
    }
    let _ = writeln!(
        s,
        ")\n\
         out={}\n\
         key=${{units[$SLURM_ARRAY_TASK_ID]:-}}\n\
         if [ -z \"$key\" ]; then echo \"no unit for array task $SLURM_ARRAY_TASK_ID\" >&2; exit 2; fi\n\
         task=\"$out/slurm/units/${{key//\\//__}}\"\n\
         mkdir -p \"$task\"\n\
         echo \"${{SLURM_ARRAY_JOB_ID}}_${{SLURM_ARRAY_TASK_ID}}\" > \"$task/slurm-task\"\n\
         echo \"unit $key on $(hostname) in $task\"\n\
         # Solves compare against the references: copy the finished ones in (hard links if possible).\n\
         if [[ $key != reference/* ]]; then\n\
         \x20 for r in \"$out/reference\" \"$out\"/slurm/units/reference__*/reference; do\n\
         \x20   if [ -d \"$r\" ]; then\n\
         \x20     mkdir -p \"$task/reference\"\n\
         \x20     cp -rln \"$r/.\" \"$task/reference/\" 2>/dev/null || cp -rn \"$r/.\" \"$task/reference/\"\n\
         \x20   fi\n\
         \x20 done\n\
         fi\n\
         export RAYON_NUM_THREADS=\"${{SLURM_CPUS_PER_TASK:-1}}\"",
        q(&job.out)
    );
    let args: Vec<String> = job.args.iter().map(|a| sh_quote(a)).collect();
    let _ = writeln!(
        s,
        "exec {} study {} --out \"$task\" --only \"$key\" -q",
        q(&job.exe),
        args.join(" ")
    );
    s
}

/// Where each planned unit stands after [`Study::collect_tasks`].
#[derive(Clone, Debug, Default, PartialEq)]
pub struct UnitStatus {
    /// Units whose record is in the study directory.
    pub done: Vec<String>,
    /// Units whose task ended without a result: (key, outcome, log file).
    pub failed: Vec<(String, String, Option<PathBuf>)>,
    /// Units whose task started and has no outcome yet (running, or killed by Slurm, e.g. at
    /// its time limit): (key, log file).
    pub unfinished: Vec<(String, Option<PathBuf>)>,
    /// Units without a task directory (never submitted, or still pending).
    pub not_started: Vec<String>,
}

impl UnitStatus {
    /// Keys of every unit that is not done.
    pub fn missing(&self) -> Vec<String> {
        let mut v: Vec<String> = self.failed.iter().map(|f| f.0.clone()).collect();
        v.extend(self.unfinished.iter().map(|f| f.0.clone()));
        v.extend(self.not_started.iter().cloned());
        v
    }

    /// A few lines for the terminal: the counts, then one line per failed or unfinished unit.
    pub fn summary(&self) -> String {
        let n = self.done.len() + self.missing().len();
        let mut s = format!(
            "{} of {n} units done; {} failed, {} started without a result, {} not started",
            self.done.len(),
            self.failed.len(),
            self.unfinished.len(),
            self.not_started.len()
        );
        let log = |l: &Option<PathBuf>| {
            l.as_ref()
                .map(|p| format!(" (log {})", p.display()))
                .unwrap_or_default()
        };
        for (k, o, l) in &self.failed {
            let _ = write!(s, "\n  failed: {k}: {o}{}", log(l));
        }
        for (k, l) in &self.unfinished {
            let _ = write!(s, "\n  no result: {k}{}", log(l));
        }
        s
    }
}

/// The Slurm log of the task whose directory is `dir` (from the id the script writes there).
fn task_log(out: &Path, dir: &Path) -> Option<PathBuf> {
    let id = std::fs::read_to_string(dir.join("slurm-task")).ok()?;
    Some(out.join("slurm/logs").join(format!("{}.out", id.trim())))
}

impl Study<'_> {
    /// Merge the finished units of the Slurm tasks (`slurm/units/*`) into the study directory;
    /// returns how many files were copied.
    pub fn collect_tasks(&self) -> Result<usize> {
        let dirs = task_dirs(&self.cfg.out);
        if dirs.is_empty() {
            return Ok(0);
        }
        super::merge(&self.cfg.out, &dirs)
    }

    /// Where each of `jobs` stands: done in the study directory, or failed, unfinished or not
    /// started according to its task directory.
    pub fn status(&self, jobs: &[Job]) -> UnitStatus {
        let mut st = UnitStatus::default();
        for j in jobs {
            let key = j.key();
            if self.store.has(&key) {
                st.done.push(key);
                continue;
            }
            let dir = task_dir(&self.cfg.out, &key);
            if !dir.is_dir() {
                st.not_started.push(key);
                continue;
            }
            let log = task_log(&self.cfg.out, &dir);
            let store = Store::new(&dir);
            let last = store
                .keys("runs")
                .iter()
                .filter_map(|k| store.get::<RunRecord>(k))
                .max_by(|a, b| a.started_unix.total_cmp(&b.started_unix));
            match last {
                Some(r) if r.outcome != "finished" => st.failed.push((key, r.outcome, log)),
                // Finished, yet its unit is not here: a record that did not parse.
                Some(_) => st
                    .failed
                    .push((key, "finished without its record".into(), log)),
                None => st.unfinished.push((key, log)),
            }
        }
        st
    }
}

/// The task directories below `out/slurm/units`, sorted.
pub fn task_dirs(out: &Path) -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(out.join("slurm").join("units"))
        .into_iter()
        .flatten()
        .flatten()
        .map(|e| e.path())
        .filter(|p| p.is_dir())
        .collect();
    v.sort();
    v
}

#[cfg(test)]
mod tests {
    use super::*;

    fn job(units: &[&str], references: usize) -> SlurmJob {
        SlurmJob {
            exe: "/opt/hirad bin/hirad".into(),
            args: vec!["cornell".into(), "--eps-list".into(), "0.5,0.25".into()],
            out: "/shared/study".into(),
            workdir: "/home/me".into(),
            name: "hirad-cornell".into(),
            units: units.iter().map(|s| s.to_string()).collect(),
            references,
        }
    }

    #[test]
    fn quoting_survives_the_shell() {
        assert_eq!(sh_quote("a/b-c.obj"), "a/b-c.obj");
        assert_eq!(sh_quote("my scene's.obj"), r"'my scene'\''s.obj'");
        assert_eq!(sh_quote(""), "''");
        assert_eq!(sh_quote("$HOME"), "'$HOME'");
        // sbatch's own splitting of #SBATCH lines: double quotes, backslash escapes.
        assert_eq!(sbatch_quote("/home/me/study"), "/home/me/study");
        assert_eq!(sbatch_quote("/home/my study"), r#""/home/my study""#);
        assert_eq!(sbatch_quote(r#"a"b\c#d"#), r#""a\"b\\c#d""#);
    }

    #[test]
    fn script_runs_one_unit_per_task_after_the_references() {
        let j = job(
            &["reference/front", "solve/kdt/eps-5.0000e-1", "clusters/kdt"],
            1,
        );
        let opts = SlurmOptions {
            partition: Some("short".into()),
            cpus: Some(4),
            ..Default::default()
        };
        let s = script(&j, &opts);
        assert!(s.starts_with("#!/bin/bash\n"));
        assert!(s.contains("#SBATCH --partition=short\n"), "{s}");
        assert!(s.contains("#SBATCH --cpus-per-task=4\n"));
        assert!(!s.contains("--time=") && !s.contains("--mem="), "{s}");
        assert!(s.contains("#SBATCH --output=/shared/study/slurm/logs/%A_%a.out\n"));
        assert!(s.contains("#SBATCH --chdir=/home/me\n"));
        // Every #SBATCH line comes before the first command (sbatch stops reading there).
        let first_cmd = s.find("\nset -euo").unwrap();
        assert!(s.rfind("#SBATCH").unwrap() < first_cmd);
        assert!(s.contains(
            "exec '/opt/hirad bin/hirad' study cornell --eps-list 0.5,0.25 --out \"$task\" --only \"$key\" -q\n"
        ), "{s}");
        assert!(s.contains(
            "#   refs=$(sbatch --parsable --array=0-0 /shared/study/slurm/study.sbatch)"
        ));
        assert!(s.contains("#   sbatch --parsable --array=1-2 --dependency=afterok:$refs --kill-on-invalid-dep=yes /shared/study/slurm/study.sbatch"), "{s}");
        // The bash and the Rust side agree on a task's directory.
        assert!(
            s.contains("task=\"$out/slurm/units/${key//\\//__}\""),
            "{s}"
        );
        assert_eq!(
            task_dir(Path::new("/s"), "solve/kdt/eps-5.0000e-1"),
            Path::new("/s/slurm/units/solve__kdt__eps-5.0000e-1")
        );
    }

    #[test]
    fn submissions_skip_what_is_not_needed() {
        let (r, rest) = submissions(&job(&["reference/a", "reference/b"], 2));
        assert_eq!(r.unwrap()[1], "--array=0-1");
        assert!(rest.is_none());
        let (r, rest) = submissions(&job(&["clusters/kdt", "solve/kdt/e"], 0));
        assert!(r.is_none());
        let rest = rest.unwrap();
        assert_eq!(rest[1], "--array=0-1");
        assert!(
            !rest.iter().any(|a| a.starts_with("--dependency")),
            "{rest:?}"
        );
    }

    #[test]
    fn status_tells_failed_from_unfinished_and_not_started() {
        let d = tempfile::tempdir().unwrap();
        let cfg = super::super::StudyConfig {
            scene: "cornell".into(),
            strategies: vec![hirad_accel::cluster::Strategy::Kdt],
            tolerances: 0,
            ray_pairs: 2000,
            out: d.path().join("s"),
            ..Default::default()
        };
        let cancel = std::sync::atomic::AtomicBool::new(false);
        let study = Study::new(cfg, &hirad_core::progress::NoProgress, &cancel).unwrap();
        let jobs = study.plan().unwrap();
        let keys: Vec<String> = jobs.iter().map(|j| j.key()).collect();
        assert_eq!(keys, ["clusters/kdt", "raybench/kdt"]);
        let st = study.status(&jobs);
        assert_eq!(st.not_started, keys);
        // A task that started (killed at its time limit, or still running) ...
        let t = task_dir(&study.cfg.out, "clusters/kdt");
        std::fs::create_dir_all(&t).unwrap();
        std::fs::write(t.join("slurm-task"), "5_0\n").unwrap();
        let st = study.status(&jobs);
        let log = study.cfg.out.join("slurm/logs/5_0.out");
        assert_eq!(
            st.unfinished,
            vec![("clusters/kdt".to_string(), Some(log.clone()))]
        );
        assert_eq!(st.not_started, ["raybench/kdt"]);
        // ... that recorded a failure.
        let rec = RunRecord {
            outcome: "failed: disk full".into(),
            ..Default::default()
        };
        Store::new(&t).put("runs/1-1", &rec).unwrap();
        let st = study.status(&jobs);
        assert_eq!(
            st.failed,
            vec![("clusters/kdt".into(), "failed: disk full".into(), Some(log))]
        );
        assert!(st
            .summary()
            .contains("0 of 2 units done; 1 failed, 0 started without a result, 1 not started"));
        // Collected once done: the unit's record in the task's directory joins the study.
        let mut only = study.cfg.clone();
        only.out = t.clone();
        only.only = vec!["clusters/kdt".into()];
        drop(study);
        let task = Study::new(only, &hirad_core::progress::NoProgress, &cancel).unwrap();
        task.run_all(&mut |_, _, _| {}).unwrap();
        drop(task);
        let cfg = Store::new(d.path().join("s"))
            .get::<super::super::StudyConfig>("config")
            .unwrap();
        let study = Study::new(cfg, &hirad_core::progress::NoProgress, &cancel).unwrap();
        assert!(study.collect_tasks().unwrap() > 0);
        let st = study.status(&jobs);
        assert_eq!(st.done, ["clusters/kdt"]);
        assert_eq!(st.missing(), ["raybench/kdt"]);
    }

    /// The generated script is valid bash and maps array tasks to units and directories as
    /// [`task_dir`] does (run with a stub `hirad` that prints its arguments).
    #[cfg(unix)]
    #[test]
    fn script_maps_tasks_to_units_in_bash() {
        use std::os::unix::fs::PermissionsExt;
        let d = tempfile::tempdir().unwrap();
        let out = d.path().join("study dir");
        let exe = d.path().join("hirad");
        std::fs::write(&exe, "#!/bin/sh\necho \"$@\"\n").unwrap();
        std::fs::set_permissions(&exe, std::fs::Permissions::from_mode(0o755)).unwrap();
        let mut j = job(&["reference/front", "solve/kdt/eps-5.0000e-1"], 1);
        j.exe = exe;
        j.out = out.clone();
        j.workdir = d.path().to_path_buf();
        // The reference task's result, which the solve's task must copy in.
        let rdir = task_dir(&out, "reference/front").join("reference");
        std::fs::create_dir_all(&rdir).unwrap();
        std::fs::write(rdir.join("front.json"), "{}").unwrap();
        let sh = d.path().join("s.sh");
        std::fs::write(&sh, script(&j, &SlurmOptions::default())).unwrap();
        let o = std::process::Command::new("bash")
            .arg(&sh)
            .env("SLURM_ARRAY_TASK_ID", "1")
            .env("SLURM_ARRAY_JOB_ID", "77")
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let text = String::from_utf8(o.stdout).unwrap();
        let t = task_dir(&out, "solve/kdt/eps-5.0000e-1");
        assert!(
            text.contains(&format!(
                "study cornell --eps-list 0.5,0.25 --out {} --only solve/kdt/eps-5.0000e-1 -q",
                t.display()
            )),
            "{text}"
        );
        assert!(t.join("reference/front.json").is_file());
        assert_eq!(
            std::fs::read_to_string(t.join("slurm-task")).unwrap(),
            "77_1\n"
        );
        // Past the last unit: an error, not a run of nothing.
        let o = std::process::Command::new("bash")
            .arg(&sh)
            .env("SLURM_ARRAY_TASK_ID", "2")
            .env("SLURM_ARRAY_JOB_ID", "77")
            .output()
            .unwrap();
        assert_eq!(o.status.code(), Some(2));
    }
}
