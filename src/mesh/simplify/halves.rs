//! A large mesh simplified on two cores: its two spatial halves side by side, then the
//! whole down to the target.
//!
//! The collapse loop is sequential (each collapse changes the costs of its neighbours'
//! edges), and carrying the points beside it keeps the second core busy: on a 139k-vertex
//! scan the carrying took about four fifths of the collapsing thread's time, so two halves
//! each with their carrier gained almost nothing (704 ms against 811 ms in one piece).
//! The halves therefore collapse without carrying.
//!
//! The faces are split at the median of their centroids along the longest side of the
//! bounding box. A vertex with faces on both sides (a cut vertex) is frozen in both
//! halves: no collapse removes it, moves it or folds a neighbour into it, so neither half
//! makes an edge between two cut vertices that the other half may make too, and the two
//! results share the cut's vertices and edges unchanged and glue into one manifold mesh.
//! A boundary loop that reaches the cut is frozen whole, because a half sees it joined to
//! the cut and its guard on short loops (`min_boundary_loop`) would count the wrong loop.
//! Faces alternating around a vertex would pinch it in each half: they are moved to one
//! side first (`unpinch`).
//!
//! Each half stops at its share of twice the target (plus its frozen vertices). A free
//! vertex's faces all lie in its half, so its quadric and the guards of its collapses
//! are those of the whole mesh (but for the fewest-faces guard on a cut vertex opposite
//! the edge, which counts that vertex's faces in the half only); the order differs,
//! cheapest first in each half instead of over the whole. At the handover every input
//! point lands on the nearest face around the vertex its collapses led into or around
//! that vertex's neighbours: a local projection, so a point of a thin part stays on its
//! own side as carrying keeps it. The glued mesh then runs the ordinary collapse loop to
//! the target with the halves' quadrics and locks, the points carried, so the last,
//! costliest half of the collapses is ordered by one queue over the whole mesh and the
//! cut leaves no strip of small faces.
//!
//! Crease chains are kept as in one piece. A free vertex's crease edges all lie in its
//! half, so its constraint planes, whether it is a crease corner and the crease guards of
//! its collapses (which read the crease neighbours of the edge's two ends, never a walk
//! along the chain, unlike the boundary loops' guard) are the whole mesh's; a cut vertex
//! takes its planes and lock from the whole mesh at the glue, as its quadric. The glued
//! mesh's crease edges are the halves' surviving ones and the input's between two
//! survivors (a crease edge along the cut is a boundary edge of both halves, kept by
//! neither). Measured on CGAL's CAD parts Loop-subdivided to 21-154k vertices (fandisk,
//! fandisk_large, turbine, blade, anchor, anchor_dense, rotor, rotor_small, couplingdown;
//! `trispline fit --domain mesh`): the simplification took 0.46-0.64 of its time in one
//! piece, the fits' RMS 0.83-1.10 times theirs (geometric mean 1.00).
//!
//! The halves run as one `rayon::join`: a caller may itself run on rayon's threads (the
//! control mesh's guarded and unguarded simplifications are simplified side by side), and
//! a half's topology is built by rayon, so halves on threads of their own, waited for by
//! a rayon thread that steals nothing meanwhile, could leave rayon no thread to build it.
//!
//! Taken only without kept vertices (part meshes are small), and only when the halves'
//! topologies build: otherwise the caller simplifies in one piece.

use super::carry::{bounding_ball, Landings};
use super::crease::Creases;
use super::quadric::initial_quadrics;
use super::state::State;
use super::vertex::Vertex;
use super::{collapse, run_passes, Simplified, SimplifyOptions, FAN_BATCHES, REMOVED};
use crate::mesh::distance::{barycentric_on, closest_on_triangle};
use crate::mesh::topology::{Topology, NONE};
use crate::mesh::TriMesh;
use glam::DVec3;
use rayon::prelude::*;

/// Meshes below this many vertices are simplified in one piece: the time saved is a few
/// milliseconds, and the cut is a larger share of the mesh. Tried at 5000 on CGAL's
/// object meshes of 5-20k vertices, the fits moved by -5 to +19 % in RMS (the collapse
/// order feeding the refinement's path), against about 1 % either way on larger meshes.
const MIN_VERTICES: usize = 20_000;

/// The halves stop at this many times the target between them: the glued mesh's queue
/// orders the rest.
const HANDOVER: usize = 2;

