//! [`Layout::new`]: lays a cluster tree out for traversal.

use super::super::volume::box6;
use super::encode::{
    leaf_ref, leaf_run, Group, CHUNK, FIRST, LEAF, LEAF_MAX_START, LEAF_MAX_TRIS, NONE, RUN, SUB,
};
use super::faces::{face_bits, flat_bits};
use super::packets::{put, Packet, Wide, WIDE_MIN};
use super::run_tree::{eager_run, run_box, run_lane, top_fanout, Piece, RunTree, CHUNK_MAX};
use super::{Boxes, Layout};
use crate::cluster::ClusterTree;
use hirad_core::geom::{triangle_area_f64, Aabb};
use hirad_scene::Scene;

impl Layout {
    pub(in crate::ray) fn new(scene: &Scene, tree: &ClusterTree, boxes: Boxes) -> Layout {
        let n = tree.nodes.len();
        if n == 0 {
            return Layout::default();
        }
        let nt = scene.num_triangles() as u32;
        // Children of a node that the layout follows: valid ids greater than the parent's
        // (true of every laid-out tree; guarantees termination on malformed input).
        let kids = |id: u32| {
            tree.nodes[id as usize]
                .children()
                .filter(move |&c| (c as usize) < n && c > id)
        };
        let surfs = |id: u32| {
            let node = &tree.nodes[id as usize];
            let end =
                (node.first_surface as usize + node.num_surfaces as usize).min(tree.surfaces.len());
            let start = (node.first_surface as usize).min(end);
            tree.surfaces[start..end]
                .iter()
                .copied()
                .filter(|&s| s < nt)
        };
        // Depth-first pre-order.
        let mut order = Vec::with_capacity(n);
        let mut seen = vec![false; n];
        let mut stack = vec![0u32];
        while let Some(id) = stack.pop() {
            if std::mem::replace(&mut seen[id as usize], true) {
                continue;
            }
            order.push(id);
            let mut k: Vec<u32> = kids(id).collect();
            k.reverse();
            stack.extend(k);
        }
        // Each node's own triangles.
        let mut own: Vec<Vec<u32>> = (0..n as u32).map(|id| surfs(id).collect()).collect();
        // Boxes of the nodes' own runs and of the nodes (grown to, or tight around, their
        // contents), children first.
        let mut run_bound = vec![Aabb::EMPTY; n];
        let mut bound = vec![Aabb::EMPTY; n];
        let mut run_faces = vec![0u8; n];
        let mut node_faces = vec![0u8; n];
        for &id in order.iter().rev() {
            let rb = run_box(scene, &own[id as usize]);
            run_bound[id as usize] = rb;
            let mut b = match boxes {
                Boxes::Tight | Boxes::Nodes => rb,
                Boxes::Cluster => {
                    let mut b = tree.nodes[id as usize].bbox;
                    b.grow_box(&rb);
                    b
                }
            };
            for c in kids(id) {
                let cb = bound[c as usize];
                b.grow_box(&cb);
            }
            bound[id as usize] = b;
            let tris = || {
                own[id as usize]
                    .iter()
                    .map(|&s| scene.tri_bbox(s as usize))
                    .map(|t| (t, flat_bits(&t)))
            };
            run_faces[id as usize] = face_bits(&rb, tris());
            let below = kids(id).map(|c| (bound[c as usize], node_faces[c as usize]));
            node_faces[id as usize] = face_bits(&b, tris().chain(below));
        }
        // Whether occlusion tests a node's own triangles at once when their box is hit (in a
        // free lane of the node).
        let eager: Vec<bool> = (0..n)
            .map(|i| {
                boxes != Boxes::Cluster
                    && !own[i].is_empty()
                    && eager_run(scene, &own[i], &run_bound[i])
            })
            .collect();
        // With tight boxes, a run longer than CHUNK_MAX (that is not a leaf's run held in
        // place) is reordered into pieces behind boxes of their own where that pays.
        let mut runs: Vec<Option<RunTree>> = vec![None; n];
        if boxes == Boxes::Tight {
            use rayon::prelude::*;
            own.par_iter_mut()
                .zip(&mut runs)
                .enumerate()
                .for_each(|(id, (ids, run))| {
                    let c = kids(id as u32).count();
                    if ids.len() > CHUNK_MAX && (c > 0 || ids.len() > LEAF_MAX_TRIS) {
                        let mut split = ids.clone();
                        let rt = RunTree::new(scene, &mut split, top_fanout(c));
                        let sa = run_bound[id].surface_area() as f64;
                        if rt.pays(ids.len(), sa, run_lane(c) && !eager[id]) {
                            *ids = split;
                            *run = Some(rt);
                        }
                    }
                });
        }
        // Nodes a ray passes through for free with tight boxes: no triangles of their own and
        // one child, whose box is theirs (an empty half of a k-d cell). Their parent's lane
        // refers to the child directly.
        let pass: Vec<bool> = (0..n)
            .map(|i| boxes != Boxes::Cluster && own[i].is_empty() && kids(i as u32).count() == 1)
            .collect();
        // The lanes of each node: its children, or with tight boxes, inner children pulled
        // up into it (`collapse`). Pulled-up runs and pieces are encoded in place (a chunk's
        // first packet stays below `LEAF_MAX_START`: a packet holds at least one triangle, and
        // a run's chunks start at most its length further on); a node with two parents
        // (malformed input) leaves the tree as it is.
        let kid_lists: Vec<Vec<u32>> = (0..n as u32).map(|id| kids(id).collect()).collect();
        let mut parents = vec![0u8; n];
        for &c in kid_lists.iter().flatten() {
            parents[c as usize] = parents[c as usize].saturating_add(1);
        }
        let mut lanes: Vec<Vec<Lane>> = if boxes == Boxes::Tight
            && 2 * nt as usize <= LEAF_MAX_START
            && n + (nt as usize) < RUN as usize
            && parents.iter().all(|&p| p <= 1)
        {
            collapse(&order, &kid_lists, &own, &runs, &pass, &bound)
        } else {
            kid_lists
                .iter()
                .map(|k| k.iter().copied().map(Lane::Node).collect())
                .collect()
        };
        occlusion_order(
            scene, &mut lanes, &order, &kids, &own, &runs, &bound, &run_bound,
        );
        let mut absorbed = vec![false; n];
        for l in &lanes {
            for lane in l {
                if let Lane::Run(a) | Lane::Piece(a, _) = *lane {
                    absorbed[a as usize] = true;
                }
            }
        }
        // Nodes pulled up are not laid out (their own runs are lanes of the node above).
        let mut laid = vec![false; n];
        laid[0] = true;
        for &id in &order {
            if laid[id as usize] {
                for lane in &lanes[id as usize] {
                    if let Lane::Node(c) = *lane {
                        laid[c as usize] = true;
                    }
                }
            }
        }
        // Pass 1: references, group and triangle positions.
        let mut refs = vec![NONE; n];
        let mut tri_pos = vec![0usize; n];
        let mut sub_pos = vec![0usize; n];
        let mut ng = 0usize;
        // Packets and wide packets allocated so far.
        let mut np = [0usize; 2];
        let mut run_pos = vec![0usize; n];
        for &id in &order {
            let i = id as usize;
            if absorbed[i] {
                match runs[i].as_mut() {
                    // Its pieces are lanes of the node above; the groups of its sub-pieces
                    // and its chunks are placed here.
                    Some(rt) => {
                        sub_pos[i] = ng;
                        ng += rt.subs.len();
                        place_pieces(rt, sub_pos[i], &mut np);
                    }
                    None => run_pos[i] = alloc(&mut np, own[i].len()),
                }
            }
            if pass[i] || !laid[i] {
                continue;
            }
            let c = lanes[i].len();
            let t = own[i].len();
            // Every chunk starts at most `t` packets further on; the node's groups (its children
            // and top pieces, then fewer groups of pieces than triangles) stay below RUN.
            let fits =
                np[0].max(np[1]) + t <= LEAF_MAX_START && ng + c.div_ceil(4) + 1 + t < RUN as usize;
            if let Some(rt) = runs[i].as_mut().filter(|_| fits) {
                refs[i] = ng as u32;
                ng += (c + rt.top.len()).div_ceil(4);
                sub_pos[i] = ng;
                ng += rt.subs.len();
                place_pieces(rt, sub_pos[i], &mut np);
                continue;
            }
            runs[i] = None;
            let start = alloc(&mut np, t);
            tri_pos[i] = start;
            if c == 0 && t <= LEAF_MAX_TRIS && start <= LEAF_MAX_START {
                refs[i] = leaf_ref(start, t);
            } else {
                refs[i] = ng as u32;
                let lane = boxes != Boxes::Cluster && t > 0 && run_lane(c);
                ng += (c + usize::from(lane)).div_ceil(4).max(1);
            }
        }
        // Pass 2: fill in.
        let mut groups = vec![Group::default(); ng];
        let mut faces = vec![0u32; ng];
        let empty = Packet {
            v: [[0.0; 4]; 9],
            id: [u32::MAX; 4],
        };
        let [npk, nw] = np;
        let mut packets = super::super::pages::filled(npk, empty);
        let mut wide = super::super::pages::filled(
            nw,
            Wide {
                v: [[0.0; 16]; 9],
                id: [u32::MAX; 16],
            },
        );
        // The reference a lane holding node `i` gets: its own, or that of the first node below
        // it that a ray does not pass through for free (children first).
        let mut link = refs.clone();
        for &id in order.iter().rev() {
            if pass[id as usize] {
                link[id as usize] = kids(id).map(|c| link[c as usize]).next().unwrap_or(NONE);
            }
        }
        for &id in &order {
            let i = id as usize;
            let ids = &own[i];
            if absorbed[i] {
                match &runs[i] {
                    Some(rt) => {
                        fill_subs(&mut groups, &mut faces, scene, ids, rt, sub_pos[i]);
                        store_chunks(scene, &mut packets, &mut wide, ids, rt);
                    }
                    None => store_run(scene, &mut packets, &mut wide, ids, run_pos[i]),
                }
            }
            if pass[i] || !laid[i] {
                continue;
            }
            let r = refs[i];
            if r & LEAF == 0 {
                let g0 = r as usize;
                let k = &lanes[i];
                let children = k.iter().map(|&lane| match lane {
                    Lane::Node(c) => (bound[c as usize], link[c as usize], node_faces[c as usize]),
                    Lane::Run(a) => (
                        run_bound[a as usize],
                        leaf_ref(run_pos[a as usize], own[a as usize].len()) | CHUNK,
                        run_faces[a as usize],
                    ),
                    Lane::Piece(a, j) => {
                        let rt = runs[a as usize].as_ref().expect("pulled-up pieces");
                        piece_lane(scene, &own[a as usize], &rt.top[j as usize])
                    }
                });
                // The box, reference and face bits of a piece of the node's own run.
                let rt = runs[i].as_ref();
                let top = rt
                    .into_iter()
                    .flat_map(|rt| rt.top.iter().map(|p| piece_lane(scene, ids, p)));
                let first = rt.is_some() && eager[i];
                let mut lanes = 0usize;
                for (j, (b, cr, f)) in children.chain(top).enumerate() {
                    let g = &mut groups[g0 + j / 4];
                    g.set_lane(j % 4, &b, cr);
                    if first && j >= k.len() {
                        g.eager |= FIRST << (j % 4);
                    }
                    faces[g0 + j / 4] |= (f as u32) << (8 * (j % 4));
                    lanes += 1;
                }
                if let Some(rt) = rt {
                    fill_subs(&mut groups, &mut faces, scene, ids, rt, sub_pos[i]);
                }
                let nt = if runs[i].is_some() { 0 } else { ids.len() };
                // The run gets a lane of its own when the node's eight-lane node has one free
                // ([`run_lane`]; in a group of its own when the children fill theirs).
                let run_lane =
                    boxes != Boxes::Cluster && nt > 0 && run_lane(k.len()) && ng < RUN as usize;
                let num_groups = (lanes + usize::from(run_lane)).div_ceil(4).max(1);
                let at = if run_lane { g0 + num_groups - 1 } else { g0 };
                let g = &mut groups[at];
                g.tri_start = tri_pos[i] as u32;
                g.num_tris = nt as u32;
                if run_lane {
                    let lane = k.len() % 4;
                    g.set_lane(lane, &run_bound[i], RUN | at as u32);
                    faces[at] |= (run_faces[i] as u32) << (8 * lane);
                    g.run = 1 << lane;
                    if eager[i] {
                        g.eager = 1 << lane;
                    }
                }
                groups[g0].num_groups = num_groups as u32;
            }
            match &runs[i] {
                None => store_run(scene, &mut packets, &mut wide, ids, tri_pos[i]),
                Some(rt) => store_chunks(scene, &mut packets, &mut wide, ids, rt),
            }
        }
        Layout {
            root_box: box6(&bound[0]),
            root: Some(link[0]),
            groups,
            faces,
            packets,
            wide,
        }
    }
}

