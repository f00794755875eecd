//! Writing scenes and per-vertex results (OBJ, glTF binary, PLY), atomically.

use crate::{Error, Result};
use glam::Vec3;
use std::path::Path;

/// A triangle mesh with one linear RGB colour per vertex: the exported form of a radiosity
/// solution (colours are radiosity B in W/m²; images show B/π).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ColoredMesh {
    pub positions: Vec<Vec3>,
    pub triangles: Vec<[u32; 3]>,
    pub colors: Vec<Vec3>,
}

/// Write a coloured mesh; the format follows the extension (`.glb`, `.ply`, `.obj`).
pub fn write_colored_mesh(path: &Path, _mesh: &ColoredMesh) -> Result<()> {
    Err(Error::input(path, "mesh export not implemented yet"))
}

/// Read back a coloured mesh written by [`write_colored_mesh`] (`.glb` or `.ply`).
pub fn read_colored_mesh(path: &Path) -> Result<ColoredMesh> {
    Err(Error::input(path, "mesh import not implemented yet"))
}
