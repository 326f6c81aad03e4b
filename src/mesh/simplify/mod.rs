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

pub mod baseline;
mod carry;
mod crease;
mod quadric;
mod summary;

use super::topology::{Topology, TopologyError, NONE};
use super::TriMesh;
use carry::{Fans, Landings};
use crease::Creases;
use crossbeam_channel::Sender;
use glam::DVec3;
use quadric::Quadric;
use rayon::prelude::*;
use std::cmp::Reverse;
use std::collections::BinaryHeap;
pub use summary::SurfaceTopology;

/// Marks an input vertex that was collapsed away (`Simplified::control_of`).
pub const REMOVED: u32 = u32::MAX;

/// Target size and the guards a collapse must pass (see the module docs).
#[derive(Clone, Debug)]
pub struct SimplifyOptions {
    /// Vertices left at the end (at least 4; fewer if no further collapse is allowed).
    pub target_vertices: usize,
    /// Most faces around an interior vertex; a boundary vertex has one less.
    pub max_faces_per_vertex: usize,
    /// Triangle quality `4 sqrt(3) area / sum of squared edges` (1 for equilateral) that a
    /// collapse may not go below unless the faces it replaces were already worse.
    pub min_quality: f64,
    /// A collapse may turn no remaining face's normal by more than this.
    pub max_normal_turn_deg: f64,
    /// Weight of a boundary edge's constraint plane relative to face planes of the same
    /// squared size.
    pub boundary_weight: f64,
    /// Boundary vertices where the boundary turns by more than this stay where they are.
    pub corner_turn_deg: f64,
    /// Weight of the edge length to the fourth power (the quadric error's units) added to
    /// each collapse's cost. 0 is plain quadric decimation, the best piecewise-linear
    /// approximation for the count; a positive weight collapses short edges first, giving
    /// the more even, isotropic triangles a control mesh needs (a Loop limit surface over
    /// long thin faces and widely spread valences fits far worse than over an even mesh).
    pub isotropy: f64,
    /// Edges a boundary loop keeps at least (a loop that starts shorter keeps all of
    /// its edges); at least 3. A hole's rim is the cubic B-spline of its loop on a Loop
    /// surface: a loop of very few controls cannot follow a round rim.
    pub min_boundary_loop: usize,
}

impl Default for SimplifyOptions {
    fn default() -> Self {
        Self {
            target_vertices: 1000,
            max_faces_per_vertex: 12,
            min_quality: 0.15,
            max_normal_turn_deg: 60.0,
            boundary_weight: 20.0,
            corner_turn_deg: 75.0,
            isotropy: 0.0,
            min_boundary_loop: 3,
        }
    }
}

/// Where an input vertex lies on the simplified mesh: a face and the barycentric weights of
/// its corners 0 and 1 (corner 2 has `1 - u - v`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Landing {
    /// Index into the simplified mesh's `triangles`.
    pub face: u32,
    /// Barycentric weight of the face's corner 0.
    pub u: f64,
    /// Barycentric weight of the face's corner 1.
    pub v: f64,
}

/// The result of [`simplify`]: the control mesh and how the input vertices map onto it.
#[derive(Clone, Debug)]
pub struct Simplified {
    /// The simplified mesh, vertices renumbered densely (input order kept).
    pub mesh: TriMesh,
    /// Per input vertex: the vertex of `mesh` it became, or `REMOVED`.
    pub control_of: Vec<u32>,
    /// Per input vertex: where it lies on `mesh`.
    pub landing: Vec<Landing>,
    /// Edge collapses performed (input vertices minus output vertices).
    pub collapses: usize,
    /// Boundary vertices and crease corners locked in place.
    pub locked_corners: usize,
    /// The crease edges kept, in `mesh`'s numbering (low index first, sorted).
    pub crease_edges: Vec<[u32; 2]>,
}

