//! Control meshes by simplification: topology-preserving quadric-error edge collapse
//! (Garland & Heckbert 1997) of a cleaned manifold mesh down to a target vertex count.
//!
//! A collapse is taken only if it keeps the surface's topology and a usable control mesh:
//! the link condition (the two end points share exactly the neighbours opposite the edge),
//! no interior edge between two boundary vertices (that would pinch or bridge a hole), no
//! boundary loop below `min_boundary_loop` edges, faces per vertex in 3..=max (2.. on the
//! boundary), no
//! face turning by more than `max_normal_turn_deg`, no face worse than both
//! `min_quality` and the worst face it replaces. Boundary edges carry constraint planes
//! (perpendicular to their face through the edge) so holes keep their shape, and boundary
//! vertices where the boundary turns sharply are locked. Crease edges, when given, are
//! kept the same way (see `crease`): the control mesh then carries them.
//!
//! Every input vertex is carried along: it starts on one of its own faces, and each
//! collapse re-projects the points of the faces it changes onto the new fan around the
//! kept vertex (the nearest of those faces). A point so never leaves the neighbourhood it
//! came from, which a global closest-point projection at the end does not guarantee on thin
//! parts (ears, fingers) where the nearest control face may be on the other side.
//!
//! The order is deterministic: costs tie-break on the vertex indices, stale queue entries
//! are recognised by per-vertex versions (lazy invalidation).
//!
//! A large mesh is simplified in two halves side by side and then as a whole (`halves`):
//! the same guards, the collapses in another order, the points landed locally between
//! the stages.

pub mod baseline;
mod carry;
mod crease;
mod halves;
mod options;
mod quadric;
mod state;
mod summary;
mod vertex;

use super::topology::Topology;
use super::TriMesh;
use carry::{Fans, Landings};
use crease::Creases;
use crossbeam_channel::Receiver;
use glam::DVec3;
pub use options::{Landing, Simplified, SimplifyError, SimplifyOptions, REMOVED};
use state::State;
pub use summary::SurfaceTopology;

/// Simplifies `mesh` (manifold, consistently oriented: `mesh::clean`'s output) to
/// `opts.target_vertices` vertices or as close as the guards allow.
pub fn simplify(mesh: &TriMesh, opts: &SimplifyOptions) -> Result<Simplified, SimplifyError> {
    simplify_with_creases(mesh, opts, &[])
}

/// `simplify` keeping crease edges (pairs of vertex indices; pairs that are no interior
/// edge are ignored): collapses run along crease chains only and crease corners stay, so
/// every chain survives as a chain of control edges (`Simplified::crease_edges`).
pub fn simplify_with_creases(
    mesh: &TriMesh,
    opts: &SimplifyOptions,
    crease_edges: &[[u32; 2]],
) -> Result<Simplified, SimplifyError> {
    simplify_keeping(mesh, opts, crease_edges, &[])
}

/// The vertices of `mesh` the simplification keeps in place for `crease_edges` (crease
/// corners, chain ends, sharp turns along a chain, creases meeting the boundary): a
/// control mesh that carries these creases has at least as many vertices.
pub fn fixed_crease_vertices(
    mesh: &TriMesh,
    topo: &Topology,
    crease_edges: &[[u32; 2]],
    opts: &SimplifyOptions,
) -> Vec<bool> {
    Creases::new(topo, crease_edges).corners(&mesh.positions, topo, opts.corner_turn_deg)
}

/// [`simplify_with_creases`] that also keeps every vertex `keep` marks where it is (a
/// vertex past the end of `keep` is not kept): no collapse removes or moves it, so a face
/// whose corners are all kept comes out as it went in. Vertices stay in input order, so
/// kept vertices ahead of every other keep their indices, and so do faces ahead of every
/// face a collapse touched.
pub fn simplify_keeping(
    mesh: &TriMesh,
    opts: &SimplifyOptions,
    crease_edges: &[[u32; 2]],
    keep: &[bool],
) -> Result<Simplified, SimplifyError> {
    simplify_built(mesh, None, opts, crease_edges, keep)
}

/// [`simplify_with_creases`] of a mesh whose topology the caller has built already
/// (`Topology::from_mesh(mesh)`): on a 139k-vertex scan building it again took about
/// 30 ms of a 0.9 s simplification.
pub fn simplify_with_topology(
    mesh: &TriMesh,
    topo: &Topology,
    opts: &SimplifyOptions,
    crease_edges: &[[u32; 2]],
) -> Result<Simplified, SimplifyError> {
    simplify_built(mesh, Some(topo), opts, crease_edges, &[])
}

