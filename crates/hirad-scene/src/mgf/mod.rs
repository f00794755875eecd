//! MGF 2.0 (Materials and Geometry Format, G. Ward, LBNL) loader, written by hand.
//!
//! MGF is the format of the classic radiosity test scenes (RenderPark, Radiance). [`load_with`]
//! splits a file into statements (`parse`: continuation lines, words, line numbers) and runs
//! each entity (`entities`) against the current colour, material and vertex contexts
//! (`context`) under the transform stack (`xf`); polygons are ear-clipped (`triangulate`),
//! curved primitives and prisms tessellated (`shapes`), colours converted to linear sRGB
//! (`colour`). Includes are read relative to the including file (depth limit
//! [`MAX_INCLUDE_DEPTH`], include loops are errors).
//!
//! Errors name the file and line. As mgflib does, an unknown entity (including malformed lines
//! such as a bare `0 0 0` or a stray file path) is reported once per kind with a warning and
//! skipped. MGF has no up axis; the loader says +Z. The entities read, the units of `rd` and
//! `ed` and the two-sided rule are described in `docs/scene-format.md`.

mod colour;
mod context;
mod entities;
mod parse;
mod shapes;
mod triangulate;
mod xf;

pub use colour::{blackbody_xy, spectrum_xy, xy_to_rgb, Xy};

use super::RawScene;
use super::UpAxis;
use context::{Contexts, Mat, MatKey, Vert};
use glam::{DMat4, DVec3};
use hirad_core::{Error, Result};
use parse::{match_xf, statements, At, Stmt};
use std::collections::{HashMap, HashSet};
use std::path::{Path, PathBuf};
use xf::{parse_xf, Xf, XfArgs};

/// Quarter-circle divisions of curved primitives used by [`load`] (RenderPark's default).
pub const DEFAULT_DIVISIONS: usize = 4;
/// Deepest include nesting accepted.
pub const MAX_INCLUDE_DEPTH: usize = 64;
/// Largest scene (triangles) the loader builds before giving up (runaway `xf -a` arrays).
const MAX_TRIANGLES: usize = 20_000_000;

/// An MGF file loaded: the raw scene plus what the scene model has no field for.
#[derive(Clone, Debug)]
pub struct MgfScene {
    /// The scene as the loader built it (up axis +Z, two-sided flag set).
    pub raw: RawScene,
    /// Per material of `raw.materials`: two-sided (`sides 2`, the MGF default).
    pub two_sided: Vec<bool>,
}

impl MgfScene {
    /// True when every material used is two-sided.
    pub fn all_two_sided(&self) -> bool {
        self.two_sided.iter().all(|&t| t)
    }
}

/// Load an MGF file with [`DEFAULT_DIVISIONS`].
pub fn load(path: &Path) -> Result<RawScene> {
    Ok(load_with(path, DEFAULT_DIVISIONS)?.raw)
}

/// Load an MGF file, tessellating curved primitives with `divisions` quarter-circle divisions.
pub fn load_with(path: &Path, divisions: usize) -> Result<MgfScene> {
    if !(1..=64).contains(&divisions) {
        return Err(Error::Config(format!(
            "MGF divisions must be in 1..=64, got {divisions}"
        )));
    }
    let stem = path
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "scene".into());
    let mut l = Loader::new(divisions, stem.clone());
    l.raw.name = stem;
    l.raw.source = Some(path.to_path_buf());
    l.raw.up = UpAxis::Z;
    l.include(path, None, 0)?;
    if !l.clamped.is_empty() {
        tracing::warn!(
            "{}: reflectance rd × colour above 1 clamped in materials: {}",
            path.display(),
            l.clamped.join(", ")
        );
    }
    let two_sided = l.out_two_sided;
    // One-sided emitters (a lamp with `sides 1`) emit from their front in a two-sided solve too.
    l.raw.two_sided = !two_sided.is_empty()
        && two_sided
            .iter()
            .zip(&l.raw.materials)
            .all(|(&t, m)| t || m.is_emitter());
    // Mixed files: the two-sided materials keep their back faces in a one-sided solve.
    l.raw.two_sided_materials = two_sided.clone();
    Ok(MgfScene {
        raw: l.raw,
        two_sided,
    })
}

/// The loader's state while it reads a file and its includes.
struct Loader {
    divisions: usize,
    raw: RawScene,
    out_two_sided: Vec<bool>,
    colours: Contexts<Xy>,
    mats: Contexts<Mat>,
    verts: Contexts<Vert>,
    xf: Vec<Xf>,
    objects: Vec<String>,
    object_ids: HashMap<String, u32>,
    vcache: HashMap<(u64, u64), u32>,
    next_id: u64,
    warned: HashSet<String>,
    includes: Vec<PathBuf>,
    array_depth: usize,
    /// Output materials by (name, ρ, L_e, two-sided).
    out_mats: HashMap<MatKey, u32>,
    stem: String,
    clamped: Vec<String>,
}

