//! Merging study directories (`hirad study merge`), e.g. the outputs of `--jobs` run elsewhere.

use super::StudyConfig;
use crate::store::Store;
use hirad_core::{Error, Result};
use std::path::PathBuf;

/// Merge the stores of several study directories into `into` (files already there are kept),
/// each with its Slurm tasks' directories ([`super::slurm::task_dirs`]).
pub fn merge(into: &std::path::Path, dirs: &[PathBuf]) -> Result<usize> {
    let mut copied = 0;
    let mut all = Vec::new();
    for d in dirs {
        all.push(d.clone());
        all.extend(super::slurm::task_dirs(d));
    }
    for d in &all {
        let src = Store::new(d);
        for prefix in [
            "clusters",
            "raybench",
            "reference",
            "noise",
            "solve",
            "volume",
            "runs",
        ] {
            for k in src.keys(prefix) {
                let from = src.path(&k);
                let to = Store::new(into).path(&k);
                if to.exists() {
                    continue;
                }
                let bytes = std::fs::read(&from).map_err(|e| Error::io(&from, e))?;
                hirad_core::io::write_bytes_atomic(&to, &bytes)?;
                copied += 1;
            }
        }
        // Images and references next to the records.
        copy_tree(d, into, &["png", "exr", "svg"])?;
        if !into.join("config.json").exists() {
            // A job's configuration, without the job's `--only`: the merge holds every unit.
            if let Some(mut cfg) = src.get::<StudyConfig>("config") {
                cfg.only.clear();
                cfg.out = into.to_path_buf();
                Store::new(into).put("config", &cfg)?;
            }
        }
    }
    Ok(copied)
}

fn copy_tree(from: &std::path::Path, to: &std::path::Path, exts: &[&str]) -> Result<()> {
    for p in crate::store::walk_files(from, &["plots", "slurm"]) {
        if !p.extension().is_some_and(|x| exts.iter().any(|e| x == *e)) {
            continue;
        }
        let Ok(r) = p.strip_prefix(from) else {
            continue;
        };
        let dst = to.join(r);
        if !dst.exists() {
            let bytes = std::fs::read(&p).map_err(|e| Error::io(&p, e))?;
            hirad_core::io::write_bytes_atomic(&dst, &bytes)?;
        }
    }
    Ok(())
}
