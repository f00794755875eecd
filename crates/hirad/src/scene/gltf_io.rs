//! Loader for gltf files (not implemented yet).

use super::RawScene;
use crate::{Error, Result};
use std::path::Path;

/// Load a gltf file into raw scene data.
pub fn load(path: &Path) -> Result<RawScene> {
    Err(Error::input(path, "gltf loader not implemented yet"))
}
