//! TOML scene description files (not implemented yet).

use super::{Scene, SceneOptions};
use crate::{Error, Result};
use std::path::Path;

/// Load a TOML scene description.
pub fn load(path: &Path, _opts: &SceneOptions) -> Result<Scene> {
    Err(Error::input(path, "scene files not implemented yet"))
}
