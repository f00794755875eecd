//! MGF 2.0 (Materials and Geometry Format, G. Ward, LBNL) loader, written by hand.
//!
//! MGF is the format of the classic radiosity test scenes (RenderPark, Radiance). The loader
//! reads the entities `c cxy cspec cct cmix m sides rd td rs ts ed ir v p n f fh sph cyl cone
//! ring torus prism xf i o` and `#` comments, with named templates (`m a = b`), backslash line
//! continuations, includes relative to the including file (depth limit [`MAX_INCLUDE_DEPTH`],
//! include loops are errors) and transforms in every form (`-t -rx -ry -rz -s -mx -my -mz -i N
//! -a N`; `xf -a` blocks are replayed once per array element, nested). Vertices are transformed
//! when geometry references them; a mirroring transform reverses the vertex order so surfaces
//! keep facing outwards. Polygons are ear-clipped in their plane (concave polygons, `fh` holes
//! bridged to the outer contour); curved primitives are tessellated as mgflib does, with
//! `divisions` quarter-circle divisions (default 4, as RenderPark).
//!
//! Materials: colours are CIE xy chromaticities (`cspec`/`cct` spectra are integrated with the
//! CIE 1931 2° observer; `cmix` mixes weighted in Y) converted to linear sRGB with equal-energy
//! white mapped to grey and luminance normalised to 1. ρ = `rd` × colour. `ed` is the diffuse
//! emittance (exitance) in lm/m², so the emitted radiance is L_e = `ed` × colour / π and the
//! emitted power Σ π·L_e·A equals Σ `ed`·A lumens. (The OBJ conversions in `shared/scenes`
//! carry `Ke = ed × colour`, which this crate reads as radiance: π times brighter.) Specular
//! and transmitted components (`rs`, `ts`, `td`) are ignored by the diffuse solver, with one
//! warning per kind. `sides` is recorded per material ([`MgfScene::two_sided`]); a file whose
//! non-emitting materials are all two-sided (the MGF default) makes a two-sided scene
//! ([`RawScene::two_sided`]): solved and path-traced with back faces without `--two-sided`.
//!
//! Errors name the file and line. As mgflib does, an unknown entity (including malformed lines
//! such as a bare `0 0 0` or a stray file path) is reported once per kind with a warning and
//! skipped. MGF has no up axis; the loader says +Z.

use super::{Material, RawScene, UpAxis};
use glam::{DMat3, DMat4, DVec2, DVec3};
use hirad_core::{Error, Result};
use std::collections::{HashMap, HashSet};
use std::path::{Path, PathBuf};

/// Quarter-circle divisions of curved primitives used by [`load`] (RenderPark's default).
pub const DEFAULT_DIVISIONS: usize = 4;
/// Deepest include nesting accepted.
pub const MAX_INCLUDE_DEPTH: usize = 64;
/// Deepest `xf` nesting accepted.
const MAX_XF_DEPTH: usize = 512;
/// Deepest nesting of `xf -a` array blocks (each level recurses).
const MAX_ARRAY_DEPTH: usize = 32;
/// Most elements of one (multi-dimensional) `xf -a` array.
const MAX_ARRAY_ELEMENTS: u64 = 1_000_000;
/// Largest scene (triangles) the loader builds before giving up (runaway `xf -a` arrays).
const MAX_TRIANGLES: usize = 20_000_000;

/// An MGF file loaded: the raw scene plus what the scene model has no field for.
#[derive(Clone, Debug)]
pub struct MgfScene {
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
    Ok(MgfScene {
        raw: l.raw,
        two_sided,
    })
}

// ---------------------------------------------------------------------------------------------
// Colour

/// CIE 1931 2° colour matching functions x̄, ȳ, z̄ at 380, 390, ..., 780 nm.
const CMF: [[f64; 3]; 41] = [
    [0.001368, 0.000039, 0.006450],
    [0.004243, 0.000120, 0.020050],
    [0.014310, 0.000396, 0.067850],
    [0.043510, 0.001210, 0.207400],
    [0.134380, 0.004000, 0.645600],
    [0.283900, 0.011600, 1.385600],
    [0.348280, 0.023000, 1.747060],
    [0.336200, 0.038000, 1.772110],
    [0.290800, 0.060000, 1.669200],
    [0.195360, 0.090980, 1.287640],
    [0.095640, 0.139020, 0.812950],
    [0.032010, 0.208020, 0.465180],
    [0.004900, 0.323000, 0.272000],
    [0.009300, 0.503000, 0.158200],
    [0.063270, 0.710000, 0.078250],
    [0.165500, 0.862000, 0.042160],
    [0.290400, 0.954000, 0.020300],
    [0.433450, 0.994950, 0.008750],
    [0.594500, 0.995000, 0.003900],
    [0.762100, 0.952000, 0.002100],
    [0.916300, 0.870000, 0.001650],
    [1.026300, 0.757000, 0.001100],
    [1.062200, 0.631000, 0.000800],
    [1.002600, 0.503000, 0.000340],
    [0.854450, 0.381000, 0.000190],
    [0.642400, 0.265000, 0.000050],
    [0.447900, 0.175000, 0.000020],
    [0.283500, 0.107000, 0.000000],
    [0.164900, 0.061000, 0.000000],
    [0.087400, 0.032000, 0.000000],
    [0.046770, 0.017000, 0.000000],
    [0.022700, 0.008210, 0.000000],
    [0.011359, 0.004102, 0.000000],
    [0.005790, 0.002091, 0.000000],
    [0.002899, 0.001047, 0.000000],
    [0.001440, 0.000520, 0.000000],
    [0.000690, 0.000249, 0.000000],
    [0.000332, 0.000120, 0.000000],
    [0.000166, 0.000060, 0.000000],
    [0.000083, 0.000030, 0.000000],
    [0.000042, 0.000015, 0.000000],
];

/// Smallest chromaticity y used in conversions (colours of y = 0 have no luminance).
const MIN_Y: f64 = 1e-3;

/// A colour: CIE xy chromaticity.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Xy {
    pub x: f64,
    pub y: f64,
}

impl Xy {
    /// Equal-energy white, the MGF default colour.
    pub const NEUTRAL: Xy = Xy {
        x: 1.0 / 3.0,
        y: 1.0 / 3.0,
    };
}