/// Lanes a node may hold after [`collapse`]: two groups. Measured against one group on the
/// solver's and the paper's segments (`docs/perf-log.md` 2026-12-05 (20)).
const WIDTH: usize = 8;

/// What a lane of a laid-out node holds: a node, or the own run of an inner node pulled up
/// into it.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Lane {
    Node(u32),
    Run(u32),
    /// Top piece `.1` of the split run of node `.0`.
    Piece(u32, u32),
}

/// Lanes per node when inner children are pulled up (tight boxes): in pre-order, while a
/// node's lanes fit in two groups ([`WIDTH`], one lane fewer for a node with triangles of its
/// own), the inner lane of largest box area is replaced by that node's children and, when it
/// has triangles of its own, a lane holding them (at most [`LEAF_MAX_TRIS`]) or, when they
/// were split into pieces, the lanes of its top pieces. Nodes passed through and nodes whose
/// run is split into pieces keep their children. The same triangles, each behind the box of
/// its node's run or piece, but for a node whose children fill its eight-lane nodes: its own
/// run is tested at its visits, when the ray hits the run's box ([`run_lane`],
/// `Node8::run_box`).
fn collapse(
    order: &[u32],
    kids: &[Vec<u32>],
    own: &[Vec<u32>],
    runs: &[Option<RunTree>],
    pass: &[bool],
    bound: &[Aabb],
) -> Vec<Vec<Lane>> {
    let n = kids.len();
    let mut lanes: Vec<Vec<Lane>> = vec![Vec::new(); n];
    let mut gone = vec![false; n];
    for &id in order {
        let i = id as usize;
        let mut l: Vec<Lane> = kids[i].iter().copied().map(Lane::Node).collect();
        if !gone[i] && !pass[i] && runs[i].is_none() {
            let width = WIDTH - usize::from(!own[i].is_empty());
            loop {
                let mut pick: Option<(usize, f32)> = None;
                for (j, lane) in l.iter().enumerate() {
                    let Lane::Node(c) = *lane else { continue };
                    let c = c as usize;
                    let nk = kids[c].len();
                    let extra = match &runs[c] {
                        Some(rt) => rt.top.len(),
                        None => usize::from(!own[c].is_empty()),
                    };
                    let len = l.len() - 1 + nk + extra;
                    if nk == 0 || (runs[c].is_none() && own[c].len() > LEAF_MAX_TRIS) || len > width
                    {
                        continue;
                    }
                    let a = bound[c].surface_area();
                    if pick.is_none_or(|(_, b)| a > b) {
                        pick = Some((j, a));
                    }
                }
                let Some((j, _)) = pick else { break };
                let Lane::Node(c) = l.remove(j) else {
                    unreachable!()
                };
                gone[c as usize] = true;
                let mut add: Vec<Lane> = kids[c as usize].iter().copied().map(Lane::Node).collect();
                match &runs[c as usize] {
                    Some(rt) => add.extend((0..rt.top.len() as u32).map(|j| Lane::Piece(c, j))),
                    None if !own[c as usize].is_empty() => add.push(Lane::Run(c)),
                    None => {}
                }
                l.splice(j..j, add);
            }
        }
        lanes[i] = l;
    }
    lanes
}

