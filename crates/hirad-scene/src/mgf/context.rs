//! The loader's named contexts (colours, materials, vertices, each with a current entry and
//! `name = template` definitions) and what geometry takes from them: vertices transformed to
//! world space once per value and transform, materials converted once per definition, objects
//! named by the `o` nesting.

use super::colour::{xy_to_rgb, Xy};
use super::parse::{kind, At};
use super::Loader;
use crate::Material;
use glam::DVec3;
use hirad_core::Result;
use std::collections::HashMap;

/// An MGF material context as defined so far.
#[derive(Clone, Debug)]
pub(super) struct Mat {
    pub(super) name: String,
    /// Diffuse reflectance `rd` and the colour current when it was set.
    pub(super) rd: f64,
    pub(super) rd_c: Xy,
    /// Diffuse emittance `ed` (lm/m²) and the colour current when it was set.
    pub(super) ed: f64,
    pub(super) ed_c: Xy,
    /// `sides 2` (the default).
    pub(super) two_sided: bool,
    /// Index in `raw.materials` of the material as it is now, once geometry used it.
    pub(super) out: Option<u32>,
}

impl Mat {
    pub(super) fn new(name: &str) -> Self {
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

/// An MGF vertex context: position `p` and normal `n` (zero when none), local coordinates.
#[derive(Clone, Copy, Debug)]
pub(super) struct Vert {
    pub(super) p: DVec3,
    pub(super) n: DVec3,
    /// Unique id of the vertex's current value (cache key of transformed vertices).
    pub(super) version: u64,
}

/// Named contexts of one kind with a current entry; entry 0 is the unnamed context.
pub(super) struct Contexts<T> {
    pub(super) items: Vec<T>,
    pub(super) names: HashMap<String, usize>,
    pub(super) cur: usize,
}

impl<T: Clone> Contexts<T> {
    pub(super) fn new(unnamed: T) -> Self {
        Self {
            items: vec![unnamed],
            names: HashMap::new(),
            cur: 0,
        }
    }
    pub(super) fn cur(&mut self) -> &mut T {
        &mut self.items[self.cur]
    }
    pub(super) fn get(&self, name: &str) -> Option<&T> {
        self.names.get(name).map(|&i| &self.items[i])
    }
    /// Make `name` current with value `v` (creating it if needed).
    pub(super) fn define(&mut self, name: &str, v: T) {
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

/// Output material key: name, ρ and L_e bits, two-sided.
pub(super) type MatKey = (String, [u32; 3], [u32; 3], bool);

impl Loader {
    /// `X name` / `X name =` / `X name = template`: `Some(value)` to define, `None` to make an
    /// existing context current.
    pub(super) fn template<T>(
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

    /// Vertex `name` as defined (local coordinates).
    pub(super) fn local_vertex(&self, at: At, name: &str) -> Result<Vert> {
        self.verts
            .get(name)
            .copied()
            .ok_or_else(|| at.err(format!("undefined vertex '{name}'")))
    }

    /// Output index of vertex `name` under the current transform.
    pub(super) fn world_vertex(&mut self, at: At, name: &str) -> Result<u32> {
        let v = self.local_vertex(at, name)?;
        let xf = self.top_xf();
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

    /// Output index of the current material, converted on first use.
    pub(super) fn material(&mut self) -> u32 {
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

    /// Output index of the current object (`o` names joined by `/`, else the file stem).
    pub(super) fn object(&mut self) -> u32 {
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
}
