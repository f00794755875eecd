//! The paper's experiments as reproducible, resumable sweeps (`experiments.md`).
