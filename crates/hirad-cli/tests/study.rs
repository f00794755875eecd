//! `hirad study`: a small study on the built-in Cornell box is resumable (finished units are
//! skipped) and gives the same results as an uninterrupted run; a study on the office killed in
//! the middle (SIGINT, SIGKILL) leaves only complete files and its rerun skips the finished units
//! and ends with the uninterrupted run's results; `--jobs` lists one command per unit; `merge`
//! combines directories.

mod study_common;

use std::collections::BTreeSet;
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
    // The references' own noise: a second 4-spp reference of another seed differs from the
    // first, and the report weighs the curves' rises against it.
    let noise: Vec<f64> = files(&a.join("noise"))
        .iter()
        .filter(|p| p.extension().is_some_and(|e| e == "json"))
        .map(|p| {
            let v: serde_json::Value =
                serde_json::from_str(&std::fs::read_to_string(p).unwrap()).unwrap();
            assert_eq!(v["seed"], 2);
            v["delta_e"].as_f64().unwrap()
        })
        .collect();
    assert_eq!(noise.len(), 2, "one per camera");
    assert!(noise.iter().all(|&n| n > 1.0), "{noise:?}");
    let md = std::fs::read_to_string(a.join("report.md")).unwrap();
    assert!(
        md.contains("The references' own noise, RMS ΔE*uv of a second reference")
            && md.contains("| strategy | rises | largest rise | rises above the noise |"),
        "{md}"
    );
    // Without it, no second reference and the report says so.
    let c = tmp.path().join("c");
    let st = hirad(
        &c,
        &["--no-reference-noise", "--report", "--only", "solve/kdt"],
    )
    .status()
    .unwrap();
    assert!(st.success());
    assert!(!c.join("noise").exists());
    let md = std::fs::read_to_string(c.join("report.md")).unwrap();
    assert!(
        md.contains("The references' own noise: not measured."),
        "{md}"
    );

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
    // The merge holds every unit: no job's --only restriction is reported.
    assert!(!md.contains("Only the units"), "{md}");
    // The findings across studies: one column per directory, one row per finding.
    let sum = tmp.path().join("sum");
    let st = Command::new(env!("CARGO_BIN_EXE_hirad"))
        .args(["study", "summary", "--out"])
        .arg(&sum)
        .arg(&merged)
        .arg("-q")
        .status()
        .unwrap();
    assert!(st.success());
    let s = std::fs::read_to_string(sum.join("summary.md")).unwrap();
    assert!(s.contains("| merged (`cornell`) |"), "{s}");
    assert_eq!(s.matches("\n| ").count(), 1 + 5 + 1, "{s}");
    assert!(sum.join("summary.html").is_file());
    // A directory that is not a study is an error, not an empty column.
    let st = Command::new(env!("CARGO_BIN_EXE_hirad"))
        .args(["study", "summary", "--out"])
        .arg(&sum)
        .arg(tmp.path().join("nothing"))
        .arg("-q")
        .status()
        .unwrap();
    assert!(!st.success());
}

/// The kill test's study: the office (3 viewpoints) with one strategy and three ε; the solves
/// take a noticeable time (the smallest ε the longest), so a run caught when its first solve is
/// written still has most of its work ahead.
const KILL_ARGS: &[&str] = &[
    "study",
    "office",
    "--clustering",
    "proxi",
    "--eps-list",
    "0.2,0.1,0.05",
    "--pairs",
    "2000",
    "--spp",
    "4",
    "--size",
    "64x48",
    "--repeat",
    "1",
    "-q",
];

fn office(out: &Path, extra: &[&str]) -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_hirad"));
    c.args(KILL_ARGS).arg("--out").arg(out).args(extra);
    c
}

/// Keys of the finished units in a study directory (the record files, without runs and config).
fn unit_keys(dir: &Path) -> BTreeSet<String> {
    files(dir)
        .into_iter()
        .filter_map(|p| {
            let rel = p
                .strip_prefix(dir)
                .ok()?
                .to_string_lossy()
                .replace('\\', "/");
            let key = rel.strip_suffix(".json")?.to_string();
            [
                "clusters/",
                "raybench/",
                "reference/",
                "noise/",
                "solve/",
                "volume/",
            ]
            .iter()
            .any(|k| key.starts_with(k))
            .then_some(key)
        })
        .collect()
}

fn is_temp(p: &Path) -> bool {
    let n = p.file_name().unwrap().to_string_lossy();
    n.starts_with(".hirad-") && n.ends_with(".tmp")
}