/// Whether `mesh` is simplified in halves (module docs).
pub(super) fn worth_halving(mesh: &TriMesh, opts: &SimplifyOptions, keep: &[bool]) -> bool {
    // Not on the machine's cores: the same mesh is simplified the same way everywhere
    // (a worker is a function of its input), and on one core the halves still save the
    // carrying of their collapses.
    let n = mesh.positions.len();
    n >= MIN_VERTICES && 4 * HANDOVER * opts.target_vertices.max(4) <= n && !keep.contains(&true)
}

/// One side's faces as a mesh of their own.
struct Half {
    mesh: TriMesh,
    /// Per vertex of `mesh`, the input vertex.
    original: Vec<u32>,
    /// Per input vertex, its vertex in `mesh` (`REMOVED`: not in this half).
    local: Vec<u32>,
    /// Per vertex of `mesh`, whether it is frozen (module docs).
    frozen: Vec<bool>,
    /// The crease edges between two of its vertices, in its numbering.
    crease_edges: Vec<[u32; 2]>,
    /// Vertices the half stops at.
    target: usize,
}

/// A half after its collapses, with its vertices' records (quadrics, locks) as they are.
struct Collapsed {
    simplified: Simplified,
    survivors: Vec<Vertex>,
    /// Per vertex of the half, the vertex its collapses led into.
    representative: Vec<u32>,
}

/// `mesh` simplified in two halves and then as a whole; `None` when it cannot be split
/// (see the module docs), and the caller simplifies it in one piece.
pub(super) fn simplify_in_halves(
    mesh: &TriMesh,
    topo: &Topology,
    opts: &SimplifyOptions,
    crease_edges: &[[u32; 2]],
) -> Option<Simplified> {
    let creases = Creases::new(topo, crease_edges);
    let halves = split(mesh, topo, &creases, opts.target_vertices.max(4))?;
    let (first, second) = rayon::join(
        || collapse_half(&halves[0], opts),
        || collapse_half(&halves[1], opts),
    );
    let collapsed = [first?, second?];
    let glued = glue(mesh, topo, opts, &creases, &halves, &collapsed)?;
    let rep = glued_representatives(&halves, &collapsed, &glued.union_of)?;
    let (face, bary) = land_points(&mesh.positions, &glued.mesh, &rep);
    let topo = Topology::from_mesh(&glued.mesh).ok()?;
    let (carrier, carried) = crossbeam_channel::bounded(FAN_BATCHES);
    let state = State::with_vertices(
        &glued.mesh,
        &topo,
        opts,
        Creases::new(&topo, &glued.crease_edges),
        glued.verts,
        Some(carrier),
    );
    let landings = Landings::landed(&mesh.positions, face, bary, glued.mesh.triangles.len());
    let (state, land_face, land_bary) = collapse(state, landings, carried, opts.target_vertices);
    let whole = state.finish(&land_face, &land_bary);
    let control_of = glued
        .union_of
        .iter()
        .map(|&u| match u {
            REMOVED => REMOVED,
            u => whole.control_of[u as usize],
        })
        .collect();
    let collapses = collapsed
        .iter()
        .map(|c| c.simplified.collapses)
        .sum::<usize>();
    Some(Simplified {
        control_of,
        collapses: collapses + whole.collapses,
        ..whole
    })
}