/// Chromaticity of a spectrum given by `f(λ)` (nm), integrated at 10 nm over 380–780 nm.
/// `None` when the spectrum has no visible energy.
pub fn spectrum_xy(f: impl Fn(f64) -> f64) -> Option<Xy> {
    let mut xyz = [0.0f64; 3];
    for (k, c) in CMF.iter().enumerate() {
        let s = f(380.0 + 10.0 * k as f64);
        for i in 0..3 {
            xyz[i] += s * c[i];
        }
    }
    let sum = xyz[0] + xyz[1] + xyz[2];
    (sum.is_finite() && sum > 0.0 && xyz[1] > 0.0).then(|| Xy {
        x: xyz[0] / sum,
        y: xyz[1] / sum,
    })
}

/// Chromaticity of a blackbody at `kelvin`.
pub fn blackbody_xy(kelvin: f64) -> Option<Xy> {
    const C2: f64 = 1.4388e7; // nm·K
    spectrum_xy(|l| l.powi(-5) / ((C2 / (l * kelvin)).exp() - 1.0))
}

/// Linear sRGB of a chromaticity at luminance 1, equal-energy white mapped to (1, 1, 1);
/// out-of-gamut (negative) channels are clipped to 0 before the luminance is renormalised.
pub fn xy_to_rgb(c: Xy) -> DVec3 {
    let m = |x: f64, y: f64| {
        let xyz = DVec3::new(x / y, 1.0, (1.0 - x - y) / y);
        DVec3::new(
            3.2404542 * xyz.x - 1.5371385 * xyz.y - 0.4985314 * xyz.z,
            -0.9692660 * xyz.x + 1.8760108 * xyz.y + 0.0415560 * xyz.z,
            0.0556434 * xyz.x - 0.2040259 * xyz.y + 1.0572252 * xyz.z,
        )
    };
    let white = m(1.0 / 3.0, 1.0 / 3.0);
    let rgb = (m(c.x, c.y.max(MIN_Y)) / white).max(DVec3::ZERO);
    let lum = rgb.dot(DVec3::new(0.2126, 0.7152, 0.0722));
    if lum > 0.0 && lum.is_finite() {
        rgb / lum
    } else {
        DVec3::ONE
    }
}

// ---------------------------------------------------------------------------------------------
// Contexts

#[derive(Clone, Debug)]
struct Mat {
    name: String,
    rd: f64,
    rd_c: Xy,
    ed: f64,
    ed_c: Xy,
    two_sided: bool,
    /// Index in `raw.materials` of the material as it is now, once geometry used it.
    out: Option<u32>,
}

impl Mat {
    fn new(name: &str) -> Self {
        Mat {
            name: name.to_string(),
            rd: 0.0,
            rd_c: Xy::NEUTRAL,
            ed: 0.0,
            ed_c: Xy::NEUTRAL,
            two_sided: true,
            out: None,
        }
    }
}

#[derive(Clone, Copy, Debug)]
struct Vert {
    p: DVec3,
    n: DVec3,
    /// Unique id of the vertex's current value (cache key of transformed vertices).
    version: u64,
}

/// Named contexts of one kind with a current entry; entry 0 is the unnamed context.
struct Contexts<T> {
    items: Vec<T>,
    names: HashMap<String, usize>,
    cur: usize,
}

impl<T: Clone> Contexts<T> {
    fn new(unnamed: T) -> Self {
        Self {
            items: vec![unnamed],
            names: HashMap::new(),
            cur: 0,
        }
    }
    fn cur(&mut self) -> &mut T {
        &mut self.items[self.cur]
    }
    fn get(&self, name: &str) -> Option<&T> {
        self.names.get(name).map(|&i| &self.items[i])
    }
    /// Make `name` current with value `v` (creating it if needed).
    fn define(&mut self, name: &str, v: T) {
        match self.names.get(name) {
            Some(&i) => {
                self.items[i] = v;
                self.cur = i;
            }
            None => {
                self.items.push(v);
                self.cur = self.items.len() - 1;
                self.names.insert(name.to_string(), self.cur);
            }
        }
    }
}

/// One level of the transform stack.
#[derive(Clone, Copy)]
struct Xf {
    m: DMat4,
    flip: bool,
    id: u64,
}

/// How often a group of `xf` arguments is applied.
#[derive(Clone, Copy)]
enum Count {
    Fixed(u64),
    Array(u64),
}

/// A parsed `xf` argument list: groups of operations, each applied `Count` times in order.
struct XfArgs {
    groups: Vec<(DMat4, Count)>,
}

impl XfArgs {
    fn arrays(&self) -> Vec<u64> {
        self.groups
            .iter()
            .filter_map(|g| match g.1 {
                Count::Array(n) => Some(n),
                Count::Fixed(_) => None,
            })
            .collect()
    }

    /// The matrix for array indices `idx` (one per `-a`).
    fn matrix(&self, idx: &[u64]) -> DMat4 {
        let mut m = DMat4::IDENTITY;
        let mut a = 0;
        for (g, c) in &self.groups {
            let n = match c {
                Count::Fixed(n) => *n,
                Count::Array(_) => {
                    a += 1;
                    idx[a - 1]
                }
            };
            m = pow(*g, n) * m;
        }
        m
    }
}

fn pow(mut b: DMat4, mut n: u64) -> DMat4 {
    let mut r = DMat4::IDENTITY;
    while n > 0 {
        if n & 1 == 1 {
            r = b * r;
        }
        b = b * b;
        n >>= 1;
    }
    r
}

/// One statement: 1-based line of its first physical line and its words.
struct Stmt {
    line: usize,
    words: Vec<String>,
}

/// Split a file into statements (backslash continuations joined, blank lines dropped).
fn statements(text: &str) -> Vec<Stmt> {
    let mut out = Vec::new();
    let mut pending: Option<(usize, String)> = None;
    for (i, raw) in text.lines().enumerate() {
        let line = raw.trim_end_matches('\r');
        let (cont, body) = match line.trim_end().strip_suffix('\\') {
            Some(b) => (true, b),
            None => (false, line),
        };
        let (start, mut acc) = pending.take().unwrap_or((i + 1, String::new()));
        acc.push(' ');
        acc.push_str(body);
        if cont {
            pending = Some((start, acc));
            continue;
        }
        let words: Vec<String> = acc.split_whitespace().map(str::to_string).collect();
        if !words.is_empty() {
            out.push(Stmt { line: start, words });
        }
    }
    if let Some((start, acc)) = pending {
        let words: Vec<String> = acc.split_whitespace().map(str::to_string).collect();
        if !words.is_empty() {
            out.push(Stmt { line: start, words });
        }
    }
    out
}

