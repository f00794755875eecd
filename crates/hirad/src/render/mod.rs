//! Images: pinhole camera, z-buffer rasteriser of per-vertex radiance, path-traced references,
//! EXR and PNG output.