/// The two halves of `mesh` (module docs), or `None` when one side would be empty.
fn split(mesh: &TriMesh, topo: &Topology, creases: &Creases, target: usize) -> Option<[Half; 2]> {
    let (lo, hi) = crate::numeric::bounds(&mesh.positions)?;
    let extent = hi - lo;
    let axis = if extent.x >= extent.y && extent.x >= extent.z {
        0
    } else if extent.y >= extent.z {
        1
    } else {
        2
    };
    let pos = &mesh.positions;
    let key = |t: &[u32; 3]| t.iter().map(|&v| pos[v as usize][axis]).sum::<f64>();
    let keys: Vec<f64> = mesh.triangles.iter().map(key).collect();
    let mut sorted = keys.clone();
    let middle = sorted.len() / 2;
    let median = *sorted.select_nth_unstable_by(middle, f64::total_cmp).1;
    let mut side: Vec<usize> = keys.iter().map(|&k| usize::from(k >= median)).collect();
    if !unpinch(mesh, topo, &mut side) {
        return None;
    }
    // Bit s of `sides[v]`: v has a face on side s.
    let mut sides = vec![0u8; pos.len()];
    for (t, &s) in mesh.triangles.iter().zip(&side) {
        for &v in t {
            sides[v as usize] |= 1 << s;
        }
    }
    let frozen = frozen_vertices(topo, &sides);
    let free: [usize; 2] = [1, 2].map(|bit| {
        let only = sides.iter().zip(&frozen);
        only.filter(|&(&s, &f)| s == bit && !f).count()
    });
    let all_free = free[0] + free[1];
    if free.contains(&0) {
        return None;
    }
    let halves = [0, 1].map(|s| {
        let mut local = vec![REMOVED; pos.len()];
        let mut original = Vec::new();
        let mut triangles = Vec::new();
        for (t, _) in mesh.triangles.iter().zip(&side).filter(|(_, &f)| f == s) {
            triangles.push(t.map(|v| {
                if local[v as usize] == REMOVED {
                    local[v as usize] = original.len() as u32;
                    original.push(v);
                }
                local[v as usize]
            }));
        }
        let positions = original.iter().map(|&v| pos[v as usize]).collect();
        let frozen: Vec<bool> = original.iter().map(|&v| frozen[v as usize]).collect();
        let crease_edges = creases
            .edges_among(&local)
            .filter(|e| e.iter().all(|&v| v != REMOVED))
            .collect();
        let held = frozen.iter().filter(|&&f| f).count();
        let share = (HANDOVER * target * free[s]).div_ceil(all_free);
        Half {
            target: (held + share).min(original.len()),
            mesh: TriMesh::new(positions, triangles),
            original,
            local,
            frozen,
            crease_edges,
        }
    });
    Some(halves)
}

/// Moves faces across the cut until no vertex's faces on one side form two fans or more
/// (a pinch, which a half's topology refuses): all faces of such a vertex go to the side
/// that holds most of them. False when pinches remain after a few sweeps.
fn unpinch(mesh: &TriMesh, topo: &Topology, side: &mut [usize]) -> bool {
    let n = mesh.positions.len();
    for _ in 0..8 {
        // Per side and vertex: its faces there, and its edges between two faces there.
        let mut faces = [vec![0u32; n], vec![0u32; n]];
        let mut joins = [vec![0u32; n], vec![0u32; n]];
        for (f, t) in mesh.triangles.iter().enumerate() {
            let s = side[f];
            for (k, &v) in t.iter().enumerate() {
                faces[s][v as usize] += 1;
                let twin = topo.twin[3 * f + k];
                if twin != NONE && (twin as usize) > 3 * f + k && side[twin as usize / 3] == s {
                    joins[s][v as usize] += 1;
                    joins[s][t[(k + 1) % 3] as usize] += 1;
                }
            }
        }
        // A side's faces around a vertex form `faces - joins` fans.
        let pinched = |v: usize| {
            let fans = |s: usize| faces[s][v].saturating_sub(joins[s][v]);
            faces[0][v] > 0 && faces[1][v] > 0 && (fans(0) > 1 || fans(1) > 1)
        };
        let pinches: Vec<usize> = (0..n).filter(|&v| pinched(v)).collect();
        if pinches.is_empty() {
            return true;
        }
        for v in pinches {
            let to = usize::from(faces[1][v] > faces[0][v]);
            for &h in topo.ring_halfedges(v as u32).iter().filter(|&&h| h != NONE) {
                side[h as usize / 3] = to;
            }
        }
    }
    false
}

/// The cut vertices (faces on both sides) and every boundary loop that reaches one.
fn frozen_vertices(topo: &Topology, sides: &[u8]) -> Vec<bool> {
    let mut frozen: Vec<bool> = sides.iter().map(|&s| s == 3).collect();
    let mut stack: Vec<u32> = (0..sides.len() as u32)
        .filter(|&v| frozen[v as usize] && topo.is_boundary(v))
        .collect();
    // A boundary vertex's ring runs from one boundary neighbour to the other.
    while let Some(v) = stack.pop() {
        let ring = topo.ring(v);
        for next in [ring.first(), ring.last()].into_iter().flatten() {
            if topo.is_boundary(*next) && !frozen[*next as usize] {
                frozen[*next as usize] = true;
                stack.push(*next);
            }
        }
    }
    frozen
}