/// [`simplify_keeping`], with `mesh`'s topology when the caller has it.
fn simplify_built(
    mesh: &TriMesh,
    topo: Option<&Topology>,
    opts: &SimplifyOptions,
    crease_edges: &[[u32; 2]],
    keep: &[bool],
) -> Result<Simplified, SimplifyError> {
    if mesh.triangles.is_empty() {
        return Err(SimplifyError::NoFaces);
    }
    // Quadrics hold planes' offsets from the origin, and an edge's cost is their sum less
    // terms of the same size: far from the origin the costs cancel to noise (bun_zipper
    // moved 4000 km off, as in UTM coordinates, fitted at 66 um against 62). They are
    // summed around a local origin, which moves the points exactly.
    let origin = crate::numeric::local_origin(&mesh.positions);
    if origin == DVec3::ZERO {
        return simplify_centred(mesh, topo, opts, crease_edges, keep);
    }
    let centred = TriMesh::new(
        mesh.positions.iter().map(|p| *p - origin).collect(),
        mesh.triangles.clone(),
    );
    // Moved, not changed: the same topology.
    let mut simplified = simplify_centred(&centred, topo, opts, crease_edges, keep)?;
    for p in &mut simplified.mesh.positions {
        *p += origin;
    }
    Ok(simplified)
}

/// `simplify_keeping` of a mesh near the origin.
fn simplify_centred(
    mesh: &TriMesh,
    topo: Option<&Topology>,
    opts: &SimplifyOptions,
    crease_edges: &[[u32; 2]],
    keep: &[bool],
) -> Result<Simplified, SimplifyError> {
    let built;
    let topo = match topo {
        Some(topo) => topo,
        None => {
            built = Topology::from_mesh(mesh).map_err(SimplifyError::NonManifold)?;
            &built
        }
    };
    if let Some(vertex) = topo.face_valence.iter().position(|&n| n == 0) {
        return Err(SimplifyError::IsolatedVertex { vertex });
    }
    if halves::worth_halving(mesh, opts, keep) {
        if let Some(simplified) = halves::simplify_in_halves(mesh, topo, opts, crease_edges) {
            return Ok(simplified);
        }
    }
    Ok(simplify_in_one_piece(mesh, topo, opts, crease_edges, keep))
}

/// `simplify_centred` on one thread of collapses (and one carrying the points).
fn simplify_in_one_piece(
    mesh: &TriMesh,
    topo: &Topology,
    opts: &SimplifyOptions,
    crease_edges: &[[u32; 2]],
    keep: &[bool],
) -> Simplified {
    let (carrier, carried) = crossbeam_channel::bounded(FAN_BATCHES);
    let creases = Creases::new(topo, crease_edges);
    let mut state = State::new(mesh, topo, opts, creases, Some(carrier));
    for (v, _) in keep.iter().enumerate().filter(|(_, &kept)| kept) {
        state.lock(v);
    }
    let landings = Landings::new(&mesh.positions, &state.faces, &state.vfaces);
    let (state, land_face, land_bary) = collapse(state, landings, carried, opts.target_vertices);
    state.finish(&land_face, &land_bary)
}

/// The collapse passes of `state` down to `target` vertices (at least 4), with the input
/// points carried beside them on a thread of their own (`carried` is the receiving end
/// of `state`'s carrier): the state after the last collapse and every point's landing
/// (a face of `state` and barycentric weights).
fn collapse<'a>(
    state: State<'a>,
    landings: Landings<'_>,
    carried: Receiver<Fans>,
    target: usize,
) -> (State<'a>, Vec<u32>, Vec<[f64; 3]>) {
    let target = target.max(4);
    std::thread::scope(|scope| {
        let carrier = scope.spawn(move || landings.carry_all(carried));
        // Owned here so that a panic drops it, and with it the sender the carrier waits
        // on, before the scope waits for the carrier.
        let mut state = state;
        run_passes(&mut state, target);
        state.stop_carrying();
        let (land_face, land_bary) = carrier
            .join()
            .unwrap_or_else(|panic| std::panic::resume_unwind(panic));
        (state, land_face, land_bary)
    })
}

/// Collapse passes down to `target` vertices: edges refused in one pass may be allowed
/// after their neighbourhood changed.
fn run_passes(state: &mut State<'_>, target: usize) {
    for _ in 0..4 {
        if state.alive_vertices <= target || state.run_pass(target) == 0 {
            break;
        }
    }
}

/// Batches of collapses the collapsing thread may run ahead of the carrying one: enough
/// that neither waits on the other's short stalls, few enough that the fans queued stay
/// small (a collapse is some hundred bytes).
const FAN_BATCHES: usize = 16;

#[cfg(test)]
pub(crate) mod tests;