/// Where a statement is, for messages.
#[derive(Clone, Copy)]
struct At<'a> {
    file: &'a Path,
    line: usize,
}

impl At<'_> {
    fn err(&self, msg: impl Into<String>) -> Error {
        Error::input_at(self.file, self.line, msg)
    }
    fn num(&self, s: &str) -> Result<f64> {
        match s.parse::<f64>() {
            Ok(v) if v.is_finite() => Ok(v),
            _ => Err(self.err(format!("bad number '{s}'"))),
        }
    }
    fn int(&self, s: &str) -> Result<u64> {
        s.parse::<u64>()
            .map_err(|_| self.err(format!("bad count '{s}' (expected an integer >= 0)")))
    }
    fn argc(&self, w: &[String], ok: bool, usage: &str) -> Result<()> {
        if ok {
            Ok(())
        } else {
            Err(self.err(format!(
                "'{}': wrong number of arguments (expected {usage})",
                w[0]
            )))
        }
    }
}

type MatKey = (String, [u32; 3], [u32; 3], bool);

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

    /// Run `body` once per array element of `args`, each with its transform pushed.
    fn with_xf(
        &mut self,
        at: At,
        args: &XfArgs,
        body: &mut dyn FnMut(&mut Loader) -> Result<()>,
    ) -> Result<()> {
        let dims = args.arrays();
        let total: u64 = dims
            .iter()
            .try_fold(1u64, |a, &n| a.checked_mul(n))
            .unwrap_or(u64::MAX);
        if total > MAX_ARRAY_ELEMENTS {
            return Err(at.err(format!("xf array of {total} elements is too large")));
        }
        if !dims.is_empty() {
            if self.array_depth >= MAX_ARRAY_DEPTH {
                return Err(at.err(format!("xf arrays nested deeper than {MAX_ARRAY_DEPTH}")));
            }
            self.array_depth += 1;
        }
        let r = self.each_element(at, args, &dims, total, body);
        if !dims.is_empty() {
            self.array_depth -= 1;
        }
        r
    }

    fn each_element(
        &mut self,
        at: At,
        args: &XfArgs,
        dims: &[u64],
        total: u64,
        body: &mut dyn FnMut(&mut Loader) -> Result<()>,
    ) -> Result<()> {
        let mut idx = vec![0u64; dims.len()];
        for _ in 0..total {
            self.push_xf(at, args.matrix(&idx))?;
            let r = body(self);
            self.xf.pop();
            r?;
            for k in (0..idx.len()).rev() {
                idx[k] += 1;
                if idx[k] < dims[k] {
                    break;
                }
                idx[k] = 0;
            }
        }
        Ok(())
    }

    fn push_xf(&mut self, at: At, local: DMat4) -> Result<()> {
        if self.xf.len() > MAX_XF_DEPTH {
            return Err(at.err(format!("xf nested deeper than {MAX_XF_DEPTH}")));
        }
        let parent = *self.xf.last().expect("xf stack");
        let m = parent.m * local;
        let id = self.id();
        self.xf.push(Xf {
            m,
            flip: DMat3::from_mat4(m).determinant() < 0.0,
            id,
        });
        Ok(())
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

    fn statement(&mut self, at: At, w: &[String], depth: usize) -> Result<()> {
        let e = w[0].as_str();
        if e.starts_with('#') {
            return Ok(());
        }
        let n = w.len() - 1;
        match e {
            "c" => {
                at.argc(w, n <= 3, "c [name [= template]]")?;
                if n == 0 {
                    self.colours.cur = 0;
                    self.colours.items[0] = Xy::NEUTRAL;
                } else {
                    let v =
                        self.template(at, w, |l, name| l.colours.get(name).copied(), Xy::NEUTRAL)?;
                    match v {
                        Some(v) => self.colours.define(&w[1], v),
                        None => self.colours.cur = self.colours.names[&w[1]],
                    }
                }
            }
            "cxy" => {
                at.argc(w, n == 2, "cxy x y")?;
                let (x, y) = (at.num(&w[1])?, at.num(&w[2])?);
                // y = 0 (a line-of-purples colour, hospital/blokken2.mgf) is legal in mgflib;
                // conversions use y ≥ MIN_Y.
                if x < 0.0 || y < 0.0 || x + y > 1.0 {
                    return Err(at.err(format!("illegal chromaticity ({x}, {y})")));
                }
                *self.colours.cur() = Xy { x, y };
            }
            "cspec" => {
                at.argc(w, n >= 4, "cspec lmin lmax v1 v2 ...")?;
                let (l0, l1) = (at.num(&w[1])?, at.num(&w[2])?);
                let vals = w[3..]
                    .iter()
                    .map(|s| at.num(s))
                    .collect::<Result<Vec<_>>>()?;
                if l1 <= l0 {
                    return Err(at.err("illegal spectrum (needs lmin < lmax)"));
                }
                let step = (l1 - l0) / (vals.len() - 1) as f64;
                // Basis spectra (CIE daylight components) have negative values: accepted,
                // as by mgflib; a spectrum without a valid chromaticity becomes neutral.
                let c = spectrum_xy(|l| {
                    if l < l0 || l > l1 {
                        return 0.0;
                    }
                    let t = (l - l0) / step;
                    let k = (t.floor() as usize).min(vals.len() - 2);
                    let f = t - k as f64;
                    vals[k] * (1.0 - f) + vals[k + 1] * f
                })
                .filter(|c| c.x >= 0.0 && c.y > 0.0 && c.x + c.y <= 1.0)
                .unwrap_or_else(|| {
                    self.warn_once(
                        "cspec",
                        at,
                        "spectrum without a valid chromaticity taken as neutral",
                    );
                    Xy::NEUTRAL
                });
                *self.colours.cur() = c;
            }
            "cct" => {
                at.argc(w, n == 1, "cct temperature")?;
                let t = at.num(&w[1])?;
                let c = (t > 0.0)
                    .then(|| blackbody_xy(t))
                    .flatten()
                    .ok_or_else(|| at.err(format!("illegal colour temperature {t}")))?;
                *self.colours.cur() = c;
            }
            "cmix" => {
                at.argc(w, n >= 2 && n.is_multiple_of(2), "cmix w1 c1 w2 c2 ...")?;
                let (mut x, mut y, mut z) = (0.0, 0.0, 0.0);
                for pair in w[1..].chunks_exact(2) {
                    let wt = at.num(&pair[0])?;
                    let c = *self
                        .colours
                        .get(&pair[1])
                        .ok_or_else(|| at.err(format!("undefined colour '{}'", pair[1])))?;
                    let cy = c.y.max(MIN_Y);
                    x += wt * c.x / cy;
                    y += wt;
                    z += wt * (1.0 - c.x - c.y).max(0.0) / cy;
                }
                let sum = x + y + z;
                if !(y > 0.0 && sum > 0.0) {
                    return Err(at.err("cmix weights must sum to a positive value"));
                }
                *self.colours.cur() = Xy {
                    x: x / sum,
                    y: y / sum,
                };
            }
            "m" => {
                at.argc(w, n <= 3, "m [name [= template]]")?;
                if n == 0 {
                    self.mats.cur = 0;
                    self.mats.items[0] = Mat::new("default");
                } else {
                    let v =
                        self.template(at, w, |l, name| l.mats.get(name).cloned(), Mat::new(&w[1]))?;
                    match v {
                        Some(mut v) => {
                            v.name = w[1].clone();
                            v.out = None;
                            self.mats.define(&w[1], v)
                        }
                        None => self.mats.cur = self.mats.names[&w[1]],
                    }
                }
            }
            "sides" => {
                at.argc(w, n == 1, "sides 1|2")?;
                let two = match w[1].as_str() {
                    "1" => false,
                    "2" => true,
                    s => return Err(at.err(format!("sides must be 1 or 2, got '{s}'"))),
                };
                let m = self.mats.cur();
                m.two_sided = two;
                m.out = None;
            }
            "rd" | "ed" => {
                at.argc(w, n == 1, &format!("{e} value"))?;
                let v = at.num(&w[1])?;
                if v < 0.0 || (e == "rd" && v > 1.0) {
                    return Err(at.err(format!("illegal {e} {v}")));
                }
                let c = *self.colours.cur();
                let m = self.mats.cur();
                if e == "rd" {
                    m.rd = v;
                    m.rd_c = c;
                } else {
                    m.ed = v;
                    m.ed_c = c;
                }
                m.out = None;
            }
            "td" | "rs" | "ts" => {
                let want = if e == "td" { 1 } else { 2 };
                at.argc(
                    w,
                    n == want,
                    if e == "td" {
                        "td value"
                    } else {
                        "value roughness"
                    },
                )?;
                let v = at.num(&w[1])?;
                if n == 2 {
                    at.num(&w[2])?;
                }
                if v > 0.0 {
                    self.warn_once(
                        e,
                        at,
                        &format!(
                            "'{e}' (specular or transmitted light) ignored: the solver is diffuse"
                        ),
                    );
                }
            }
            "ir" => {
                at.argc(w, n == 2, "ir n_real n_imag")?;
                at.num(&w[1])?;
                at.num(&w[2])?;
            }
            "v" => {
                at.argc(w, n <= 3, "v [name [= template]]")?;
                let fresh = Vert {
                    p: DVec3::ZERO,
                    n: DVec3::ZERO,
                    version: 0,
                };
                if n == 0 {
                    // The unnamed vertex: never referenced by geometry, reset to the origin.
                    self.verts.cur = 0;
                    self.verts.items[0] = fresh;
                    return Ok(());
                }
                let v = self.template(at, w, |l, name| l.verts.get(name).copied(), fresh)?;
                match v {
                    Some(mut v) => {
                        v.version = self.id();
                        self.verts.define(&w[1], v)
                    }
                    None => self.verts.cur = self.verts.names[&w[1]],
                }
            }
            "p" | "n" => {
                at.argc(w, n == 3, &format!("{e} x y z"))?;
                let v = DVec3::new(at.num(&w[1])?, at.num(&w[2])?, at.num(&w[3])?);
                let id = self.id();
                let cur = self.verts.cur();
                if e == "p" {
                    cur.p = v;
                } else {
                    cur.n = v;
                }
                cur.version = id;
            }
            "f" => {
                at.argc(w, n >= 3, "f v1 v2 v3 ...")?;
                let idx = w[1..]
                    .iter()
                    .map(|s| self.world_vertex(at, s))
                    .collect::<Result<Vec<_>>>()?;
                self.polygon(vec![idx]);
            }
            "fh" => {
                at.argc(w, n >= 3, "fh v1 v2 v3 ... [- v1 v2 v3 ...]")?;
                let mut contours = vec![Vec::new()];
                for s in &w[1..] {
                    if s == "-" {
                        contours.push(Vec::new());
                    } else {
                        let v = self.world_vertex(at, s)?;
                        contours.last_mut().expect("contour").push(v);
                    }
                }
                if contours.iter().any(|c| c.len() < 3) {
                    return Err(at.err("fh: every contour needs at least 3 vertices"));
                }
                self.polygon(contours);
            }
            "sph" => {
                at.argc(w, n == 2, "sph center radius")?;
                let c = self.local_vertex(at, &w[1])?.p;
                let r = at.num(&w[2])?;
                let mesh = sphere(c, r, self.divisions);
                self.emit_mesh(mesh);
            }
            "cyl" | "cone" => {
                let (r1, r2, v2) = if e == "cyl" {
                    at.argc(w, n == 3, "cyl v1 radius v2")?;
                    let r = at.num(&w[2])?;
                    (r, r, &w[3])
                } else {
                    at.argc(w, n == 4, "cone v1 radius1 v2 radius2")?;
                    (at.num(&w[2])?, at.num(&w[4])?, &w[3])
                };
                let a = self.local_vertex(at, &w[1])?.p;
                let b = self.local_vertex(at, v2)?.p;
                if r1 * r2 < 0.0 || (r1 == 0.0 && r2 == 0.0) {
                    return Err(at.err(format!("illegal radii {r1}, {r2}")));
                }
                if let Some(mesh) = cone(a, r1, b, r2, self.divisions) {
                    self.emit_mesh(mesh);
                }
            }
            "ring" => {
                at.argc(w, n == 3, "ring center rmin rmax")?;
                let v = self.local_vertex(at, &w[1])?;
                let (r0, r1) = (at.num(&w[2])?, at.num(&w[3])?);
                if r0 < 0.0 || r1 <= r0 {
                    return Err(at.err(format!("illegal ring radii {r0}, {r1}")));
                }
                let nrm =
                    v.n.try_normalize()
                        .ok_or_else(|| at.err(format!("ring: vertex '{}' has no normal", w[1])))?;
                let mesh = ring(v.p, nrm, r0, r1, self.divisions);
                self.emit_mesh(mesh);
            }
            "torus" => {
                at.argc(w, n == 3, "torus center rmin rmax")?;
                let v = self.local_vertex(at, &w[1])?;
                let (r0, r1) = (at.num(&w[2])?, at.num(&w[3])?);
                if r0 * r1 < 0.0 || r1.abs() <= r0.abs() {
                    return Err(at.err(format!("illegal torus radii {r0}, {r1}")));
                }
                let nrm =
                    v.n.try_normalize()
                        .ok_or_else(|| at.err(format!("torus: vertex '{}' has no normal", w[1])))?;
                let mesh = torus(v.p, nrm, r0, r1, self.divisions);
                self.emit_mesh(mesh);
            }
            "prism" => {
                at.argc(w, n >= 4, "prism v1 v2 v3 ... length")?;
                let len = at.num(&w[n])?;
                let pts = w[1..n]
                    .iter()
                    .map(|s| Ok(self.local_vertex(at, s)?.p))
                    .collect::<Result<Vec<_>>>()?;
                if let Some(mesh) = prism(&pts, len) {
                    self.emit_mesh(mesh);
                }
            }
            "o" => {
                if n == 0 {
                    if self.objects.pop().is_none() {
                        return Err(at.err("'o' without a matching 'o name'"));
                    }
                } else {
                    self.objects.push(w[1].clone());
                }
            }
            "i" => {
                at.argc(w, n >= 1, "i file [xf arguments]")?;
                let dir = at.file.parent().unwrap_or(Path::new(""));
                let path = dir.join(&w[1]);
                let args = if n > 1 {
                    parse_xf(at, &w[2..])?
                } else {
                    XfArgs { groups: Vec::new() }
                };
                self.include(&path, Some((at, args)), depth + 1)?;
            }
            "ies" => {
                self.warn_once(e, at, "'ies' light sources are not supported, skipped");
            }
            _ => {
                let msg = format!("unknown entity '{e}', line skipped");
                self.warn_once(&format!("?{e}"), at, &msg);
            }
        }
        Ok(())
    }

    /// `X name` / `X name =` / `X name = template`: `Some(value)` to define, `None` to make an
    /// existing context current.
    fn template<T>(
        &self,
        at: At,
        w: &[String],
        get: impl Fn(&Loader, &str) -> Option<T>,
        fresh: T,
    ) -> Result<Option<T>> {
        let name = &w[1];
        match w.len() {
            2 => {
                if get(self, name).is_none() {
                    return Err(at.err(format!("undefined {} '{name}'", kind(&w[0]))));
                }
                Ok(None)
            }
            3 | 4 if w[2] == "=" => {
                if w.len() == 3 {
                    return Ok(Some(fresh));
                }
                get(self, &w[3])
                    .map(Some)
                    .ok_or_else(|| at.err(format!("undefined {} '{}'", kind(&w[0]), w[3])))
            }
            _ => Err(at.err(format!(
                "expected '{} name = [template]', got '{}'",
                w[0],
                w.join(" ")
            ))),
        }
    }

    fn local_vertex(&self, at: At, name: &str) -> Result<Vert> {
        self.verts
            .get(name)
            .copied()
            .ok_or_else(|| at.err(format!("undefined vertex '{name}'")))
    }

    /// Output index of vertex `name` under the current transform.
    fn world_vertex(&mut self, at: At, name: &str) -> Result<u32> {
        let v = self.local_vertex(at, name)?;
        let xf = *self.xf.last().expect("xf stack");
        let key = (v.version, xf.id);
        if let Some(&i) = self.vcache.get(&key) {
            return Ok(i);
        }
        let i = self.raw.positions.len() as u32;
        self.raw
            .positions
            .push(xf.m.transform_point3(v.p).as_vec3());
        self.vcache.insert(key, i);
        Ok(i)
    }

    fn material(&mut self) -> u32 {
        let m = self.mats.cur();
        if let Some(i) = m.out {
            return i;
        }
        let mut rho = xy_to_rgb(m.rd_c) * m.rd;
        if rho.max_element() > 1.0 {
            rho = rho.min(DVec3::ONE);
            if !self.clamped.contains(&m.name) {
                self.clamped.push(m.name.clone());
            }
        }
        let emission = xy_to_rgb(m.ed_c) * (m.ed / std::f64::consts::PI);
        let mat = Material {
            name: m.name.clone(),
            rho: rho.as_vec3(),
            emission: emission.as_vec3(),
        };
        let two = m.two_sided;
        // A material defined again with the same values (common in the set) is reused.
        let key = (
            mat.name.clone(),
            mat.rho.to_array().map(f32::to_bits),
            mat.emission.to_array().map(f32::to_bits),
            two,
        );
        let next = self.raw.materials.len() as u32;
        let i = *self.out_mats.entry(key).or_insert(next);
        if i == next {
            // A name defined again with other values gets a suffix: materials are told apart
            // by name downstream (TOML scenes merge meshes' materials by name).
            let mut mat = mat;
            let mut k = 1;
            while self.raw.materials[..i as usize]
                .iter()
                .any(|o| o.name == mat.name)
            {
                k += 1;
                mat.name = format!("{}#{k}", m.name);
            }
            self.raw.materials.push(mat);
            self.out_two_sided.push(two);
        }
        self.mats.cur().out = Some(i);
        i
    }

    fn object(&mut self) -> u32 {
        let name = if self.objects.is_empty() {
            self.stem.clone()
        } else {
            self.objects.join("/")
        };
        if let Some(&i) = self.object_ids.get(&name) {
            return i;
        }
        let i = self.raw.objects.len() as u32;
        self.raw.objects.push(name.clone());
        self.object_ids.insert(name, i);
        i
    }

    fn push_tri(&mut self, t: [u32; 3], mat: u32, obj: u32) {
        self.raw.triangles.push(t);
        self.raw.tri_material.push(mat);
        self.raw.tri_object.push(obj);
    }

    /// Triangulate a polygon (outer contour, then holes) of output vertex indices.
    fn polygon(&mut self, mut contours: Vec<Vec<u32>>) {
        let flip = self.xf.last().expect("xf stack").flip;
        if flip {
            for c in &mut contours {
                c.reverse();
            }
        }
        let pts: Vec<Vec<DVec3>> = contours
            .iter()
            .map(|c| {
                c.iter()
                    .map(|&i| self.raw.positions[i as usize].as_dvec3())
                    .collect()
            })
            .collect();
        let tris = triangulate(&pts);
        if tris.is_empty() {
            return;
        }
        let flat: Vec<u32> = contours.concat();
        let mat = self.material();
        let obj = self.object();
        for t in tris {
            self.push_tri(t.map(|k| flat[k]), mat, obj);
        }
    }

    /// Transform a mesh built in local coordinates and add it.
    fn emit_mesh(&mut self, mesh: Mesh) {
        if mesh.tris.is_empty() {
            return;
        }
        let xf = *self.xf.last().expect("xf stack");
        let base = self.raw.positions.len() as u32;
        self.raw.positions.extend(
            mesh.points
                .iter()
                .map(|&p| xf.m.transform_point3(p).as_vec3()),
        );
        let mat = self.material();
        let obj = self.object();
        for t in mesh.tris {
            let t = t.map(|k| base + k);
            self.push_tri(if xf.flip { [t[0], t[2], t[1]] } else { t }, mat, obj);
        }
    }
}

