#![warn(missing_docs)]
//! The paper's experiments as reproducible, resumable sweeps (`experiments.md`).
//!
//! Building blocks: [`store`] (one atomically written JSON file per finished unit of work, so a
//! rerun skips what is done), [`score`] (monotonicity of error curves), [`reach`] (time to an
//! error), [`plot`] (SVG+PNG plots, one colour per strategy).

pub mod plot;
pub mod reach;
pub mod records;
pub mod report;
pub mod run;
pub mod score;
pub mod store;