/// Why [`simplify`] refused a mesh.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum SimplifyError {
    /// The mesh has no triangles.
    #[error("the mesh has no faces")]
    NoFaces,
    /// A vertex is used by no triangle, so it could never land on the simplified mesh.
    #[error("vertex {vertex} belongs to no face")]
    IsolatedVertex {
        /// Index of the unused vertex in the input mesh.
        vertex: usize,
    },
    /// No half-edge topology could be built: a bad face or a non-manifold edge.
    #[error("the mesh is not a manifold")]
    NonManifold(#[source] TopologyError),
}

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
    if mesh.triangles.is_empty() {
        return Err(SimplifyError::NoFaces);
    }
    let topo = Topology::from_mesh(mesh).map_err(SimplifyError::NonManifold)?;
    if let Some(vertex) = topo.face_valence.iter().position(|&n| n == 0) {
        return Err(SimplifyError::IsolatedVertex { vertex });
    }
    let (carrier, carried) = crossbeam_channel::bounded(FAN_BATCHES);
    let creases = Creases::new(&topo, crease_edges);
    let mut state = State::new(mesh, &topo, opts, creases, carrier);
    for (locked, &kept) in state.locked.iter_mut().zip(keep) {
        *locked |= kept;
    }
    let landings = Landings::new(&mesh.positions, &state.faces, &state.vfaces);
    let target = opts.target_vertices.max(4);
    let simplified = std::thread::scope(|scope| {
        let carrier = scope.spawn(move || landings.carry_all(carried));
        // Owned here so that a panic drops it, and with it the sender the carrier waits
        // on, before the scope waits for the carrier.
        let mut state = state;
        // Edges refused in one pass may be allowed after their neighbourhood changed.
        for _ in 0..4 {
            if state.alive_vertices <= target || state.run_pass(target) == 0 {
                break;
            }
        }
        state.stop_carrying();
        let (land_face, land_bary) = carrier
            .join()
            .unwrap_or_else(|panic| std::panic::resume_unwind(panic));
        state.finish(&land_face, &land_bary)
    });
    Ok(simplified)
}

/// Batches of collapses the collapsing thread may run ahead of the carrying one: enough
/// that neither waits on the other's short stalls, few enough that the fans queued stay
/// small (a collapse is some hundred bytes).
const FAN_BATCHES: usize = 16;

/// Queue entry: cost bits (non-negative f64 order as u64), the edge, and the versions of
/// its end points when it was queued.
type Entry = Reverse<(u64, u32, u32, u32, u32)>;

/// The heap is cleared of stale entries once it holds more than this many per live vertex
/// (a live mesh has about 3 edges per vertex). On bun_zipper subdivided once (140k
/// vertices to 2.5k) the simplification took 2.4-2.7 s without clearing, 2.1-2.2 s at 8,
/// 2.0 s at 5, with the same collapses.
const STALE_HEAP_FACTOR: usize = 5;

struct Candidate {
    keep: u32,
    remove: u32,
    position: DVec3,
    quadric: Quadric,
    cost: f64,
}

struct State<'a> {
    opts: &'a SimplifyOptions,
    cos_turn: f64,
    pos: Vec<DVec3>,
    quadric: Vec<Quadric>,
    faces: Vec<[u32; 3]>,
    face_alive: Vec<bool>,
    vfaces: Vec<Vec<u32>>,
    boundary: Vec<bool>,
    locked: Vec<bool>,
    creases: Creases,
    alive: Vec<bool>,
    alive_vertices: usize,
    version: Vec<u32>,
    /// Collapses not yet sent to be carried ...
    fans: Fans,
    /// ... and where they go (`carry`); `None` once the last went.
    carrier: Option<Sender<Fans>>,
    collapses: usize,
}

fn face_normal(p: [DVec3; 3]) -> DVec3 {
    (p[1] - p[0]).cross(p[2] - p[0])
}

fn quality(p: [DVec3; 3]) -> f64 {
    let edges = (p[1] - p[0]).length_squared()
        + (p[2] - p[1]).length_squared()
        + (p[0] - p[2]).length_squared();
    if edges <= 0.0 {
        return 0.0;
    }
    2.0 * 3f64.sqrt() * face_normal(p).length() / edges
}