/// One half's collapses down to its target, its frozen vertices untouched and its points
/// not carried; `None` when its topology does not build.
fn collapse_half(half: &Half, opts: &SimplifyOptions) -> Option<Collapsed> {
    let topo = Topology::from_mesh(&half.mesh).ok()?;
    let creases = Creases::new(&topo, &half.crease_edges);
    let mut state = State::new(&half.mesh, &topo, opts, creases, None);
    for (v, _) in half.frozen.iter().enumerate().filter(|(_, &f)| f) {
        state.freeze(v);
    }
    run_passes(&mut state, half.target);
    let survivors = state.survivors();
    let representative = state.representatives();
    Some(Collapsed {
        simplified: state.finish(&[], &[]),
        survivors,
        representative,
    })
}

/// The glued mesh: its vertices' records and faces, and per input vertex its glued
/// vertex (`REMOVED` if a half collapsed it).
struct Glued {
    mesh: TriMesh,
    verts: Vec<Vertex>,
    union_of: Vec<u32>,
    /// Its crease edges: the halves' surviving ones and the input's between two
    /// survivors.
    crease_edges: Vec<[u32; 2]>,
}

/// The two collapsed halves glued along their shared frozen vertices. A frozen vertex's
/// record is the whole mesh's (a half saw only its own faces): its quadric summed over
/// its faces and crease edges alone, and its lock, as the one-piece simplification has
/// them.
fn glue(
    mesh: &TriMesh,
    topo: &Topology,
    opts: &SimplifyOptions,
    creases: &Creases,
    halves: &[Half; 2],
    collapsed: &[Collapsed; 2],
) -> Option<Glued> {
    let frozen = |v: usize| {
        halves
            .iter()
            .any(|h| h.local[v] != REMOVED && h.frozen[h.local[v] as usize])
    };
    let mut quadrics = initial_quadrics(mesh, topo, opts, frozen);
    creases.add_planes(&mesh.positions, topo, opts.boundary_weight, &mut quadrics);
    let corners = State::corners(mesh, topo, opts.corner_turn_deg);
    let crease_corners = creases.corners(&mesh.positions, topo, opts.corner_turn_deg);
    let mut crease_edges = Vec::new();
    let mut union_of = vec![REMOVED; mesh.positions.len()];
    let mut verts: Vec<Vertex> = Vec::new();
    let mut triangles = Vec::new();
    for (half, done) in halves.iter().zip(collapsed) {
        let simplified = &done.simplified;
        let mut glued_at = vec![REMOVED; simplified.mesh.positions.len()];
        for (local, &control) in simplified.control_of.iter().enumerate() {
            if control == REMOVED {
                continue;
            }
            let v = half.original[local] as usize;
            if union_of[v] == REMOVED {
                union_of[v] = verts.len() as u32;
                let mut record = *done.survivors.get(control as usize)?;
                if half.frozen[local] {
                    record.quadric = quadrics[v];
                    record.locked = corners[v] || crease_corners[v];
                    record.boundary = topo.is_boundary(v as u32);
                }
                verts.push(record);
            }
            glued_at[control as usize] = union_of[v];
        }
        for t in &simplified.mesh.triangles {
            triangles.push(t.map(|c| glued_at[c as usize]));
        }
        let glued_edge = |e: &[u32; 2]| e.map(|c| glued_at[c as usize]);
        crease_edges.extend(simplified.crease_edges.iter().map(glued_edge));
    }
    // A crease edge along the cut is a boundary edge of both halves, and neither kept
    // it; its ends are frozen, so it is an edge of the glued mesh still, as is every
    // input edge whose two ends survived.
    let survived = |e: &[u32; 2]| e.iter().all(|&v| v != REMOVED);
    crease_edges.extend(creases.edges_among(&union_of).filter(survived));
    for e in &mut crease_edges {
        e.sort_unstable();
    }
    crease_edges.sort_unstable();
    crease_edges.dedup();
    let removed = |v: &u32| *v == REMOVED;
    if triangles.iter().flatten().any(removed) || crease_edges.iter().flatten().any(removed) {
        return None;
    }
    let positions = verts.iter().map(|v| v.pos).collect();
    Some(Glued {
        mesh: TriMesh::new(positions, triangles),
        verts,
        union_of,
        crease_edges,
    })
}

/// Per input vertex, the glued vertex its half's collapses led it into.
fn glued_representatives(
    halves: &[Half; 2],
    collapsed: &[Collapsed; 2],
    union_of: &[u32],
) -> Option<Vec<u32>> {
    let rep: Vec<u32> = (0..union_of.len())
        .map(|v| {
            let s = usize::from(halves[0].local[v] == REMOVED);
            let rep = collapsed[s].representative[halves[s].local[v] as usize];
            union_of[halves[s].original[rep as usize] as usize]
        })
        .collect();
    (!rep.contains(&REMOVED)).then_some(rep)
}

