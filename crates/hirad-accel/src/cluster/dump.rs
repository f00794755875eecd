//! Wireframe export of cluster boxes (`hirad clusters --dump FILE --level N|all`): OBJ with line
//! elements (`l`) or ASCII PLY with an `edge` element, chosen by the file extension, written
//! atomically. Each box contributes 8 vertices and 12 edges.

use super::ClusterTree;
use glam::Vec3;
use hirad_core::geom::Aabb;
use hirad_core::{Error, Result};
use std::io::Write;
use std::path::Path;

/// Which boxes to write.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Level {
    /// Every node.
    All,
    /// The nodes of one depth (root = 0).
    Depth(u32),
}

impl std::str::FromStr for Level {
    type Err = Error;
    fn from_str(s: &str) -> Result<Level> {
        if s.eq_ignore_ascii_case("all") {
            return Ok(Level::All);
        }
        s.trim()
            .parse::<u32>()
            .map(Level::Depth)
            .map_err(|_| Error::Config(format!("--level must be a depth or 'all', got '{s}'")))
    }
}

/// Wireframe file formats.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Format {
    /// Wavefront OBJ (`.obj`).
    Obj,
    /// ASCII PLY (`.ply`).
    Ply,
}

impl Format {
    /// The format of a path, by extension (`.obj` or `.ply`).
    pub fn of_path(path: &Path) -> Result<Format> {
        match path
            .extension()
            .and_then(|e| e.to_str())
            .map(|e| e.to_ascii_lowercase())
            .as_deref()
        {
            Some("obj") => Ok(Format::Obj),
            Some("ply") => Ok(Format::Ply),
            _ => Err(Error::Config(format!(
                "{}: dump format must be .obj or .ply",
                path.display()
            ))),
        }
    }
}

/// Edges of a box as pairs of corner indices; corner `k` has x from bit 0, y bit 1, z bit 2.
pub const BOX_EDGES: [(u32, u32); 12] = [
    (0, 1),
    (2, 3),
    (4, 5),
    (6, 7),
    (0, 2),
    (1, 3),
    (4, 6),
    (5, 7),
    (0, 4),
    (1, 5),
    (2, 6),
    (3, 7),
];

/// Corner `k` of a box (see [`BOX_EDGES`]).
#[inline]
pub fn corner(b: &Aabb, k: u32) -> Vec3 {
    Vec3::new(
        if k & 1 == 0 { b.min.x } else { b.max.x },
        if k & 2 == 0 { b.min.y } else { b.max.y },
        if k & 4 == 0 { b.min.z } else { b.max.z },
    )
}

/// Ids of the nodes selected by `level`, in tree order.
pub fn select(tree: &ClusterTree, level: Level) -> Vec<u32> {
    (0..tree.nodes.len() as u32)
        .filter(|&i| match level {
            Level::All => true,
            Level::Depth(d) => tree.nodes[i as usize].depth == d,
        })
        .collect()
}

/// Write the boxes of the nodes selected by `level` to `path` (format by extension); returns
/// the number of boxes written. A level deeper than the tree writes an empty wireframe.
pub fn write_boxes(path: &Path, tree: &ClusterTree, level: Level) -> Result<usize> {
    let format = Format::of_path(path)?;
    let ids = select(tree, level);
    write_atomic_boxes(path, tree, &ids, format)?;
    Ok(ids.len())
}

fn write_atomic_boxes(path: &Path, tree: &ClusterTree, ids: &[u32], format: Format) -> Result<()> {
    hirad_core::io::write_atomic(path, |w| match format {
        Format::Obj => write_obj(w, tree, ids),
        Format::Ply => write_ply(w, tree, ids),
    })
}