fn kind(entity: &str) -> &'static str {
    match entity {
        "c" => "colour",
        "m" => "material",
        _ => "vertex",
    }
}

/// For every opening `xf` (with arguments) the index of its matching bare `xf`; errors on
/// unbalanced blocks.
fn match_xf(file: &Path, stmts: &[Stmt]) -> Result<Vec<usize>> {
    let mut close = vec![usize::MAX; stmts.len()];
    let mut open: Vec<usize> = Vec::new();
    for (i, s) in stmts.iter().enumerate() {
        if s.words[0] != "xf" {
            continue;
        }
        if s.words.len() > 1 {
            open.push(i);
        } else {
            match open.pop() {
                Some(o) => close[o] = i,
                None => {
                    return Err(Error::input_at(
                        file,
                        s.line,
                        "'xf' without a matching opening 'xf'",
                    ))
                }
            }
        }
    }
    if let Some(&o) = open.last() {
        return Err(Error::input_at(
            file,
            stmts[o].line,
            "'xf' block not closed by a bare 'xf' before the end of the file",
        ));
    }
    Ok(close)
}

fn parse_xf(at: At, a: &[String]) -> Result<XfArgs> {
    let mut groups = Vec::new();
    let mut m = DMat4::IDENTITY;
    let mut count = Count::Fixed(1);
    let mut i = 0;
    let need = |i: usize, k: usize| -> Result<()> {
        if i + k < a.len() {
            Ok(())
        } else {
            Err(at.err(format!("xf: '{}' needs {k} argument(s)", a[i])))
        }
    };
    while i < a.len() {
        let op = a[i].as_str();
        let step = match op {
            "-t" => {
                need(i, 3)?;
                let t = DVec3::new(at.num(&a[i + 1])?, at.num(&a[i + 2])?, at.num(&a[i + 3])?);
                m = DMat4::from_translation(t) * m;
                4
            }
            "-rx" | "-ry" | "-rz" => {
                need(i, 1)?;
                let r = at.num(&a[i + 1])?.to_radians();
                let rot = match op {
                    "-rx" => DMat4::from_rotation_x(r),
                    "-ry" => DMat4::from_rotation_y(r),
                    _ => DMat4::from_rotation_z(r),
                };
                m = rot * m;
                2
            }
            "-s" => {
                need(i, 1)?;
                let s = at.num(&a[i + 1])?;
                if s == 0.0 {
                    return Err(at.err("xf: zero scale"));
                }
                m = DMat4::from_scale(DVec3::splat(s)) * m;
                2
            }
            "-mx" | "-my" | "-mz" => {
                let s = match op {
                    "-mx" => DVec3::new(-1.0, 1.0, 1.0),
                    "-my" => DVec3::new(1.0, -1.0, 1.0),
                    _ => DVec3::new(1.0, 1.0, -1.0),
                };
                m = DMat4::from_scale(s) * m;
                1
            }
            "-i" | "-a" => {
                need(i, 1)?;
                let n = at.int(&a[i + 1])?;
                groups.push((m, count));
                m = DMat4::IDENTITY;
                count = if op == "-i" {
                    Count::Fixed(n)
                } else {
                    Count::Array(n)
                };
                2
            }
            _ => return Err(at.err(format!("xf: unknown argument '{op}'"))),
        };
        i += step;
    }
    groups.push((m, count));
    Ok(XfArgs { groups })
}

