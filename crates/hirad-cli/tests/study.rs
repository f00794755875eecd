//! `hirad study`: a small study on the built-in Cornell box is resumable (finished units are
//! skipped, an interrupted run leaves no partial file) and gives the same results as an
//! uninterrupted run; `--jobs` lists one command per unit; `merge` combines directories.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant, SystemTime};

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
    "4",
    "--size",
    "40x30",
    "--repeat",
    "1",
    "-q",
];

fn hirad(out: &Path, extra: &[&str]) -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_hirad"));
    c.args(ARGS).arg("--out").arg(out).args(extra);
    c
}

fn files(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).into_iter().flatten().flatten() {
            let p = e.path();
            if p.is_dir() {
                stack.push(p);
            } else {
                out.push(p);
            }
        }
    }
    out.sort();
    out
}

fn mtimes(dir: &Path, sub: &str) -> Vec<(PathBuf, SystemTime)> {
    files(&dir.join(sub))
        .into_iter()
        .map(|p| {
            let t = std::fs::metadata(&p).unwrap().modified().unwrap();
            (p, t)
        })
        .collect()
}

/// (strategy, eps, elements, links, errors) of every solve record: everything but timings.
fn solve_results(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = files(&dir.join("solve"))
        .into_iter()
        .filter(|p| p.extension().is_some_and(|e| e == "json"))
        .map(|p| {
            let j: serde_json::Value =
                serde_json::from_str(&std::fs::read_to_string(&p).unwrap()).unwrap();
            format!(
                "{} {} {} {} {}",
                j["strategy"], j["eps"], j["elements"], j["links"], j["errors"]
            )
        })
        .collect();
    v.sort();
    v
}

#[test]
fn study_is_resumable_and_reproducible() {
    let tmp = tempfile::tempdir().unwrap();
    // Uninterrupted run.
    let a = tmp.path().join("a");
    let st = hirad(&a, &["--report"]).status().unwrap();
    assert!(st.success());
    let full = solve_results(&a);
    assert_eq!(full.len(), 6, "{full:?}");
    for f in [
        "report.md",
        "report.html",
        "sweep.csv",
        "clusters.csv",
        "raybench.csv",
        "results.json",
    ] {
        assert!(a.join(f).is_file(), "{f} missing");
    }
    assert!(a.join("plots/time_error.png").is_file());
    let csv = std::fs::read_to_string(a.join("sweep.csv")).unwrap();
    assert_eq!(csv.lines().count(), 7, "{csv}");

    // Partial run (one strategy only), then the full run: the finished units are not redone.
    let b = tmp.path().join("b");
    let st = hirad(&b, &["--only", "solve/kdt"]).status().unwrap();
    assert!(st.success());
    assert_eq!(solve_results(&b).len(), 3);
    let before = mtimes(&b, "solve/kdt");
    std::thread::sleep(Duration::from_millis(20));
    let st = hirad(&b, &[]).status().unwrap();
    assert!(st.success());
    assert_eq!(
        mtimes(&b, "solve/kdt"),
        before,
        "finished units were redone"
    );
    assert_eq!(
        solve_results(&b),
        full,
        "resumed study differs from the uninterrupted one"
    );

    // A run killed in the middle leaves only complete files; the rerun completes it.
    let c = tmp.path().join("c");
    let mut child = hirad(&c, &[]).spawn().unwrap();
    let t0 = Instant::now();
    while t0.elapsed() < Duration::from_secs(120) {
        if files(&c.join("solve"))
            .iter()
            .any(|p| p.extension().is_some_and(|e| e == "json"))
        {
            break;
        }
        if child.try_wait().unwrap().is_some() {
            break;
        }
        std::thread::sleep(Duration::from_millis(2));
    }
    let _ = child.kill();
    let _ = child.wait();
    for p in files(&c) {
        let name = p.file_name().unwrap().to_string_lossy().to_string();
        if name.ends_with(".json") {
            let text = std::fs::read_to_string(&p).unwrap();
            assert!(
                serde_json::from_str::<serde_json::Value>(&text).is_ok(),
                "{} is not complete JSON",
                p.display()
            );
        }
    }
    let st = hirad(&c, &[]).status().unwrap();
    assert!(st.success());
    assert_eq!(solve_results(&c), full);
}

#[test]
fn jobs_list_and_merge() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("s");
    let o = hirad(&out, &["--jobs"]).output().unwrap();
    assert!(o.status.success());
    let text = String::from_utf8(o.stdout).unwrap();
    let lines: Vec<&str> = text.lines().collect();
    // 2 cluster units, 2 ray units, 1 reference (cornell's default viewpoint... one per camera),
    // 6 solves.
    assert!(
        lines.iter().filter(|l| l.contains("--only solve/")).count() == 6,
        "{text}"
    );
    assert!(lines
        .iter()
        .all(|l| l.contains("--out ") && l.contains("--eps-list")));
    // Run two of the listed jobs in their own directories, then merge.
    let pick: Vec<&str> = lines
        .iter()
        .filter(|l| l.contains("--only clusters/") || l.contains("--only solve/okdt/"))
        .cloned()
        .collect();
    let mut dirs = Vec::new();
    for l in &pick {
        let words: Vec<&str> = l.split_whitespace().collect();
        let st = Command::new(words[0]).args(&words[1..]).status().unwrap();
        assert!(st.success(), "{l}");
        let i = words.iter().position(|w| *w == "--out").unwrap();
        dirs.push(PathBuf::from(words[i + 1]));
    }
    let merged = tmp.path().join("merged");
    let st = Command::new(env!("CARGO_BIN_EXE_hirad"))
        .args(["study", "merge", "--into"])
        .arg(&merged)
        .args(&dirs)
        .arg("-q")
        .status()
        .unwrap();
    assert!(st.success());
    assert_eq!(solve_results(&merged).len(), 3);
    let md = std::fs::read_to_string(merged.join("report.md")).unwrap();
    assert!(md.contains("| kdt |") && md.contains("| okdt |"), "{md}");
}