/// Order each node's lanes for occlusion queries, which visit the highest hit lane first: by
/// increasing `p / c`, the chance that the lane's triangles block a ray crossing its box over
/// the cost of finding out. `p` = min(1, 2·(triangle area)/(box surface area)) (a flat
/// triangle's mean projected area is half its area, a convex box's a quarter of its surface),
/// `c` = 1 + log2(triangles below) (a hierarchy's search cost). Testing in decreasing `p / c`
/// minimises the expected cost of a sequential search; Embree sorts a node's children for
/// shadow rays too, by primitive count. Results do not change, only the visits
/// (`docs/perf-log.md` 2026-12-06 (44)). Ties keep the tree's order.
#[allow(clippy::too_many_arguments)]
fn occlusion_order<K: Iterator<Item = u32>>(
    scene: &Scene,
    lanes: &mut [Vec<Lane>],
    order: &[u32],
    kids: &impl Fn(u32) -> K,
    own: &[Vec<u32>],
    runs: &[Option<RunTree>],
    bound: &[Aabb],
    run_bound: &[Aabb],
) {
    use rayon::prelude::*;
    let tri_area: Vec<f64> = (0..scene.num_triangles())
        .into_par_iter()
        .map(|s| {
            let [a, b, c] = scene.tri_vertices(s);
            triangle_area_f64(a, b, c)
        })
        .collect();
    let area = |ids: &[u32]| -> f64 { ids.iter().map(|&s| tri_area[s as usize]).sum() };
    // Triangles and their area below each node.
    let n = own.len();
    let mut below = vec![(0usize, 0f64); n];
    for &id in order.iter().rev() {
        let i = id as usize;
        below[i] = kids(id).fold((own[i].len(), area(&own[i])), |(k, a), c| {
            (k + below[c as usize].0, a + below[c as usize].1)
        });
    }
    let key = |lane: &Lane| -> f64 {
        let ((k, a), b) = match *lane {
            Lane::Node(c) => (below[c as usize], bound[c as usize]),
            Lane::Run(r) => {
                let ids = &own[r as usize];
                ((ids.len(), area(ids)), run_bound[r as usize])
            }
            Lane::Piece(r, j) => {
                let rt = runs[r as usize].as_ref().expect("pieces of a split run");
                let ids = &own[r as usize][rt.top[j as usize].range.clone()];
                ((ids.len(), area(ids)), run_box(scene, ids))
            }
        };
        let sa = b.surface_area() as f64;
        let p = if sa > 0.0 {
            (2.0 * a / sa).min(1.0)
        } else {
            1.0
        };
        p / (1.0 + (k.max(1) as f64).log2())
    };
    // Keys are finite and non-negative, so their bits sort as they do (a stable sort).
    for l in lanes.iter_mut() {
        l.sort_by_cached_key(|x| key(x).to_bits());
    }
}

