//! The MGF entities other than transforms, one match arm per entity: colours (`c cxy cspec cct
//! cmix`), materials (`m sides rd ed`; `td rs ts` are read and ignored with one warning per
//! kind, the solver being diffuse; `ir` is read), vertices (`v p n`), objects (`o`), includes
//! (`i`), comments; geometry goes to `shapes`. Unknown entities are warned about once per kind
//! and skipped, as mgflib does.

use super::colour::{blackbody_xy, spectrum_xy, Xy, MIN_Y};
use super::context::{Mat, Vert};
use super::parse::At;
use super::xf::{parse_xf, XfArgs};
use super::Loader;
use glam::DVec3;
use hirad_core::Result;
use std::path::Path;

impl Loader {
    /// Run one statement (not `xf`) at `at`; `depth` is the include depth of its file.
    pub(super) fn statement(&mut self, at: At, w: &[String], depth: usize) -> Result<()> {
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
            "f" | "fh" | "sph" | "cyl" | "cone" | "ring" | "torus" | "prism" => {
                self.geometry(at, w)?
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
}
