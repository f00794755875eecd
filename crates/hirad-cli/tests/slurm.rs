//! `hirad study … --slurm`: the generated script's tasks (run by bash, as Slurm would, one
//! array index each) compute the units; a rerun collects them, names a failed one and lists
//! only it for resubmission; the collected study equals an in-process run except timings.
//! With a Slurm on this machine (`scripts/slurm-local.sh start`) the study also goes through
//! the real scheduler; without one that test is skipped, unless `HIRAD_REQUIRE_SLURM` is set
//! (CI sets it).

mod study_common;

use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::time::{Duration, Instant};

const ARGS: &[&str] = &[
    "study",
    "cornell",
    "--clustering",
    "kdt,okdt",
    "--eps-list",
    "0.5,0.25,0.125",
    "--pairs",
    "2000",
    "--spp",
    "8",
    "--size",
    "64x48",
    "--repeat",
    "1",
    "-q",
];

fn hirad(out: &Path, extra: &[&str]) -> Output {
    let o = Command::new(env!("CARGO_BIN_EXE_hirad"))
        .args(ARGS)
        .arg("--out")
        .arg(out)
        .args(extra)
        .output()
        .unwrap();
    assert!(
        o.status.success(),
        "hirad {extra:?}: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    o
}

fn units(out: &Path) -> Vec<String> {
    std::fs::read_to_string(out.join("slurm/units.txt"))
        .unwrap()
        .lines()
        .map(str::to_string)
        .collect()
}

/// Run array task `i` of the study's script with bash, as slurmd would.
fn run_task(out: &Path, i: usize) -> bool {
    Command::new("bash")
        .arg(out.join("slurm/study.sbatch"))
        .env("SLURM_ARRAY_TASK_ID", i.to_string())
        .env("SLURM_ARRAY_JOB_ID", "900")
        .output()
        .unwrap()
        .status
        .success()
}

fn task_dir(out: &Path, key: &str) -> PathBuf {
    out.join("slurm/units").join(key.replace('/', "__"))
}

#[test]
fn tasks_of_the_script_compute_the_study_and_a_rerun_resubmits_only_the_failed() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("s");
    hirad(&out, &["--slurm"]);
    let keys = units(&out);
    // 2 cluster units, 2 ray units, 2 references (cornell has two cameras), their 2 noise
    // units, 6 solves; the references first (the first submission).
    assert_eq!(keys.len(), 14, "{keys:?}");
    assert!(
        keys[..2].iter().all(|k| k.starts_with("reference/")),
        "{keys:?}"
    );
    let script = std::fs::read_to_string(out.join("slurm/study.sbatch")).unwrap();
    assert!(
        script.contains("--array=0-1") && script.contains("--array=2-13"),
        "{script}"
    );
    assert!(script.contains(&format!(
        "exec {} study cornell",
        env!("CARGO_BIN_EXE_hirad")
    )));

    // One solve cannot write its images: a file stands where its directory goes.
    let bad = "solve/okdt/eps-2.5000e-1";
    let bad_i = keys.iter().position(|k| k == bad).unwrap();
    std::fs::create_dir_all(task_dir(&out, bad)).unwrap();
    std::fs::write(task_dir(&out, bad).join("solve"), "in the way").unwrap();
    for (i, key) in keys.iter().enumerate() {
        assert_eq!(run_task(&out, i), i != bad_i, "task {i} ({key})");
    }
    assert!(!run_task(&out, keys.len()), "a task past the last unit");

    // The rerun with --slurm collects the thirteen, names the failed one and lists only it.
    let o = hirad(&out, &["--slurm"]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("13 of 14 units done; 1 failed"), "{err}");
    assert!(err.contains(&format!("failed: {bad}: failed:")), "{err}");
    assert!(err.contains("slurm/logs/900_"), "{err}");
    assert_eq!(units(&out), vec![bad.to_string()]);
    let script = std::fs::read_to_string(out.join("slurm/study.sbatch")).unwrap();
    assert!(
        !script.contains("--dependency"),
        "references are done: {script}"
    );

    std::fs::remove_file(task_dir(&out, bad).join("solve")).unwrap();
    assert!(run_task(&out, 0));
    let o = Command::new(env!("CARGO_BIN_EXE_hirad"))
        .args(["study", "merge"])
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("14 of 14 units done; 0 failed"), "{err}");

    let local = tmp.path().join("local");
    hirad(&local, &["--report"]);
    assert_eq!(
        study_common::results_without_timings(&out),
        study_common::results_without_timings(&local),
        "the tasks' study differs from the in-process one"
    );
    // Nothing is left to submit.
    let o = hirad(&out, &["--slurm"]);
    assert!(String::from_utf8_lossy(&o.stderr).contains("nothing to submit"));
}