/// First packet of a run of `t` triangles, in the array its length selects (`np`: packets
/// and wide packets allocated so far).
fn alloc(np: &mut [usize; 2], t: usize) -> usize {
    let (k, size) = if t >= WIDE_MIN { (1, 16) } else { (0, 4) };
    let start = np[k];
    np[k] += t.div_ceil(size);
    start
}

/// References of the pieces of a split run: its sub-pieces' groups from `sub` on, its chunks
/// in packets allocated from `np`.
fn place_pieces(rt: &mut RunTree, sub: usize, np: &mut [usize; 2]) {
    for p in rt.top.iter_mut().chain(rt.subs.iter_mut().flatten()) {
        p.r = match p.sub {
            Some(j) => (sub + j) as u32,
            None => leaf_ref(alloc(np, p.range.len()), p.range.len()) | CHUNK,
        }
    }
}

/// Store the triangles `ids` of a run from packet `at` on (in the array its length selects).
fn store_run(scene: &Scene, packets: &mut [Packet], wide: &mut [Wide], ids: &[u32], at: usize) {
    for (i, &s) in ids.iter().enumerate() {
        let tv = scene.tri_vertices(s as usize);
        if ids.len() >= WIDE_MIN {
            let w = &mut wide[at + i / 16];
            put(&mut w.v, &mut w.id, i % 16, tv, s);
        } else {
            let p = &mut packets[at + i / 4];
            put(&mut p.v, &mut p.id, i % 4, tv, s);
        }
    }
}

