//! Loader for ply files (not implemented yet).

use super::RawScene;
use crate::{Error, Result};
use std::path::Path;

/// Load a ply file into raw scene data.
pub fn load(path: &Path) -> Result<RawScene> {
    Err(Error::input(path, "ply loader not implemented yet"))
}
