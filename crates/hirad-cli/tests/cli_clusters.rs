//! `hirad clusters` end to end: JSON statistics, `--bench` samples, `--dump`, `--objects`,
//! exit codes.

use std::process::Command;

fn hirad() -> Command {
    Command::new(env!("CARGO_BIN_EXE_hirad"))
}

fn json(args: &[&str]) -> serde_json::Value {
    let out = hirad().args(args).output().unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).unwrap()
}

#[test]
fn statistics_of_every_strategy() {
    let v = json(&["clusters", "cornell", "--json", "-q"]);
    let rows = v["strategies"].as_array().unwrap();
    let names: Vec<&str> = rows
        .iter()
        .map(|r| r["strategy"].as_str().unwrap())
        .collect();
    assert_eq!(
        names,
        ["kdt", "obt", "okdt", "okdt-p", "tf-oct", "proxi", "sah", "objr"]
    );
    let n = v["triangles"].as_u64().unwrap();
    for r in rows {
        assert_eq!(r["surfaces"].as_u64(), Some(n));
        assert!(r["clusters"].as_u64().unwrap() >= 1);
        assert!(r["build_seconds_single"].as_f64().unwrap() >= 0.0);
        assert!(r["bytes_per_surface"].as_f64().unwrap() < 64.0);
        // Every strategy is compared to proxi, which is in the list.
        assert!(r["percent_of_proxi_parallel"].as_f64().is_some());
    }
    assert_eq!(rows[5]["percent_of_proxi_single"].as_f64(), Some(100.0));
    // okdt is binary.
    assert!(rows[2]["children_per_cluster_max"].as_u64().unwrap() <= 2);
}

#[test]
fn bench_repeats_and_lambda() {
    let v = json(&[
        "clusters",
        "cornell",
        "--clustering",
        "obt,kdt",
        "--lambda",
        "0",
        "--bench",
        "--repeat",
        "3",
        "-q",
    ]);
    assert_eq!(v["repeat"].as_u64(), Some(3));
    assert_eq!(v["config"]["lambda"].as_f64(), Some(0.0));
    let rows = v["strategies"].as_array().unwrap();
    for r in rows {
        assert_eq!(r["samples_single"].as_array().unwrap().len(), 3);
        assert_eq!(r["samples_parallel"].as_array().unwrap().len(), 3);
        assert!(r.get("percent_of_proxi_single").is_none());
    }
    // obt(0) is kdt: same statistics.
    for k in ["clusters", "depth_mean", "overlap", "empty_space_ratio"] {
        assert_eq!(rows[0][k], rows[1][k], "{k}");
    }
}

#[test]
fn dump_writes_wireframes() {
    let d = tempfile::tempdir().unwrap();
    let p = d.path().join("boxes.obj");
    let v = json(&[
        "clusters",
        "cornell",
        "--clustering",
        "okdt,tf-oct",
        "--dump",
        p.to_str().unwrap(),
        "--level",
        "1",
        "--json",
        "-q",
    ]);
    for (name, row) in ["okdt", "tf-oct"]
        .iter()
        .zip(v["strategies"].as_array().unwrap())
    {
        let f = d.path().join(format!("boxes.{name}.obj"));
        let s = std::fs::read_to_string(&f).unwrap();
        let boxes = s.lines().filter(|l| l.starts_with("l ")).count() / 12;
        assert!(boxes >= 1);
        assert!(row["dump"]
            .as_str()
            .unwrap()
            .contains(&format!("({boxes} boxes)")));
        assert!(s.contains("g depth_1") && !s.contains("g depth_0"));
    }
    let ply = d.path().join("all.ply");
    let out = hirad()
        .args(["clusters", "cornell", "--clustering", "kdt", "-q", "--dump"])
        .arg(&ply)
        .output()
        .unwrap();
    assert!(out.status.success());
    let s = std::fs::read_to_string(&ply).unwrap();
    assert!(s.starts_with("ply\n") && s.contains("element edge"));
}

#[test]
fn objects_are_written_coloured_by_object() {
    // objsoup's eleven tessellated objects, each in a colour of its own.
    let d = tempfile::tempdir().unwrap();
    let p = d.path().join("objects.ply");
    let v = json(&[
        "clusters",
        "objsoup:2000",
        "--clustering",
        "proxi",
        "--objects",
        p.to_str().unwrap(),
        "--json",
        "-q",
    ]);
    let m = hirad::scene::export::read_colored_mesh(&p).unwrap();
    assert_eq!(m.triangles.len() as u64, v["triangles"].as_u64().unwrap());
    let mut colours: Vec<[u32; 3]> = m
        .colors
        .iter()
        .map(|c| c.to_array().map(f32::to_bits))
        .collect();
    colours.sort_unstable();
    colours.dedup();
    assert_eq!(colours.len(), 11);
    // A format it cannot write is refused before any work.
    let out = hirad()
        .args(["clusters", "objsoup:2000", "-q", "--objects", "objects.txt"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("objects.txt"));
}

#[test]
fn bad_arguments_exit_2() {
    for args in [
        &["clusters", "cornell", "--lambda", "-1"][..],
        &["clusters", "cornell", "--clustering", "nope"],
        &["clusters", "cornell", "--level", "deep"],
        &["clusters", "cornell", "--dump", "x.txt"],
        &["clusters", "cornell", "--repeat", "0"],
        &["clusters", "no_such_scene_here"],
    ] {
        let out = hirad().args(args).arg("-q").output().unwrap();
        assert_eq!(out.status.code(), Some(2), "{args:?}");
        assert!(out.stdout.is_empty(), "{args:?}");
    }
}