/// The box, reference and face bits of a piece of the run `ids`.
fn piece_lane(scene: &Scene, ids: &[u32], p: &Piece) -> (Aabb, u32, u8) {
    let tris = &ids[p.range.clone()];
    let b = run_box(scene, tris);
    let items = tris.iter().map(|&s| scene.tri_bbox(s as usize));
    (b, p.r, face_bits(&b, items.map(|t| (t, flat_bits(&t)))))
}

/// Fill the groups of the sub-pieces of the split run `ids`, from group `at` on.
fn fill_subs(
    groups: &mut [Group],
    faces: &mut [u32],
    scene: &Scene,
    ids: &[u32],
    rt: &RunTree,
    at: usize,
) {
    for (j, sub) in rt.subs.iter().enumerate() {
        for (lane, p) in sub.iter().enumerate() {
            let (b, cr, f) = piece_lane(scene, ids, p);
            groups[at + j].set_lane(lane, &b, cr);
            faces[at + j] |= (f as u32) << (8 * lane);
        }
        groups[at + j].num_groups = 1;
        groups[at + j].run = SUB;
    }
}

/// Store the chunks of the split run `ids`.
fn store_chunks(
    scene: &Scene,
    packets: &mut [Packet],
    wide: &mut [Wide],
    ids: &[u32],
    rt: &RunTree,
) {
    for p in rt.top.iter().chain(rt.subs.iter().flatten()) {
        if p.sub.is_none() {
            store_run(scene, packets, wide, &ids[p.range.clone()], leaf_run(p.r).0);
        }
    }
}