impl<'a> State<'a> {
    fn new(
        mesh: &'a TriMesh,
        topo: &Topology,
        opts: &'a SimplifyOptions,
        creases: Creases,
        carrier: Sender<Fans>,
    ) -> Self {
        let nv = mesh.positions.len();
        let nf = mesh.triangles.len();
        let pos = mesh.positions.clone();
        let mut quadric = vec![Quadric::default(); nv];
        let mut vfaces: Vec<Vec<u32>> = (0..nv)
            .map(|v| Vec::with_capacity(topo.face_valence[v] as usize))
            .collect();
        for (f, t) in mesh.triangles.iter().enumerate() {
            let p = t.map(|v| pos[v as usize]);
            let n = face_normal(p);
            let area = 0.5 * n.length();
            let unit = n.normalize_or_zero();
            let plane = Quadric::plane(unit, p[0], area);
            for (k, &v) in t.iter().enumerate() {
                quadric[v as usize].add(&plane);
                vfaces[v as usize].push(f as u32);
                if topo.twin[3 * f + k] == NONE {
                    let (a, b) = (p[k], p[(k + 1) % 3]);
                    let side = (b - a).cross(unit).normalize_or_zero();
                    let weight = opts.boundary_weight * (b - a).length_squared();
                    let constraint = Quadric::plane(side, a, weight);
                    quadric[v as usize].add(&constraint);
                    quadric[t[(k + 1) % 3] as usize].add(&constraint);
                }
            }
        }
        creases.add_planes(&mesh.positions, topo, opts.boundary_weight, &mut quadric);
        let mut locked = Self::corners(mesh, topo, opts.corner_turn_deg);
        let crease_corners = creases.corners(&mesh.positions, topo, opts.corner_turn_deg);
        for (l, c) in locked.iter_mut().zip(crease_corners) {
            *l |= c;
        }
        State {
            opts,
            cos_turn: opts.max_normal_turn_deg.to_radians().cos(),
            pos,
            quadric,
            faces: mesh.triangles.clone(),
            face_alive: vec![true; nf],
            vfaces,
            boundary: topo.boundary.clone(),
            locked,
            creases,
            alive: vec![true; nv],
            alive_vertices: nv,
            version: vec![0; nv],
            fans: Fans::default(),
            carrier: Some(carrier),
            collapses: 0,
        }
    }

    /// Boundary vertices where the boundary turns by more than `turn_deg` (the angle
    /// between the two boundary edges, seen from inside, is below 180 - turn).
    fn corners(mesh: &TriMesh, topo: &Topology, turn_deg: f64) -> Vec<bool> {
        let min_angle = (180.0 - turn_deg).to_radians();
        (0..mesh.positions.len() as u32)
            .map(|v| {
                let ring = topo.ring(v);
                if !topo.is_boundary(v) || ring.len() < 2 {
                    return false;
                }
                let p = mesh.positions[v as usize];
                let first = mesh.positions[ring[0] as usize] - p;
                let last = mesh.positions[ring[ring.len() - 1] as usize] - p;
                // The interior angle is the sum of the face angles at v.
                let interior: f64 = ring
                    .windows(2)
                    .map(|w| {
                        let a = mesh.positions[w[0] as usize] - p;
                        let b = mesh.positions[w[1] as usize] - p;
                        a.angle_between(b)
                    })
                    .sum();
                first.length() > 0.0 && last.length() > 0.0 && interior < min_angle
            })
            .collect()
    }

    fn run_pass(&mut self, target: usize) -> usize {
        // Every edge's candidate at once, in parallel, heapified in O(n): the entries are
        // totally ordered (cost, then the edge), so the pop order is that of pushing them
        // one by one.
        let this = &*self;
        let entries: Vec<Entry> = (0..this.faces.len())
            .into_par_iter()
            .filter(|&f| this.face_alive[f])
            .flat_map_iter(|f| {
                (0..3).filter_map(move |k| {
                    let (a, b) = (this.faces[f][k], this.faces[f][(k + 1) % 3]);
                    // Each interior edge once (from the face where it runs upwards); a
                    // boundary edge may run either way, so it is queued in both cases.
                    (a < b || !this.edge_is_interior(a, b))
                        .then(|| this.entry(a, b))
                        .flatten()
                })
            })
            .collect();
        let mut heap: BinaryHeap<Entry> = BinaryHeap::from(entries);
        let before = self.collapses;
        while self.alive_vertices > target {
            let Some(Reverse((_, a, b, va, vb))) = heap.pop() else {
                break;
            };
            let (ai, bi) = (a as usize, b as usize);
            if !self.alive[ai]
                || !self.alive[bi]
                || self.version[ai] != va
                || self.version[bi] != vb
            {
                continue;
            }
            let Some(c) = self.candidate(a, b) else {
                continue;
            };
            if !self.allowed(&c) {
                continue;
            }
            self.collapse(&c);
            for x in self.neighbours(c.keep) {
                self.push(&mut heap, c.keep, x);
            }
            // Every collapse leaves the entries of the edges it changed behind in the heap,
            // unreachable until popped; dropping them in bulk keeps the heap near the
            // edge count (about 3 per vertex) instead of the pushes so far, and the
            // sift-downs, which miss the cache, in a smaller array.
            if heap.len() > STALE_HEAP_FACTOR * self.alive_vertices {
                heap.retain(|e| self.is_current(e));
            }
        }
        self.collapses - before
    }