fn slurm_ready() -> bool {
    let ok = Command::new("sinfo")
        .args(["-h", "-o", "%T"])
        .output()
        .is_ok_and(|o| o.status.success() && !o.stdout.is_empty());
    assert!(
        ok || std::env::var_os("HIRAD_REQUIRE_SLURM").is_none(),
        "HIRAD_REQUIRE_SLURM is set but `sinfo` reaches no Slurm: run scripts/slurm-local.sh start"
    );
    if !ok {
        eprintln!("note: no Slurm answers `sinfo` here (scripts/slurm-local.sh start): skipped");
    }
    ok
}

fn text(c: &mut Command) -> String {
    let o = c.output().unwrap();
    String::from_utf8_lossy(&o.stdout).to_string() + &String::from_utf8_lossy(&o.stderr)
}

#[test]
fn study_through_the_local_slurm_equals_the_in_process_study() {
    if !slurm_ready() {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("slurm-study");
    let t0 = Instant::now();
    let o = hirad(&out, &["--slurm", "--submit"]);
    let ids: Vec<String> = String::from_utf8_lossy(&o.stdout)
        .lines()
        .filter_map(|l| l.split_whitespace().next().map(str::to_string))
        .collect();
    assert_eq!(ids.len(), 2, "references and units: {ids:?}");
    println!(
        "--- {}\n{}",
        out.join("slurm/study.sbatch").display(),
        std::fs::read_to_string(out.join("slurm/study.sbatch")).unwrap()
    );
    println!("--- submitted: {}", ids.join(", "));
    let fmt = "%.18i %.9P %.14j %.8T %.6M %R";
    let mut last = String::new();
    loop {
        let q = text(Command::new("squeue").args(["-j", &ids.join(","), "-o", fmt]));
        if q != last {
            print!("--- squeue at {:.1} s\n{q}", t0.elapsed().as_secs_f64());
            last = q;
        }
        let active = text(Command::new("squeue").args(["-h", "-j", &ids.join(","), "-o", "%i"]));
        if active.trim().is_empty() || active.contains("Invalid job id") {
            break;
        }
        assert!(
            t0.elapsed() < Duration::from_secs(900),
            "the jobs did not end"
        );
        std::thread::sleep(Duration::from_millis(500));
    }
    let wall = t0.elapsed().as_secs_f64();
    // Accounting (when slurmdbd runs) records the last tasks a moment after they leave the queue.
    let mut acct = String::new();
    for _ in 0..20 {
        acct = text(Command::new("sacct").args([
            "-j",
            &ids.join(","),
            "-X",
            "-o",
            "JobID%14,JobName%14,Partition,State,Elapsed,ExitCode",
        ]));
        if acct.matches("COMPLETED").count() >= 14 || acct.contains("disabled") {
            break;
        }
        std::thread::sleep(Duration::from_millis(250));
    }
    println!("--- sacct\n{acct}");

    let o = Command::new(env!("CARGO_BIN_EXE_hirad"))
        .args(["study", "merge"])
        .arg(&out)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    println!("--- hirad study merge\n{err}");
    assert!(o.status.success());
    assert!(err.contains("14 of 14 units done; 0 failed"), "{err}");
    let logs = std::fs::read_dir(out.join("slurm/logs")).unwrap().count();
    assert_eq!(logs, 14, "one log per task");

    let local = tmp.path().join("local");
    let t1 = Instant::now();
    hirad(&local, &["--report"]);
    let local_s = t1.elapsed().as_secs_f64();
    assert_eq!(
        study_common::results_without_timings(&out),
        study_common::results_without_timings(&local),
        "the Slurm study differs from the in-process one"
    );
    println!(
        "--- results.json of the Slurm run and of the in-process run: equal except timings \
         (Slurm: submit to last task {wall:.1} s; in-process {local_s:.1} s)"
    );
}
