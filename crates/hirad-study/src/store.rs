//! Resumable result store of a study: one JSON file per finished unit of work, written
//! atomically when the unit completes. A rerun reads what is there and skips it; a file that
//! does not parse (which atomic writes should make impossible) is treated as missing and redone.

use hirad_core::io::write_json_atomic;
use hirad_core::Result;
use serde::de::DeserializeOwned;
use serde::Serialize;
use std::path::{Path, PathBuf};

/// A directory of finished results addressed by string keys such as `solve/okdt/eps-1e-3`.
#[derive(Clone, Debug)]
pub struct Store {
    dir: PathBuf,
}

impl Store {
    /// A store rooted at `dir` (created on first write).
    pub fn new(dir: impl Into<PathBuf>) -> Store {
        Store { dir: dir.into() }
    }

    /// Root directory.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// File that holds `key`: each `/`-separated part is sanitised to `[A-Za-z0-9._-]`.
    pub fn path(&self, key: &str) -> PathBuf {
        let mut p = self.dir.clone();
        let parts: Vec<&str> = key.split('/').filter(|s| !s.is_empty()).collect();
        for (i, part) in parts.iter().enumerate() {
            let clean: String = part
                .chars()
                .map(|c| {
                    if c.is_ascii_alphanumeric() || matches!(c, '.' | '_' | '-') {
                        c
                    } else {
                        '_'
                    }
                })
                .collect();
            let clean = if clean == "." || clean == ".." {
                "_".to_string()
            } else {
                clean
            };
            // Keys may contain dots (`eps-2.0e-1`): append the extension, never replace.
            p.push(if i + 1 == parts.len() {
                format!("{clean}.json")
            } else {
                clean
            });
        }
        p
    }

    /// Directory that holds the keys under `prefix`.
    fn dir_of(&self, prefix: &str) -> PathBuf {
        let p = self.path(prefix);
        let name = p
            .file_name()
            .map(|n| n.to_string_lossy().to_string())
            .unwrap_or_default();
        p.with_file_name(name.strip_suffix(".json").unwrap_or(&name))
    }

    /// The stored value of `key`, if a complete one exists.
    pub fn get<T: DeserializeOwned>(&self, key: &str) -> Option<T> {
        let text = std::fs::read_to_string(self.path(key)).ok()?;
        match serde_json::from_str(&text) {
            Ok(v) => Some(v),
            Err(e) => {
                tracing::warn!(
                    "ignoring unreadable result {}: {e}",
                    self.path(key).display()
                );
                None
            }
        }
    }

    /// True when `key` is finished: its file exists and is complete JSON (a file that does not
    /// parse is redone, not skipped).
    pub fn has(&self, key: &str) -> bool {
        self.get::<serde_json::Value>(key).is_some()
    }

    /// Store `value` under `key` atomically.
    pub fn put<T: Serialize>(&self, key: &str, value: &T) -> Result<()> {
        write_json_atomic(&self.path(key), value)
    }

    /// Return the stored value of `key`, or compute, store and return it.
    pub fn get_or_run<T, F>(&self, key: &str, run: F) -> Result<(T, bool)>
    where
        T: Serialize + DeserializeOwned,
        F: FnOnce() -> Result<T>,
    {
        if let Some(v) = self.get(key) {
            return Ok((v, true));
        }
        let v = run()?;
        self.put(key, &v)?;
        Ok((v, false))
    }

    /// Every stored key under `prefix` (a directory key), sorted.
    pub fn keys(&self, prefix: &str) -> Vec<String> {
        let mut out: Vec<String> = walk_files(&self.dir_of(prefix), &[])
            .into_iter()
            .filter_map(|p| {
                let rel = p
                    .strip_prefix(&self.dir)
                    .ok()?
                    .to_string_lossy()
                    .replace('\\', "/");
                rel.strip_suffix(".json").map(str::to_string)
            })
            .collect();
        out.sort();
        out
    }
}

/// Every file below `dir` (recursively, sorted), not descending into directories named in
/// `skip_dirs`.
pub fn walk_files(dir: &Path, skip_dirs: &[&str]) -> Vec<PathBuf> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        let Ok(rd) = std::fs::read_dir(&d) else {
            continue;
        };
        for e in rd.flatten() {
            let p = e.path();
            if p.is_dir() {
                if !p
                    .file_name()
                    .is_some_and(|n| skip_dirs.iter().any(|s| n == *s))
                {
                    stack.push(p);
                }
            } else {
                out.push(p);
            }
        }
    }
    out.sort();
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn put_get_skip_and_sanitise() {
        let dir = tempfile::tempdir().unwrap();
        let s = Store::new(dir.path());
        assert_eq!(s.get::<f64>("solve/okdt-p/eps 1e-3"), None);
        let mut calls = 0;
        let (v, cached) = s
            .get_or_run("solve/okdt-p/eps 1e-3", || {
                calls += 1;
                Ok(2.5f64)
            })
            .unwrap();
        assert_eq!((v, cached), (2.5, false));
        let (v, cached) = s
            .get_or_run("solve/okdt-p/eps 1e-3", || {
                calls += 1;
                Ok(9.0f64)
            })
            .unwrap();
        assert_eq!((v, cached, calls), (2.5, true, 1));
        assert!(s.path("a/../b").starts_with(dir.path()));
        assert!(s
            .path("solve/okdt-p/eps 1e-3")
            .ends_with("solve/okdt-p/eps_1e-3.json"));
        assert_eq!(s.keys("solve"), vec!["solve/okdt-p/eps_1e-3".to_string()]);
        // Dots are kept: distinct ε give distinct files.
        s.put("solve/kdt/eps-2.0000e-1", &1.0).unwrap();
        s.put("solve/kdt/eps-2.0000e-2", &2.0).unwrap();
        assert_eq!(s.get::<f64>("solve/kdt/eps-2.0000e-2"), Some(2.0));
        assert_eq!(s.keys("solve/kdt").len(), 2);
        // A corrupt file counts as missing.
        std::fs::write(s.path("bad"), "{not json").unwrap();
        assert_eq!(s.get::<f64>("bad"), None);
        assert!(!s.has("bad") && s.has("solve/kdt/eps-2.0000e-1"));
        // No temporary files are left behind.
        let leftovers = std::fs::read_dir(dir.path().join("solve/okdt-p"))
            .unwrap()
            .filter(|e| {
                e.as_ref()
                    .unwrap()
                    .file_name()
                    .to_string_lossy()
                    .ends_with(".tmp")
            })
            .count();
        assert_eq!(leftovers, 0);
    }
}
