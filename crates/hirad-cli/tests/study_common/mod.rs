//! Helpers shared by the study tests (`study.rs`, `slurm.rs`).
#![allow(dead_code)]

use std::path::Path;

/// `results.json` without what depends on the clock or the invocation: timings, run metadata,
/// the invocations, and the findings (two of them compare build and ray-casting times).
pub fn results_without_timings(dir: &Path) -> serde_json::Value {
    fn strip(v: &mut serde_json::Value) {
        const TIMING: &[&str] = &[
            "meta",
            "build_ms",
            "query_ms",
            "mrays_per_s",
            "sah_mrays_per_s",
            "solve_s",
            "seconds",
            "volume_s",
            "exact_s",
            "wall_s",
            "runs",
            "findings",
        ];
        match v {
            serde_json::Value::Object(m) => {
                m.retain(|k, _| !TIMING.contains(&k.as_str()));
                m.values_mut().for_each(strip);
            }
            serde_json::Value::Array(a) => a.iter_mut().for_each(strip),
            _ => {}
        }
    }
    let mut v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("results.json")).unwrap()).unwrap();
    strip(&mut v);
    v
}