// ---------------------------------------------------------------------------------------------
// Triangulation

/// Ear-clip a planar polygon with holes (`contours[0]` outer, the rest holes); triangle
/// corners index the concatenated contours and keep the outer contour's winding.
fn triangulate(contours: &[Vec<DVec3>]) -> Vec<[usize; 3]> {
    let outer = &contours[0];
    let mut normal = DVec3::ZERO;
    for k in 0..outer.len() {
        let (a, b) = (outer[k], outer[(k + 1) % outer.len()]);
        normal += DVec3::new(
            (a.y - b.y) * (a.z + b.z),
            (a.z - b.z) * (a.x + b.x),
            (a.x - b.x) * (a.y + b.y),
        );
    }
    let ax = normal.abs();
    let k = if ax.x >= ax.y && ax.x >= ax.z {
        0
    } else if ax.y >= ax.z {
        1
    } else {
        2
    };
    if normal[k] == 0.0 || normal[k].is_nan() {
        return Vec::new();
    }
    let (u, v) = if normal[k] > 0.0 {
        ((k + 1) % 3, (k + 2) % 3)
    } else {
        ((k + 2) % 3, (k + 1) % 3)
    };
    let p2: Vec<DVec2> = contours
        .iter()
        .flatten()
        .map(|p| DVec2::new(p[u], p[v]))
        .collect();
    // Index lists per contour, dropping consecutive repeats (a closing vertex equal to the first).
    let mut start = 0;
    let mut rings: Vec<Vec<usize>> = Vec::new();
    for (ci, c) in contours.iter().enumerate() {
        let mut r: Vec<usize> = Vec::with_capacity(c.len());
        for j in start..start + c.len() {
            if r.last().is_none_or(|&l| p2[l] != p2[j]) {
                r.push(j);
            }
        }
        while r.len() > 1 && p2[r[0]] == p2[*r.last().expect("ring")] {
            r.pop();
        }
        start += c.len();
        if ci == 0 && r.len() < 3 {
            return Vec::new();
        }
        if r.len() >= 3 {
            rings.push(r);
        }
    }
    let mut poly = rings.remove(0);
    let area = |r: &[usize]| -> f64 {
        (0..r.len())
            .map(|i| p2[r[i]].perp_dot(p2[r[(i + 1) % r.len()]]))
            .sum::<f64>()
    };
    let (lo, hi) = p2.iter().fold(
        (DVec2::splat(f64::INFINITY), DVec2::splat(f64::NEG_INFINITY)),
        |(lo, hi), p| (lo.min(*p), hi.max(*p)),
    );
    let eps = 1e-12 * (hi - lo).length_squared();
    // Holes: clockwise, rightmost first, each bridged to the polygon built so far.
    for h in &mut rings {
        if area(h) > 0.0 {
            h.reverse();
        }
    }
    rings.sort_by(|a, b| {
        let mx = |r: &Vec<usize>| r.iter().map(|&i| p2[i].x).fold(f64::NEG_INFINITY, f64::max);
        mx(b).total_cmp(&mx(a))
    });
    for hi_ in 0..rings.len() {
        let hole = &rings[hi_];
        let mi = (0..hole.len())
            .max_by(|&a, &b| p2[hole[a]].x.total_cmp(&p2[hole[b]].x))
            .expect("hole");
        let m = p2[hole[mi]];
        let mut best: Option<(f64, usize)> = None;
        let mut fallback: Option<(f64, usize)> = None;
        for (pi, &pv) in poly.iter().enumerate() {
            let d = (p2[pv] - m).length_squared();
            if fallback.is_none_or(|(bd, _)| d < bd) {
                fallback = Some((d, pi));
            }
            if best.is_some_and(|(bd, _)| d >= bd) {
                continue;
            }
            let blocked = |r: &[usize]| {
                (0..r.len()).any(|e| crosses(p2[pv], m, p2[r[e]], p2[r[(e + 1) % r.len()]], eps))
            };
            if blocked(&poly) || rings[hi_..].iter().any(|r| blocked(r)) {
                continue;
            }
            best = Some((d, pi));
        }
        let Some((_, pi)) = best.or(fallback) else {
            continue;
        };
        let mut merged = Vec::with_capacity(poly.len() + hole.len() + 2);
        merged.extend_from_slice(&poly[..=pi]);
        merged.extend(hole[mi..].iter().chain(&hole[..=mi]));
        merged.extend_from_slice(&poly[pi..]);
        poly = merged;
    }
    let mut out = Vec::with_capacity(poly.len().saturating_sub(2));
    ear_clip(&p2, poly, eps, &mut out);
    out
}

