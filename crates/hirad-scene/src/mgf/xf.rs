//! MGF transforms: `xf` argument lists (`-t -rx -ry -rz -s -mx -my -mz`, repeated with `-i N`,
//! arrays with `-a N`) parsed into matrices, and the transform stack. An `xf -a` block (or an
//! include with `-a`) is replayed once per array element, nested arrays in row-major order.
//! Vertices are transformed when geometry references them; a mirroring transform (negative
//! determinant) reverses the vertex order so surfaces keep facing outwards.

use super::parse::At;
use super::Loader;
use glam::{DMat3, DMat4, DVec3};
use hirad_core::Result;

/// Deepest `xf` nesting accepted.
const MAX_XF_DEPTH: usize = 512;
/// Deepest nesting of `xf -a` array blocks (each level recurses).
const MAX_ARRAY_DEPTH: usize = 32;
/// Most elements of one (multi-dimensional) `xf -a` array.
const MAX_ARRAY_ELEMENTS: u64 = 1_000_000;

/// One level of the transform stack.
#[derive(Clone, Copy)]
pub(super) struct Xf {
    /// Local to world.
    pub(super) m: DMat4,
    /// `m` mirrors (negative determinant).
    pub(super) flip: bool,
    /// Unique id (cache key of transformed vertices).
    pub(super) id: u64,
}

/// How often a group of `xf` arguments is applied.
#[derive(Clone, Copy)]
pub(super) enum Count {
    Fixed(u64),
    Array(u64),
}

/// A parsed `xf` argument list: groups of operations, each applied `Count` times in order.
pub(super) struct XfArgs {
    pub(super) groups: Vec<(DMat4, Count)>,
}

impl XfArgs {
    /// Element counts of the `-a` groups, in order.
    pub(super) fn arrays(&self) -> Vec<u64> {
        self.groups
            .iter()
            .filter_map(|g| match g.1 {
                Count::Array(n) => Some(n),
                Count::Fixed(_) => None,
            })
            .collect()
    }

    /// The matrix for array indices `idx` (one per `-a`).
    pub(super) fn matrix(&self, idx: &[u64]) -> DMat4 {
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

/// `b` to the power `n`, by squaring.
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

impl Loader {
    /// The current transform (top of the stack).
    pub(super) fn top_xf(&self) -> Xf {
        *self.xf.last().expect("xf stack")
    }

    /// Run `body` once per array element of `args`, each with its transform pushed.
    pub(super) fn with_xf(
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

    /// The loop of [`Loader::with_xf`] over the elements, last index fastest.
    fn each_element(
        &mut self,
        at: At,
        args: &XfArgs,
        dims: &[u64],
        total: u64,
        body: &mut dyn FnMut(&mut Loader) -> Result<()>,
    ) -> Result<()> {
        let mut idx = vec![0u64; dims.len()];
        let before = self.raw.triangles.len() as u64;
        for e in 0..total {
            self.push_xf(at, args.matrix(&idx))?;
            let r = body(self);
            self.xf.pop();
            r?;
            // Every element repeats the first one's triangles: stop a runaway array now rather
            // than after building (and storing) the limit's worth of triangles.
            let per = self.raw.triangles.len() as u64 - before;
            let expected = before.saturating_add(per.saturating_mul(total));
            if e == 0 && expected > super::MAX_TRIANGLES as u64 {
                return Err(at.err(format!(
                    "xf array of {total} elements × {per} triangles exceeds {} triangles",
                    super::MAX_TRIANGLES
                )));
            }
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

    /// Push `local` applied inside the current transform.
    pub(super) fn push_xf(&mut self, at: At, local: DMat4) -> Result<()> {
        if self.xf.len() > MAX_XF_DEPTH {
            return Err(at.err(format!("xf nested deeper than {MAX_XF_DEPTH}")));
        }
        let parent = self.top_xf();
        let m = parent.m * local;
        let id = self.id();
        self.xf.push(Xf {
            m,
            flip: DMat3::from_mat4(m).determinant() < 0.0,
            id,
        });
        Ok(())
    }
}

/// Parse the arguments of `xf` (or of an include's transform).
pub(super) fn parse_xf(at: At, a: &[String]) -> Result<XfArgs> {
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