    /// Whether a heap entry still stands for an edge as it is (both ends alive and not
    /// collapsed into since it was queued).
    fn is_current(&self, e: &Entry) -> bool {
        let Reverse((_, a, b, va, vb)) = *e;
        let (a, b) = (a as usize, b as usize);
        self.alive[a] && self.alive[b] && self.version[a] == va && self.version[b] == vb
    }

    fn push(&self, heap: &mut BinaryHeap<Entry>, a: u32, b: u32) {
        if let Some(e) = self.entry(a, b) {
            heap.push(e);
        }
    }

    fn entry(&self, a: u32, b: u32) -> Option<Entry> {
        let (a, b) = (a.min(b), a.max(b));
        let c = self.candidate(a, b)?;
        let cost = if c.cost.is_finite() { c.cost } else { f64::MAX };
        Some(Reverse((
            cost.to_bits(),
            a,
            b,
            self.version[a as usize],
            self.version[b as usize],
        )))
    }

    fn edge_is_interior(&self, a: u32, b: u32) -> bool {
        self.shared_faces(a, b).len() == 2
    }

    fn shared_faces(&self, a: u32, b: u32) -> Vec<u32> {
        self.vfaces[a as usize]
            .iter()
            .copied()
            .filter(|&f| self.faces[f as usize].contains(&b))
            .collect()
    }

    fn neighbours(&self, v: u32) -> Vec<u32> {
        let mut n: Vec<u32> = self.vfaces[v as usize]
            .iter()
            .flat_map(|&f| self.faces[f as usize])
            .filter(|&x| x != v)
            .collect();
        n.sort_unstable();
        n.dedup();
        n
    }

    /// Which end stays and where it goes: a locked or boundary end stays in place when the
    /// other is free or interior (the boundary keeps its shape), otherwise the lower index
    /// stays and moves to the quadric's minimiser (on the edge where that is singular).
    fn candidate(&self, a: u32, b: u32) -> Option<Candidate> {
        let (ai, bi) = (a as usize, b as usize);
        if self.locked[ai] && self.locked[bi] {
            return None;
        }
        let q = self.quadric[ai].sum(&self.quadric[bi]);
        // A locked end stays whatever the other is; a locked interior end and a boundary
        // end would move the boundary inwards or remove the locked vertex: no collapse.
        let pinned_inside =
            |l: usize, o: usize| self.locked[l] && !self.boundary[l] && self.boundary[o];
        if pinned_inside(ai, bi) || pinned_inside(bi, ai) {
            return None;
        }
        let fixed = if self.locked[ai] {
            Some((a, b))
        } else if self.locked[bi] {
            Some((b, a))
        } else if self.boundary[ai] && !self.boundary[bi] {
            Some((a, b))
        } else if self.boundary[bi] && !self.boundary[ai] {
            Some((b, a))
        } else if self.creases.count(a) > 0 && !self.creases.is_crease(a, b) {
            // Off a chain only a crease vertex with a smooth neighbour may be collapsed
            // (`Creases::allows`): the crease vertex stays.
            Some((a, b))
        } else if self.creases.count(b) > 0 && !self.creases.is_crease(a, b) {
            Some((b, a))
        } else {
            None
        };
        let (keep, remove, position) = match fixed {
            Some((k, r)) => (k, r, self.pos[k as usize]),
            None => {
                let (pa, pb) = (self.pos[ai], self.pos[bi]);
                let mid = (pa + pb) * 0.5;
                let reach = 2.0 * (pa - pb).length();
                let x = q
                    .minimiser(mid, reach)
                    .unwrap_or_else(|| q.segment_minimiser(pa, pb));
                (a.min(b), a.max(b), x)
            }
        };
        let length2 = (self.pos[ai] - self.pos[bi]).length_squared();
        Some(Candidate {
            keep,
            remove,
            position,
            cost: q.error(position) + self.opts.isotropy * length2 * length2,
            quadric: q,
        })
    }