/// True when segments ab and cd cross at a point interior to both (shared endpoints and
/// touching do not count).
fn crosses(a: DVec2, b: DVec2, c: DVec2, d: DVec2, eps: f64) -> bool {
    if a == c || a == d || b == c || b == d {
        return false;
    }
    let o = |p: DVec2, q: DVec2, r: DVec2| (q - p).perp_dot(r - p);
    let (d1, d2) = (o(a, b, c), o(a, b, d));
    let (d3, d4) = (o(c, d, a), o(c, d, b));
    ((d1 > eps && d2 < -eps) || (d1 < -eps && d2 > eps))
        && ((d3 > eps && d4 < -eps) || (d3 < -eps && d4 > eps))
}

/// Ear clipping of a counter-clockwise polygon (indices into `p`), n − 2 triangles.
fn ear_clip(p: &[DVec2], mut v: Vec<usize>, eps: f64, out: &mut Vec<[usize; 3]>) {
    while v.len() > 3 {
        let n = v.len();
        let corner = |k: usize| (v[(k + n - 1) % n], v[k], v[(k + 1) % n]);
        let turn = |k: usize| {
            let (a, b, c) = corner(k);
            (p[b] - p[a]).perp_dot(p[c] - p[b])
        };
        let is_ear = |k: usize| {
            let (a, b, c) = corner(k);
            if turn(k) <= eps {
                return false;
            }
            let (pa, pb, pc) = (p[a], p[b], p[c]);
            !v.iter().any(|&j| {
                let q = p[j];
                if q == pa || q == pb || q == pc {
                    return false;
                }
                let e = -eps;
                (pb - pa).perp_dot(q - pa) >= e
                    && (pc - pb).perp_dot(q - pb) >= e
                    && (pa - pc).perp_dot(q - pc) >= e
            })
        };
        let k = (0..n)
            .find(|&k| is_ear(k))
            .or_else(|| (0..n).find(|&k| turn(k).abs() <= eps))
            .unwrap_or_else(|| {
                (0..n)
                    .max_by(|&a, &b| turn(a).total_cmp(&turn(b)))
                    .expect("polygon")
            });
        let (a, b, c) = corner(k);
        out.push([a, b, c]);
        v.remove(k);
    }
    if v.len() == 3 {
        out.push([v[0], v[1], v[2]]);
    }
}

