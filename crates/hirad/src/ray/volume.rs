//! Volumetric transmittance through a cluster tree (Sillion 1995). Work in progress.