    /// The topological and geometric guards of the module comment.
    fn allowed(&self, c: &Candidate) -> bool {
        let (k, r) = (c.keep, c.remove);
        let (ki, ri) = (k as usize, r as usize);
        if self.alive_vertices <= 4 {
            return false;
        }
        let shared = self.shared_faces(k, r);
        let on_boundary = match shared.len() {
            1 => true,
            2 => false,
            _ => return false,
        };
        if self.boundary[ki] && self.boundary[ri] && !on_boundary {
            return false;
        }
        if !self.creases.allows(k, r, &self.boundary) {
            return false;
        }
        let mut opposite: Vec<u32> = shared
            .iter()
            .flat_map(|&f| self.faces[f as usize])
            .filter(|&x| x != k && x != r)
            .collect();
        opposite.sort_unstable();
        let nk = self.neighbours(k);
        let common: Vec<u32> = self
            .neighbours(r)
            .into_iter()
            .filter(|x| nk.binary_search(x).is_ok())
            .collect();
        if common != opposite {
            return false;
        }
        if on_boundary && self.boundary_loop_at_most(k, r, self.opts.min_boundary_loop.max(3)) {
            return false;
        }
        if !self.face_counts_allowed(k, r, shared.len(), &opposite) {
            return false;
        }
        self.geometry_allowed(c)
    }

    fn face_counts_allowed(&self, k: u32, r: u32, shared: usize, opposite: &[u32]) -> bool {
        let (ki, ri) = (k as usize, r as usize);
        let merged = self.vfaces[ki].len() + self.vfaces[ri].len() - 2 * shared;
        let max = self.opts.max_faces_per_vertex;
        let (lo, hi) = if self.boundary[ki] || self.boundary[ri] {
            (2, max.saturating_sub(1))
        } else {
            (3, max)
        };
        if merged < lo || merged > hi {
            return false;
        }
        opposite.iter().all(|&o| {
            let min = if self.boundary[o as usize] { 2 } else { 3 };
            self.vfaces[o as usize].len() > min
        })
    }

    fn geometry_allowed(&self, c: &Candidate) -> bool {
        let (k, r) = (c.keep, c.remove);
        let mut worst_before = f64::INFINITY;
        let mut worst_after = f64::INFINITY;
        for &f in self.vfaces[k as usize]
            .iter()
            .chain(&self.vfaces[r as usize])
        {
            let t = self.faces[f as usize];
            if t.contains(&k) && t.contains(&r) {
                continue;
            }
            let before = t.map(|v| self.pos[v as usize]);
            let after = t.map(|v| {
                if v == k || v == r {
                    c.position
                } else {
                    self.pos[v as usize]
                }
            });
            let (n0, n1) = (face_normal(before), face_normal(after));
            let (l0, l1) = (n0.length(), n1.length());
            if l1 <= 0.0 || (l0 > 0.0 && n0.dot(n1) < self.cos_turn * l0 * l1) {
                return false;
            }
            worst_before = worst_before.min(quality(before));
            worst_after = worst_after.min(quality(after));
        }
        worst_after >= self.opts.min_quality.min(worst_before)
    }

    /// Whether the boundary edge (a, b) lies on a loop of at most `edges` edges.
    fn boundary_loop_at_most(&self, a: u32, b: u32, edges: usize) -> bool {
        let (mut prev, mut cur) = (a, b);
        for _ in 0..edges - 1 {
            let Some(next) = self.next_on_boundary(cur, prev) else {
                return false;
            };
            if next == a {
                return true;
            }
            (prev, cur) = (cur, next);
        }
        false
    }