// ---------------------------------------------------------------------------------------------
// Primitives (local coordinates, faces oriented outwards)

struct Mesh {
    points: Vec<DVec3>,
    tris: Vec<[u32; 3]>,
}

/// Two unit vectors completing `w` to a right-handed frame (u × v = w).
fn axes(w: DVec3) -> (DVec3, DVec3) {
    let a = w.abs();
    let e = if a.x <= a.y && a.x <= a.z {
        DVec3::X
    } else if a.y <= a.z {
        DVec3::Y
    } else {
        DVec3::Z
    };
    let u = w.cross(e).normalize();
    (u, w.cross(u))
}

/// A surface of revolution about the axis (`c`, `w`): rings of `(radius, height)` from the
/// profile, `segs` segments around; each triangle faces `outward(centroid)`.
fn revolve(
    c: DVec3,
    w: DVec3,
    profile: &[(f64, f64)],
    segs: usize,
    outward: impl Fn(DVec3) -> DVec3,
) -> Mesh {
    let (u, v) = axes(w);
    let mut points = Vec::new();
    let mut rings: Vec<Vec<u32>> = Vec::new();
    for &(r, h) in profile {
        let base = c + w * h;
        if r == 0.0 {
            points.push(base);
            rings.push(vec![points.len() as u32 - 1; segs]);
        } else {
            let ring = (0..segs)
                .map(|s| {
                    let t = std::f64::consts::TAU * s as f64 / segs as f64;
                    points.push(base + (u * t.cos() + v * t.sin()) * r);
                    points.len() as u32 - 1
                })
                .collect();
            rings.push(ring);
        }
    }
    let mut tris = Vec::new();
    for k in 0..rings.len().saturating_sub(1) {
        let (r0, r1) = (&rings[k], &rings[k + 1]);
        for s in 0..segs {
            let s1 = (s + 1) % segs;
            for t in [[r0[s], r0[s1], r1[s1]], [r0[s], r1[s1], r1[s]]] {
                if t[0] == t[1] || t[1] == t[2] || t[0] == t[2] {
                    continue;
                }
                let [a, b, cc] = t.map(|i| points[i as usize]);
                let n = (b - a).cross(cc - a);
                tris.push(if n.dot(outward((a + b + cc) / 3.0)) < 0.0 {
                    [t[0], t[2], t[1]]
                } else {
                    t
                });
            }
        }
    }
    Mesh { points, tris }
}