/// Every file but the temporary ones is complete: JSON parses, images decode. Returns the number
/// of temporary files.
fn check_complete(dir: &Path) -> usize {
    let mut temp = 0;
    for p in files(dir) {
        if is_temp(&p) {
            temp += 1;
            continue;
        }
        match p.extension().and_then(|e| e.to_str()) {
            Some("json") => {
                let text = std::fs::read_to_string(&p).unwrap();
                assert!(
                    serde_json::from_str::<serde_json::Value>(&text).is_ok(),
                    "{} is not complete JSON",
                    p.display()
                );
            }
            Some("png") | Some("exr") => {
                let img = hirad::render::Image::read(&p)
                    .unwrap_or_else(|e| panic!("{} does not decode: {e}", p.display()));
                if !p.starts_with(dir.join("plots")) {
                    assert_eq!((img.width, img.height), (64, 48), "{}", p.display());
                }
            }
            _ => {}
        }
    }
    temp
}

/// The run records (`runs/*.json`) of a study directory, oldest first.
fn run_records(dir: &Path) -> Vec<serde_json::Value> {
    let mut v: Vec<serde_json::Value> = files(&dir.join("runs"))
        .into_iter()
        .filter(|p| !is_temp(p))
        .map(|p| serde_json::from_str(&std::fs::read_to_string(p).unwrap()).unwrap())
        .collect();
    v.sort_by(|a, b| {
        a["started_unix"]
            .as_f64()
            .unwrap()
            .total_cmp(&b["started_unix"].as_f64().unwrap())
    });
    v
}

fn key_set(v: &serde_json::Value) -> BTreeSet<String> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|k| k.as_str().unwrap().to_string())
        .collect()
}

/// `sweep.csv` without its timing column.
fn sweep_without_timings(dir: &Path) -> Vec<String> {
    let text = std::fs::read_to_string(dir.join("sweep.csv")).unwrap();
    let header: Vec<&str> = text.lines().next().unwrap().split(',').collect();
    let t = header.iter().position(|h| *h == "solve_s").unwrap();
    text.lines()
        .map(|l| {
            l.split(',')
                .enumerate()
                .filter(|(i, _)| *i != t)
                .map(|(_, x)| x)
                .collect::<Vec<_>>()
                .join(",")
        })
        .collect()
}

/// The solve images of a study directory, by relative path.
fn solve_images(dir: &Path) -> Vec<(PathBuf, Vec<u8>)> {
    files(&dir.join("solve"))
        .into_iter()
        .filter(|p| p.extension().is_some_and(|e| e == "png"))
        .map(|p| {
            (
                p.strip_prefix(dir).unwrap().to_path_buf(),
                std::fs::read(&p).unwrap(),
            )
        })
        .collect()
}