    /// The boundary neighbour of `v` other than `prev`.
    fn next_on_boundary(&self, v: u32, prev: u32) -> Option<u32> {
        let mut seen: Vec<(u32, u32)> = Vec::with_capacity(16);
        for &f in &self.vfaces[v as usize] {
            for x in self.faces[f as usize] {
                if x == v {
                    continue;
                }
                match seen.iter_mut().find(|(y, _)| *y == x) {
                    Some(e) => e.1 += 1,
                    None => seen.push((x, 1)),
                }
            }
        }
        seen.iter()
            .find(|&&(x, count)| count == 1 && x != prev)
            .map(|&(x, _)| x)
    }

    fn collapse(&mut self, c: &Candidate) {
        let (k, r) = (c.keep, c.remove);
        let (ki, ri) = (k as usize, r as usize);
        let mut affected: Vec<u32> = self.vfaces[ki].clone();
        affected.extend(self.vfaces[ri].iter().copied().filter(|f| {
            let t = self.faces[*f as usize];
            !t.contains(&k)
        }));
        for f in self.shared_faces(k, r) {
            self.face_alive[f as usize] = false;
            for v in self.faces[f as usize] {
                self.vfaces[v as usize].retain(|&g| g != f);
            }
        }
        let moved = std::mem::take(&mut self.vfaces[ri]);
        for f in moved {
            for v in self.faces[f as usize].iter_mut() {
                if *v == r {
                    *v = k;
                }
            }
            self.vfaces[ki].push(f);
        }
        self.pos[ki] = c.position;
        self.quadric[ki] = c.quadric;
        self.boundary[ki] |= self.boundary[ri];
        self.creases.merge(k, r);
        self.alive[ri] = false;
        self.alive_vertices -= 1;
        self.version[ki] += 1;
        self.version[ri] += 1;
        self.collapses += 1;
        self.carry_points(k, &affected);
    }

    /// Queues the new fan around `k` and the faces whose points move onto it for the
    /// carrying thread, and sends a full batch.
    fn carry_points(&mut self, k: u32, affected: &[u32]) {
        let fan = self.vfaces[k as usize]
            .iter()
            .map(|&f| (f, self.faces[f as usize].map(|v| self.pos[v as usize])));
        self.fans.push(fan, affected);
        if self.fans.len() >= Fans::BATCH {
            self.send_fans();
        }
    }

    /// Sends the queued fans to the carrying thread.
    fn send_fans(&mut self) {
        let batch = std::mem::take(&mut self.fans);
        if let Some(carrier) = &self.carrier {
            // A send fails only when the carrier is gone, which only its panic does; the
            // join passes that on.
            let _ = carrier.send(batch);
        }
    }

    /// Sends the last fans and lets the carrying thread finish.
    fn stop_carrying(&mut self) {
        self.send_fans();
        self.carrier = None;
    }

    fn finish(self, land_face: &[u32], land_bary: &[[f64; 3]]) -> Simplified {
        let mut control_of = vec![REMOVED; self.pos.len()];
        let mut positions = Vec::with_capacity(self.alive_vertices);
        for (v, &alive) in self.alive.iter().enumerate() {
            if alive {
                control_of[v] = positions.len() as u32;
                positions.push(self.pos[v]);
            }
        }
        let mut face_index = vec![u32::MAX; self.faces.len()];
        let mut triangles = Vec::new();
        for (f, t) in self.faces.iter().enumerate() {
            if self.face_alive[f] {
                face_index[f] = triangles.len() as u32;
                triangles.push(t.map(|v| control_of[v as usize]));
            }
        }
        let landing = land_face
            .iter()
            .zip(land_bary)
            .map(|(&f, b)| Landing {
                face: face_index[f as usize],
                u: b[0],
                v: b[1],
            })
            .collect();
        let locked_corners = self.locked.iter().filter(|&&l| l).count();
        let crease_edges = self.creases.edges(&control_of);
        Simplified {
            mesh: TriMesh::new(positions, triangles),
            control_of,
            landing,
            collapses: self.collapses,
            locked_corners,
            crease_edges,
        }
    }
}

#[cfg(test)]
pub(crate) mod tests;