fn write_obj(w: &mut dyn Write, tree: &ClusterTree, ids: &[u32]) -> std::io::Result<()> {
    writeln!(
        w,
        "# hirad cluster boxes: strategy {}, {} boxes, groups by depth",
        tree.strategy,
        ids.len()
    )?;
    let mut depth = u32::MAX;
    for (k, &i) in ids.iter().enumerate() {
        let n = &tree.nodes[i as usize];
        if n.depth != depth {
            depth = n.depth;
            writeln!(w, "g depth_{depth}")?;
        }
        for c in 0..8 {
            let p = corner(&n.bbox, c);
            writeln!(w, "v {} {} {}", p.x, p.y, p.z)?;
        }
        let base = 8 * k as u32 + 1;
        for (a, b) in BOX_EDGES {
            writeln!(w, "l {} {}", base + a, base + b)?;
        }
    }
    Ok(())
}

fn write_ply(w: &mut dyn Write, tree: &ClusterTree, ids: &[u32]) -> std::io::Result<()> {
    writeln!(w, "ply\nformat ascii 1.0")?;
    writeln!(w, "comment hirad cluster boxes: strategy {}", tree.strategy)?;
    writeln!(w, "element vertex {}", 8 * ids.len())?;
    writeln!(w, "property float x\nproperty float y\nproperty float z")?;
    writeln!(w, "element edge {}", 12 * ids.len())?;
    writeln!(
        w,
        "property int vertex1\nproperty int vertex2\nproperty int depth"
    )?;
    writeln!(w, "end_header")?;
    for &i in ids {
        let b = &tree.nodes[i as usize].bbox;
        for c in 0..8 {
            let p = corner(b, c);
            writeln!(w, "{} {} {}", p.x, p.y, p.z)?;
        }
    }
    for (k, &i) in ids.iter().enumerate() {
        let base = 8 * k as u32;
        let d = tree.nodes[i as usize].depth;
        for (a, b) in BOX_EDGES {
            writeln!(w, "{} {} {d}", base + a, base + b)?;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cluster::{hand_scene, ClusterConfig, Strategy};

    #[test]
    fn obj_and_ply_wireframes() {
        let p = hand_scene();
        let t = ClusterTree::build_prims(&p, Strategy::Kdt, &ClusterConfig::default());
        let dir = tempfile::tempdir().unwrap();
        let obj = dir.path().join("b.obj");
        assert_eq!(write_boxes(&obj, &t, Level::All).unwrap(), 3);
        let s = std::fs::read_to_string(&obj).unwrap();
        assert_eq!(s.lines().filter(|l| l.starts_with("v ")).count(), 24);
        assert_eq!(s.lines().filter(|l| l.starts_with("l ")).count(), 36);
        assert!(s.contains("g depth_0") && s.contains("g depth_1"));
        // Every edge joins corners differing in one coordinate, with 1-based indices.
        let v: Vec<Vec3> = s
            .lines()
            .filter_map(|l| l.strip_prefix("v "))
            .map(|l| {
                let c: Vec<f32> = l.split(' ').map(|x| x.parse().unwrap()).collect();
                Vec3::new(c[0], c[1], c[2])
            })
            .collect();
        for l in s.lines().filter_map(|l| l.strip_prefix("l ")) {
            let e: Vec<usize> = l.split(' ').map(|x| x.parse().unwrap()).collect();
            let d = v[e[0] - 1] - v[e[1] - 1];
            assert_eq!(d.cmpne(Vec3::ZERO).bitmask().count_ones(), 1, "edge {l}");
        }
        assert_eq!(v[0], Vec3::ZERO);
        assert_eq!(v[7], Vec3::splat(8.0));
        let ply = dir.path().join("b.ply");
        assert_eq!(write_boxes(&ply, &t, Level::Depth(1)).unwrap(), 2);
        let s = std::fs::read_to_string(&ply).unwrap();
        assert!(s.contains("element vertex 16") && s.contains("element edge 24"));
        let body: Vec<&str> = s.split("end_header\n").nth(1).unwrap().lines().collect();
        assert_eq!(body.len(), 16 + 24);
        assert_eq!(body[16], "0 1 1");
        assert!(write_boxes(&dir.path().join("b.txt"), &t, Level::All).is_err());
        assert_eq!("all".parse::<Level>().unwrap(), Level::All);
        assert_eq!("3".parse::<Level>().unwrap(), Level::Depth(3));
        assert!("x".parse::<Level>().is_err());
    }
}
