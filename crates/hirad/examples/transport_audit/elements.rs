//! Looking things up in a scene and its solution: elements by triangle and point, leaf
//! irradiance, objects by name.
use glam::Vec3;
use hirad::radiosity::element::{Elements, Kind};
use hirad::radiosity::Solution;
use hirad::scene::Scene;

/// Barycentric coordinates of `p` in triangle `v` (in its plane).
fn bary(v: &[Vec3; 3], p: Vec3) -> [f32; 3] {
    let (e1, e2, ep) = (v[1] - v[0], v[2] - v[0], p - v[0]);
    let (d11, d12, d22) = (e1.dot(e1), e1.dot(e2), e2.dot(e2));
    let (dp1, dp2) = (ep.dot(e1), ep.dot(e2));
    let den = d11 * d22 - d12 * d12;
    let b1 = (d22 * dp1 - d12 * dp2) / den;
    let b2 = (d11 * dp2 - d12 * dp1) / den;
    [1.0 - b1 - b2, b1, b2]
}

/// Root element of triangle `t` (its back face when `back` and two-sided).
pub fn root(sol: &Solution, t: u32, back: bool) -> u32 {
    let el = &sol.elements;
    el.first_root + t + if back && el.two_sided { el.num_tris } else { 0 }
}

/// Leaf element under `root` that contains point `p`.
pub fn leaf_at(sol: &Solution, root: u32, p: Vec3) -> u32 {
    let el = &sol.elements;
    let mut id = root;
    while el.elems[id as usize].num_children > 0 {
        id = el
            .children(id)
            .map(|c| {
                let b = bary(&el.elems[c as usize].verts, p);
                (b[0].min(b[1]).min(b[2]), c)
            })
            .fold((f32::MIN, id), |a, b| if b.0 > a.0 { b } else { a })
            .1;
    }
    id
}

/// Irradiance (channel sum) of leaf `id` from its radiosity, `H = (B − E) / ρ` per channel of
/// non-zero reflectance.
pub fn leaf_irradiance(el: &Elements, id: u32) -> f64 {
    let e = &el.elems[id as usize];
    let (rho, b) = (e.rho.as_dvec3(), el.b[id as usize] - e.emission.as_dvec3());
    (0..3)
        .map(|c| if rho[c] > 0.0 { b[c] / rho[c] } else { 0.0 })
        .sum()
}

/// The triangles of each object.
pub fn triangles_by_object(scene: &Scene) -> Vec<Vec<u32>> {
    let mut by: Vec<Vec<u32>> = vec![Vec::new(); scene.objects.len()];
    for t in 0..scene.num_triangles() {
        by[scene.tri_object[t] as usize].push(t as u32);
    }
    by
}

/// Root surface elements under element `id` (itself when a surface).
pub fn member_roots(sol: &Solution, id: u32, out: &mut Vec<u32>) {
    let el = &sol.elements;
    if el.elems[id as usize].kind == Kind::Surface {
        out.push(id);
        return;
    }
    for c in el.children(id) {
        member_roots(sol, c, out);
    }
}

/// Object of element `id`'s first leaf (an element's object, a cluster's first one's).
pub fn object_of(scene: &Scene, el: &Elements, id: u32) -> usize {
    let mut leaves = Vec::new();
    el.leaves_of(id, &mut leaves);
    scene.tri_object[el.elems[leaves[0] as usize].tri as usize] as usize
}

/// Index of the object named `name`; panics when there is none.
pub fn object_index(scene: &Scene, name: &str) -> usize {
    scene
        .objects
        .iter()
        .position(|n| n == name)
        .expect("no such object")
}

/// Object `obj`'s name cut to 40 characters, for a table column.
pub fn short_name(scene: &Scene, obj: usize) -> String {
    scene.objects[obj].chars().take(40).collect()
}