impl Loader {
    fn new(divisions: usize, stem: String) -> Self {
        Loader {
            divisions,
            raw: RawScene::default(),
            out_two_sided: Vec::new(),
            colours: Contexts::new(Xy::NEUTRAL),
            mats: Contexts::new(Mat::new("default")),
            verts: Contexts::new(Vert {
                p: DVec3::ZERO,
                n: DVec3::ZERO,
                version: 0,
            }),
            xf: vec![Xf {
                m: DMat4::IDENTITY,
                flip: false,
                id: 0,
            }],
            objects: Vec::new(),
            object_ids: HashMap::new(),
            vcache: HashMap::new(),
            next_id: 1,
            warned: HashSet::new(),
            includes: Vec::new(),
            array_depth: 0,
            out_mats: HashMap::new(),
            stem,
            clamped: Vec::new(),
        }
    }

    fn id(&mut self) -> u64 {
        self.next_id += 1;
        self.next_id
    }

    fn warn_once(&mut self, kind: &str, at: At, msg: &str) {
        if self.warned.insert(kind.to_string()) {
            tracing::warn!("{}:{}: {msg}", at.file.display(), at.line);
        }
    }

    /// Read and run one file under transform `xf` (with `-a` arrays replayed).
    fn include(&mut self, path: &Path, from: Option<(At, XfArgs)>, depth: usize) -> Result<()> {
        let (at, args) = match from {
            Some((at, args)) => (Some(at), Some(args)),
            None => (None, None),
        };
        let io_err = |e: std::io::Error| match at {
            Some(at) => at.err(format!("cannot read include {}: {e}", path.display())),
            None => Error::io(path, e),
        };
        if depth >= MAX_INCLUDE_DEPTH {
            return Err(at.map_or_else(
                || Error::input(path, "include depth limit"),
                |at| {
                    at.err(format!(
                        "includes nested deeper than {MAX_INCLUDE_DEPTH} (including {})",
                        path.display()
                    ))
                },
            ));
        }
        let canon = std::fs::canonicalize(path).map_err(io_err)?;
        if self.includes.contains(&canon) {
            return Err(at.map_or_else(
                || Error::input(path, "include loop"),
                |at| at.err(format!("include loop: {} includes itself", path.display())),
            ));
        }
        // Not a device or FIFO (`i /dev/zero` would read forever).
        if !canon.is_file() {
            return Err(at.map_or_else(
                || Error::input(path, "not a regular file"),
                |at| at.err(format!("include {} is not a regular file", path.display())),
            ));
        }
        let bytes = std::fs::read(path).map_err(io_err)?;
        let text = String::from_utf8_lossy(&bytes);
        let stmts = statements(&text);
        let close = match_xf(path, &stmts)?;
        self.includes.push(canon);
        let r = match args {
            None => self.run(path, &stmts, &close, 0, stmts.len(), depth),
            Some(args) => {
                let at = at.expect("include site");
                self.with_xf(at, &args, &mut |l: &mut Loader| {
                    l.run(path, &stmts, &close, 0, stmts.len(), depth)
                })
            }
        };
        self.includes.pop();
        r
    }

    /// Run statements `i..end` of a file; `close[k]` is the matching bare `xf` of an opening
    /// `xf` at `k`.
    fn run(
        &mut self,
        file: &Path,
        stmts: &[Stmt],
        close: &[usize],
        mut i: usize,
        end: usize,
        depth: usize,
    ) -> Result<()> {
        let base = self.xf.len();
        while i < end {
            let s = &stmts[i];
            let at = At { file, line: s.line };
            let w = &s.words;
            if w[0] == "xf" {
                if w.len() == 1 {
                    // A bare `xf` closes a plain block (array blocks are skipped over below).
                    if self.xf.len() <= base {
                        return Err(at.err("'xf' without a matching opening 'xf'"));
                    }
                    self.xf.pop();
                    i += 1;
                    continue;
                }
                let args = parse_xf(at, &w[1..])?;
                if args.arrays().is_empty() {
                    self.push_xf(at, args.matrix(&[]))?;
                    i += 1;
                    continue;
                }
                let j = close[i];
                self.with_xf(at, &args, &mut |l: &mut Loader| {
                    l.run(file, stmts, close, i + 1, j, depth)
                })?;
                i = j + 1;
                continue;
            }
            self.statement(at, w, depth)?;
            if self.raw.triangles.len() > MAX_TRIANGLES {
                return Err(at.err(format!("more than {MAX_TRIANGLES} triangles")));
            }
            i += 1;
        }
        // Blocks are balanced (checked by `match_xf`), so the stack is back at `base`.
        self.xf.truncate(base);
        Ok(())
    }
}
