//! Progress reporting hook. The library reports; the CLI draws (indicatif) or stays quiet.

/// Receives progress of long operations. Implementations must be cheap and thread-safe.
pub trait Progress: Sync {
    /// A new phase named `name` with `total` units of work (0 when unknown).
    fn start(&self, name: &str, total: u64);
    /// `n` more units done.
    fn inc(&self, n: u64);
    /// Free-form status of the current phase (e.g. "links 1.2M").
    fn message(&self, _msg: &str) {}
    /// The current phase is finished.
    fn finish(&self);
}

/// Progress sink that ignores everything.
#[derive(Clone, Copy, Debug, Default)]
pub struct NoProgress;

impl Progress for NoProgress {
    fn start(&self, _name: &str, _total: u64) {}
    fn inc(&self, _n: u64) {}
    fn finish(&self) {}
}
