//! The hierarchical radiosity solver with clustering (`spec/radiosity.md`).
