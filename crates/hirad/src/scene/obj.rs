//! Loader for obj files (not implemented yet).

use super::RawScene;
use crate::{Error, Result};
use std::path::Path;

/// Load a obj file into raw scene data.
pub fn load(path: &Path) -> Result<RawScene> {
    Err(Error::input(path, "obj loader not implemented yet"))
}