#[cfg(unix)]
#[test]
fn study_killed_midway_resumes_to_the_same_result() {
    use std::os::unix::process::ExitStatusExt;
    let tmp = tempfile::tempdir().unwrap();
    let full_dir = tmp.path().join("full");
    assert!(office(&full_dir, &["--report"]).status().unwrap().success());
    let all_units = unit_keys(&full_dir);
    // 3 references and their 3 noise units, 1 cluster unit, 1 ray unit, 3 solves.
    assert_eq!(all_units.len(), 11, "{all_units:?}");
    let full_runs = run_records(&full_dir);
    assert_eq!(full_runs.len(), 1);
    assert_eq!(full_runs[0]["outcome"], "finished");
    assert_eq!(key_set(&full_runs[0]["computed"]), all_units);
    let full_results = study_common::results_without_timings(&full_dir);
    assert_eq!(full_results["solves"].as_array().unwrap().len(), 3);

    for (name, signal) in [("sigint", libc::SIGINT), ("sigkill", libc::SIGKILL)] {
        let dir = tmp.path().join(name);
        let mut child = office(&dir, &[]).spawn().unwrap();
        // Poll until the first solve is on disk; the run must still be going.
        let t0 = Instant::now();
        loop {
            assert!(
                child.try_wait().unwrap().is_none(),
                "{name}: the study finished before it could be interrupted"
            );
            if unit_keys(&dir).iter().any(|k| k.starts_with("solve/")) {
                break;
            }
            assert!(t0.elapsed() < Duration::from_secs(300), "{name}: no solve");
            std::thread::sleep(Duration::from_millis(1));
        }
        assert!(
            child.try_wait().unwrap().is_none(),
            "{name}: the study finished before it could be interrupted"
        );
        // SAFETY: kill(2) on the pid of our own child, which has not been waited for.
        assert_eq!(unsafe { libc::kill(child.id() as i32, signal) }, 0);
        let status = child.wait().unwrap();
        if signal == libc::SIGINT {
            assert_eq!(status.code(), Some(130), "{name}: {status:?}");
        } else {
            assert_eq!(status.signal(), Some(libc::SIGKILL), "{name}: {status:?}");
        }

        // Only complete files; a SIGINT lets the current write finish and leaves no temporary
        // file, a SIGKILL may leave one (removed by the rerun).
        let temp = check_complete(&dir);
        if signal == libc::SIGINT {
            assert_eq!(temp, 0, "{name}: temporary files left");
        }
        let done = unit_keys(&dir);
        assert!(
            done.iter().any(|k| k.starts_with("solve/")) && done.len() < all_units.len(),
            "{name}: not interrupted midway: {done:?}"
        );
        assert!(done.is_subset(&all_units), "{done:?}");
        let runs = run_records(&dir);
        if signal == libc::SIGINT {
            // The interrupted invocation recorded what it did.
            assert_eq!(runs.len(), 1, "{name}");
            assert_eq!(runs[0]["outcome"], "interrupted");
            assert_eq!(key_set(&runs[0]["computed"]), done);
        } else {
            assert!(runs.is_empty(), "{name}: a killed run cannot record itself");
        }
        let before: Vec<_> = done
            .iter()
            .map(|k| {
                let p = dir.join(format!("{k}.json"));
                (
                    p.clone(),
                    std::fs::metadata(&p).unwrap().modified().unwrap(),
                )
            })
            .collect();

        // The rerun skips exactly the finished units and computes the others.
        assert!(office(&dir, &["--report"]).status().unwrap().success());
        assert_eq!(check_complete(&dir), 0, "{name}: temporary files left");
        let runs = run_records(&dir);
        let last = runs.last().unwrap();
        assert_eq!(last["outcome"], "finished", "{name}");
        assert_eq!(key_set(&last["skipped"]), done, "{name}");
        assert_eq!(
            key_set(&last["computed"]),
            all_units.difference(&done).cloned().collect(),
            "{name}"
        );
        assert_eq!(last["removed_temp"].as_u64().unwrap() as usize, temp);
        for (p, t) in &before {
            assert_eq!(
                std::fs::metadata(p).unwrap().modified().unwrap(),
                *t,
                "{name}: {} was redone",
                p.display()
            );
        }
        assert_eq!(unit_keys(&dir), all_units, "{name}");
        // Same results as the uninterrupted run, timings aside, and the same images.
        assert_eq!(
            study_common::results_without_timings(&dir),
            full_results,
            "{name}"
        );
        assert_eq!(
            sweep_without_timings(&dir),
            sweep_without_timings(&full_dir)
        );
        assert_eq!(solve_images(&dir), solve_images(&full_dir), "{name}");
        let md = std::fs::read_to_string(dir.join("report.md")).unwrap();
        assert!(md.contains("## Runs"), "{md}");
    }
}

/// `--ray-boxes cluster` runs the ray-casting test through the strategies' own boxes: the
/// records, the CSV and the report say so, and the occluded counts equal the default (tight)
/// run's, while kdt (k-d cells as boxes) visits at least as many nodes.
#[test]
fn ray_boxes_choose_the_traversal_boxes() {
    let tmp = tempfile::tempdir().unwrap();
    let rows = |dir: &Path| -> Vec<Vec<String>> {
        let csv = std::fs::read_to_string(dir.join("raybench.csv")).unwrap();
        let mut lines = csv.lines();
        assert_eq!(
            lines.next().unwrap(),
            "scene,strategy,pairs,seed,boxes,build_ms,query_ms,mrays_per_s,occluded,nodes_per_ray,tris_per_ray,sah_mrays_per_s"
        );
        lines
            .map(|l| l.split(',').map(String::from).collect())
            .collect()
    };
    let (t, c) = (tmp.path().join("tight"), tmp.path().join("cluster"));
    let only = ["--only", "raybench", "--report"];
    assert!(hirad(&t, &only).status().unwrap().success());
    let mut args = only.to_vec();
    args.extend(["--ray-boxes", "cluster"]);
    assert!(hirad(&c, &args).status().unwrap().success());
    let (rt, rc) = (rows(&t), rows(&c));
    assert_eq!(rt.len(), 2);
    for (a, b) in rt.iter().zip(&rc) {
        assert_eq!(a[1], b[1]);
        assert_eq!((a[4].as_str(), b[4].as_str()), ("tight", "cluster"));
        // Same occluded count; no more nodes per ray with tight boxes.
        assert_eq!(a[8], b[8]);
        let nodes = |r: &Vec<String>| r[9].parse::<f64>().unwrap();
        assert!(nodes(a) <= nodes(b), "{a:?} {b:?}");
        // Each unit timed `sah` beside its strategy.
        let sah_rate = |r: &Vec<String>| r[11].parse::<f64>().unwrap();
        assert!(sah_rate(a) > 0.0 && sah_rate(b) > 0.0, "{a:?} {b:?}");
    }
    let md = std::fs::read_to_string(c.join("report.md")).unwrap();
    assert!(md.contains("Batch occlusion, cluster boxes"), "{md}");
    let md = std::fs::read_to_string(t.join("report.md")).unwrap();
    assert!(md.contains("Batch occlusion, tight boxes"), "{md}");
}
