//! Replays the fuzzers' stored inputs on stable through the fuzz targets' own entry points
//! (`fuzz/src/lib.rs`, included by path): every file of the committed, minimized corpus
//! (`fuzz/corpus/<target>/`) must load or fail without a panic and in reasonable time, and every
//! input that once crashed, hung or allocated hugely (`tests/fuzz_regressions/<target>/`) must
//! now be a clean error. No single allocation may exceed the fuzzers' `-malloc_limit_mb` (a
//! counting allocator refuses it, which aborts the test).

#[path = "../../../fuzz/src/lib.rs"]
#[allow(dead_code)]
mod fuzz;

use std::alloc::{GlobalAlloc, Layout, System};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::{Duration, Instant};

/// The fuzzers' `-malloc_limit_mb=512`.
const MALLOC_LIMIT: usize = 512 << 20;
/// Largest single allocation seen.
static LARGEST: AtomicUsize = AtomicUsize::new(0);

/// The system allocator, recording the largest request and refusing those over the limit.
struct Limited;

unsafe impl GlobalAlloc for Limited {
    unsafe fn alloc(&self, l: Layout) -> *mut u8 {
        LARGEST.fetch_max(l.size(), Ordering::Relaxed);
        if l.size() > MALLOC_LIMIT {
            return std::ptr::null_mut();
        }
        System.alloc(l)
    }
    unsafe fn alloc_zeroed(&self, l: Layout) -> *mut u8 {
        LARGEST.fetch_max(l.size(), Ordering::Relaxed);
        if l.size() > MALLOC_LIMIT {
            return std::ptr::null_mut();
        }
        System.alloc_zeroed(l)
    }
    unsafe fn realloc(&self, p: *mut u8, l: Layout, new: usize) -> *mut u8 {
        LARGEST.fetch_max(new, Ordering::Relaxed);
        if new > MALLOC_LIMIT {
            return std::ptr::null_mut();
        }
        System.realloc(p, l, new)
    }
    unsafe fn dealloc(&self, p: *mut u8, l: Layout) {
        System.dealloc(p, l)
    }
}

#[global_allocator]
static ALLOC: Limited = Limited;

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// Generous bound for one small input in the test profile on a loaded 2-core machine (the
/// fuzzers' hang limit is 1 s in release builds).
const SLOW: Duration = Duration::from_secs(10);

fn replay(dir: &Path, target: fuzz::Target) -> Vec<(PathBuf, Result<(), String>, Duration)> {
    fuzz::files_in(dir)
        .into_iter()
        .map(|p| {
            let data = std::fs::read(&p).unwrap();
            let t0 = Instant::now();
            let r = std::panic::catch_unwind(|| fuzz::run(target, &data))
                .unwrap_or_else(|_| panic!("{}: the loader panicked", p.display()));
            (p, r, t0.elapsed())
        })
        .collect()
}

#[test]
fn fuzz_corpus_replays_without_panic() {
    let mut total = 0;
    for (name, target) in fuzz::TARGETS {
        let dir = root().join("fuzz/corpus").join(name);
        let runs = replay(&dir, target);
        assert!(!runs.is_empty(), "no corpus in {}", dir.display());
        for (p, _, dt) in &runs {
            assert!(*dt < SLOW, "{}: took {dt:?}", p.display());
        }
        total += runs.len();
    }
    eprintln!(
        "{total} corpus inputs replayed, largest allocation {} bytes",
        LARGEST.load(Ordering::Relaxed)
    );
}

#[test]
fn fuzz_regressions_are_errors() {
    let base = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fuzz_regressions");
    let mut n = 0;
    for (name, target) in fuzz::TARGETS {
        for (p, r, dt) in replay(&base.join(name), target) {
            let msg = r.expect_err(&format!("{}: expected an error", p.display()));
            assert!(!msg.is_empty(), "{}: empty error", p.display());
            assert!(dt < SLOW, "{}: took {dt:?}", p.display());
            n += 1;
        }
    }
    assert!(n > 0, "no regression inputs in {}", base.display());
    eprintln!("{n} regression inputs rejected");
}

#[test]
fn fuzz_unpack_splits_extra_files() {
    let parts = fuzz::unpack(
        "s.obj",
        b"mtllib a.mtl\n@@@ a.mtl\nnewmtl x\n@@@ ../x\nbad\n@@@ b\n",
    );
    let names: Vec<&str> = parts.iter().map(|(n, _)| n.as_str()).collect();
    assert_eq!(names, ["s.obj", "a.mtl", "b"]);
    assert_eq!(parts[0].1, b"mtllib a.mtl");
    assert_eq!(parts[1].1, b"newmtl x");
}