fn sphere(c: DVec3, r: f64, div: usize) -> Mesh {
    let n = 2 * div;
    let profile: Vec<(f64, f64)> = (0..=n)
        .map(|i| {
            let th = std::f64::consts::FRAC_PI_2 * i as f64 / div as f64;
            let s = if i == 0 || i == n { 0.0 } else { th.sin() };
            (r.abs() * s, r.abs() * th.cos())
        })
        .collect();
    let sign = r.signum();
    revolve(c, DVec3::Z, &profile, 4 * div, |p| (p - c) * sign)
}

fn cone(a: DVec3, r1: f64, b: DVec3, r2: f64, div: usize) -> Option<Mesh> {
    let d = b - a;
    let h = d.length();
    let w = d.try_normalize()?;
    let sign = if r1 < 0.0 || r2 < 0.0 { -1.0 } else { 1.0 };
    Some(revolve(
        a,
        w,
        &[(r1.abs(), 0.0), (r2.abs(), h)],
        4 * div,
        |p| {
            let q = p - a;
            (q - w * q.dot(w)) * sign
        },
    ))
}

fn ring(c: DVec3, n: DVec3, r0: f64, r1: f64, div: usize) -> Mesh {
    revolve(c, n, &[(r0, 0.0), (r1, 0.0)], 4 * div, |_| n)
}

fn torus(c: DVec3, n: DVec3, r0: f64, r1: f64, div: usize) -> Mesh {
    let sign = r1.signum();
    let (r0, r1) = (r0.abs(), r1.abs());
    let minor = 0.5 * (r1 - r0);
    let major = 0.5 * (r1 + r0);
    let steps = 4 * div;
    let profile: Vec<(f64, f64)> = (0..=steps)
        .map(|i| {
            let th = std::f64::consts::TAU * (i % steps) as f64 / steps as f64;
            (major + minor * th.cos(), minor * th.sin())
        })
        .collect();
    revolve(c, n, &profile, 4 * div, |p| {
        let q = p - c;
        let radial = (q - n * q.dot(n)).normalize_or_zero();
        (q - radial * major) * sign
    })
}

/// `prism`, as the MGF specification has it: the polygon keeps its orientation and is
/// extruded opposite its (right-hand rule) normal, so with a positive length every face points
/// outwards; with a negative length the prism lies above the polygon and faces inwards.
fn prism(base: &[DVec3], len: f64) -> Option<Mesh> {
    let n = base.len();
    let tris = triangulate(&[base.to_vec()]);
    let mut normal = DVec3::ZERO;
    for k in 0..n {
        normal += base[k].cross(base[(k + 1) % n]);
    }
    let normal = normal.try_normalize()?;
    let d = -normal * len;
    let mut points = base.to_vec();
    points.extend(base.iter().map(|&p| p + d));
    let n32 = n as u32;
    let mut out = Vec::new();
    for t in &tris {
        let t = t.map(|k| k as u32);
        // The base as given, the opposite end its mirror image.
        out.push(t);
        out.push([t[0] + n32, t[2] + n32, t[1] + n32]);
    }
    for k in 0..n32 {
        let k1 = (k + 1) % n32;
        out.push([k, k + n32, k1 + n32]);
        out.push([k, k1 + n32, k1]);
    }
    Some(Mesh { points, tris: out })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn equal_energy_white_is_grey() {
        let c = spectrum_xy(|_| 1.0).unwrap();
        assert!(
            (c.x - 1.0 / 3.0).abs() < 2e-3 && (c.y - 1.0 / 3.0).abs() < 2e-3,
            "{c:?}"
        );
        let g = xy_to_rgb(Xy::NEUTRAL);
        assert!((g - DVec3::ONE).abs().max_element() < 1e-9, "{g}");
        // A 6500 K blackbody is close to D65 (0.3135, 0.3237).
        let d = blackbody_xy(6500.0).unwrap();
        assert!(
            (d.x - 0.3135).abs() < 3e-3 && (d.y - 0.3237).abs() < 3e-3,
            "{d:?}"
        );
    }

    #[test]
    fn primitive_triangle_counts() {
        let c = DVec3::ZERO;
        assert_eq!(sphere(c, 1.0, 4).tris.len(), 224);
        assert_eq!(cone(c, 1.0, DVec3::Z, 1.0, 4).unwrap().tris.len(), 32);
        assert_eq!(cone(c, 1.0, DVec3::Z, 0.0, 4).unwrap().tris.len(), 16);
        assert_eq!(ring(c, DVec3::Z, 0.5, 1.0, 4).tris.len(), 32);
        assert_eq!(ring(c, DVec3::Z, 0.0, 1.0, 4).tris.len(), 16);
        assert_eq!(torus(c, DVec3::Z, 1.0, 2.0, 4).tris.len(), 512);
        let sq = [DVec3::ZERO, DVec3::X, DVec3::new(1.0, 1.0, 0.0), DVec3::Y];
        assert_eq!(prism(&sq, 1.0).unwrap().tris.len(), 12);
    }

    #[test]
    fn concave_polygon_ear_clipped() {
        // An L shape of area 3.
        let l = [(0., 0.), (2., 0.), (2., 1.), (1., 1.), (1., 2.), (0., 2.)]
            .map(|(x, y)| DVec3::new(x, y, 0.0))
            .to_vec();
        let t = triangulate(std::slice::from_ref(&l));
        assert_eq!(t.len(), 4);
        let area: f64 = t
            .iter()
            .map(|t| 0.5 * (l[t[1]] - l[t[0]]).cross(l[t[2]] - l[t[0]]).z)
            .sum();
        assert!((area - 3.0).abs() < 1e-12, "{area}");
    }
}