/// Where every input point lands on the glued mesh (a face and barycentric weights):
/// the nearest face around its representative `rep` or around that vertex's neighbours.
/// The points are taken by representative, so each one's nearby faces are listed once.
fn land_points(points: &[DVec3], glued: &TriMesh, rep: &[u32]) -> (Vec<u32>, Vec<[f64; 3]>) {
    let (positions, triangles) = (&glued.positions, &glued.triangles);
    let mut vfaces = vec![Vec::new(); positions.len()];
    for (f, t) in triangles.iter().enumerate() {
        for &v in t {
            vfaces[v as usize].push(f as u32);
        }
    }
    // The points grouped by representative (a counting sort).
    let mut start = vec![0usize; positions.len() + 1];
    for &g in rep {
        start[g as usize + 1] += 1;
    }
    for g in 0..positions.len() {
        start[g + 1] += start[g];
    }
    let mut by_rep = vec![0u32; rep.len()];
    let mut next = start.clone();
    for (p, &g) in rep.iter().enumerate() {
        by_rep[next[g as usize]] = p as u32;
        next[g as usize] += 1;
    }
    let per_vertex: Vec<Vec<(u32, Landed)>> = (0..positions.len())
        .into_par_iter()
        .map(|g| {
            let own = &by_rep[start[g]..start[g + 1]];
            if own.is_empty() {
                return Vec::new();
            }
            let near = faces_near(g as u32, positions, triangles, &vfaces);
            let land = |&p: &u32| (p, land_on(points[p as usize], &near));
            own.iter().map(land).collect()
        })
        .collect();
    let mut landed: Vec<Landed> = vec![(0, [0.0; 3]); rep.len()];
    for (p, landing) in per_vertex.into_iter().flatten() {
        landed[p as usize] = landing;
    }
    landed.into_iter().unzip()
}

/// The faces around `vertex` and then those around its neighbours, each once, with
/// their corners and bounding balls.
fn faces_near(
    vertex: u32,
    positions: &[DVec3],
    triangles: &[[u32; 3]],
    vfaces: &[Vec<u32>],
) -> Vec<NearFace> {
    let own = &vfaces[vertex as usize];
    let mut beyond: Vec<u32> = own
        .iter()
        .flat_map(|&f| triangles[f as usize])
        .flat_map(|v| vfaces[v as usize].iter().copied())
        .filter(|f| !own.contains(f))
        .collect();
    beyond.sort_unstable();
    beyond.dedup();
    let near = own.iter().chain(&beyond).map(|&face| {
        let corners = triangles[face as usize].map(|x| positions[x as usize]);
        let (centre, radius) = bounding_ball(corners);
        NearFace {
            face,
            corners,
            centre,
            radius,
        }
    });
    near.collect()
}

/// A point's face and barycentric weights there.
type Landed = (u32, [f64; 3]);

/// A face `faces_near` a vertex.
struct NearFace {
    face: u32,
    corners: [DVec3; 3],
    centre: DVec3,
    radius: f64,
}

/// Where `point` lands on the glued mesh: the nearest of the faces `near` its
/// representative (`faces_near`), as a face and barycentric weights. Only faces near where
/// the collapses took the point are looked at, so a point of a thin part stays on its own
/// side, as carrying keeps it. A face whose bounding ball lies further than the nearest
/// face so far cannot win and is not projected onto.
fn land_on(point: DVec3, near: &[NearFace]) -> Landed {
    let mut best: Option<(f64, &NearFace, DVec3)> = None;
    for candidate in near {
        let gap = point.distance(candidate.centre) - candidate.radius;
        if let Some((d2, _, _)) = best {
            // The slack covers the rounding of the distances compared (as `carry`).
            if gap > 0.0 && gap * gap > d2 * (1.0 + 1e-9) {
                continue;
            }
        }
        let [a, b, c] = candidate.corners;
        let on = closest_on_triangle(point, a, b, c);
        let d2 = on.distance_squared(point);
        if best.is_none_or(|(least, _, _)| d2 < least) {
            best = Some((d2, candidate, on));
        }
    }
    match best {
        Some((_, face, on)) => (face.face, barycentric_on(on, face.corners)),
        None => (0, [1.0, 0.0, 0.0]),
    }
}

#[cfg(test)]
#[path = "halves_tests.rs"]
mod tests;
