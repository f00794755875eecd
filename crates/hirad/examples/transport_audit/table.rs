//! Per-object tables (modes `irradiance` and `self`): the solver's irradiance over each
//! object's open area against another estimate, largest difference in power first.
use crate::elements::{leaf_irradiance, root, short_name, triangles_by_object};
use crate::estimate::ByArea;
use crate::opts::Opts;
use hirad::radiosity::overlap::Covers;
use hirad::radiosity::Solution;
use hirad::scene::Scene;
use rayon::prelude::*;

/// One row of a per-object table.
pub struct Row {
    object: usize,
    back: bool,
    area: f64,
    solver: f64,
    other: f64,
    stderr: f64,
    direct: f64,
}

/// An object's irradiance by another method: mean, its standard error, the emitters' part,
/// and the solver's value at the same points when not the area average.
pub struct Estimate {
    /// Mean irradiance (channel sum).
    pub value: f64,
    /// Standard error of `value`.
    pub stderr: f64,
    /// The emitters' part of `value`.
    pub direct: f64,
    /// The solver's irradiance at the same points, when not its area mean.
    pub solver: Option<f64>,
}

/// Per object (and side): the solver's mean irradiance over its open area (the parts no
/// coplanar triangle covers and no solid shuts, where the solver's H is defined), and `estimate`.
pub fn per_object(
    scene: &Scene,
    sol: &Solution,
    covers: &Covers,
    o: &Opts,
    estimate: impl Fn(usize, bool, &ByArea) -> Estimate + Sync,
) -> Vec<Row> {
    let (two_sided, only) = (o.two_sided, o.object.as_deref());
    let mut by = triangles_by_object(scene);
    for (obj, ts) in by.iter_mut().enumerate() {
        if only.is_some_and(|n| scene.objects[obj] != n) {
            ts.clear();
        }
    }
    let sides: &[bool] = if two_sided { &[false, true] } else { &[false] };
    let mut rows = Vec::new();
    for &back in sides {
        let part: Vec<Row> = by
            .par_iter()
            .enumerate()
            .filter(|(_, ts)| !ts.is_empty())
            .map(|(o, ts)| {
                let tris = ByArea::triangles(scene, ts.clone());
                // Leaf by leaf: H over the leaf's open area (for ρ = 0, the triangle's H).
                let (mut area, mut sum, mut leaves) = (0.0f64, 0.0f64, Vec::new());
                for &t in ts {
                    leaves.clear();
                    sol.elements.leaves_of(root(sol, t, back), &mut leaves);
                    for &id in &leaves {
                        let e = &sol.elements.elems[id as usize];
                        let a = e.area as f64 * covers.open_fraction(t, e.normal, &e.verts);
                        let h = if e.rho.max_element() > 0.0 {
                            leaf_irradiance(&sol.elements, id)
                        } else {
                            sol.triangle_irradiance(t, back).element_sum()
                        };
                        area += a;
                        sum += a * h;
                    }
                }
                let area = area.max(1e-30);
                let solver = sum / area;
                let e = estimate(o, back, &tris);
                Row {
                    object: o,
                    back,
                    area,
                    solver: e.solver.unwrap_or(solver),
                    other: e.value,
                    stderr: e.stderr,
                    direct: e.direct,
                }
            })
            .collect();
        rows.extend(part);
    }
    rows
}

/// Prints the rows' Σ A·H, then the 40 rows with the largest |A·ΔH|; `what` names the
/// other estimate.
pub fn print_rows(scene: &Scene, mut rows: Vec<Row>, what: &str) {
    let (s, o) = rows
        .iter()
        .filter(|r| r.other > 0.0)
        .fold((0.0, 0.0), |a, r| {
            (a.0 + r.area * r.solver, a.1 + r.area * r.other)
        });
    println!("Σ A·H: solver {s:.3}, {what} {o:.3}, ratio {:.4}", s / o);
    rows.sort_by(|a, b| {
        let d = |r: &Row| (r.area * (r.solver - r.other)).abs();
        d(b).total_cmp(&d(a))
    });
    println!(
        "{:40} {:5} {:>9} {:>10} {:>10} {:>7} {:>10} {:>8} {:>9}",
        "object", "back", "area", "H solver", what, "ratio", "A·ΔH", "±", "direct"
    );
    for r in rows.iter().take(40) {
        let name = short_name(scene, r.object);
        println!(
            "{name:40} {:5} {:9.3} {:10.3} {:10.3} {:7.3} {:10.2} {:8.3} {:9.3}",
            r.back,
            r.area,
            r.solver,
            r.other,
            r.solver / r.other,
            r.area * (r.solver - r.other),
            r.stderr,
            r.direct
        );
    }
}
