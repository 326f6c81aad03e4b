//! The collapse loop of `simplify`: the mesh being collapsed (positions, quadrics, faces
//! around each vertex, locks), the queue of candidate collapses by quadric cost, and the
//! guards a collapse must pass.

use super::carry::Fans;
use super::crease::Creases;
use super::options::{Landing, Simplified, SimplifyOptions, REMOVED};
use super::quadric::{initial_quadrics, Quadric};
use super::vertex::{FaceList, Vertex};
use crate::mesh::topology::Topology;
use crate::mesh::{triangle_area_normal, triangle_quality, TriMesh};
use crossbeam_channel::Sender;
use dary_heap::QuaternaryHeap;
use glam::DVec3;
use rayon::prelude::*;
use std::cmp::Reverse;

/// Queue entry: the cost bits (non-negative f64 order as u64) and the edge in one key,
/// and the versions of its end points when it was queued. Entries are ordered by the key
/// alone, one integer comparison: two entries of one key are the same edge at the same
/// cost, of which at most one is current (versions only grow), so which of them pops
/// first changes nothing. The tuple of all five fields compared field by field was a
/// sixth of the collapse loop's time (the heap's sift-downs).
#[derive(Clone, Copy)]
struct Queued {
    key: u128,
    versions: [u32; 2],
}

impl Queued {
    fn edge(&self) -> (u32, u32) {
        ((self.key >> 32) as u32, self.key as u32)
    }
}

impl PartialEq for Queued {
    fn eq(&self, other: &Self) -> bool {
        self.key == other.key
    }
}

impl Eq for Queued {}

impl PartialOrd for Queued {
    fn partial_cmp(&self, other: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(other))
    }
}

impl Ord for Queued {
    fn cmp(&self, other: &Self) -> std::cmp::Ordering {
        self.key.cmp(&other.key)
    }
}

type Entry = Reverse<Queued>;

/// Buffers the guards of a collapse reuse (a collapse asks for three vertex rings: an
/// allocation each was a sixth of the loop's time).
#[derive(Default)]
struct Scratch {
    ring_keep: Vec<u32>,
    ring_remove: Vec<u32>,
    opposite: Vec<u32>,
}

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

pub(super) struct State<'a> {
    opts: &'a SimplifyOptions,
    cos_turn: f64,
    verts: Vec<Vertex>,
    pub(super) faces: Vec<[u32; 3]>,
    face_alive: Vec<bool>,
    pub(super) vfaces: Vec<FaceList>,
    creases: Creases,
    pub(super) alive_vertices: usize,
    /// Collapses not yet sent to be carried ...
    fans: Fans,
    /// ... and where they go (`carry`); `None` once the last went, or when the points
    /// are not carried.
    carrier: Option<Sender<Fans>>,
    /// Without a carrier, per vertex the one its collapse kept (`REMOVED`: alive), so
    /// that every input vertex's representative is known at the end.
    absorbed_by: Vec<u32>,
    collapses: usize,
    /// A collapse's changed faces and the faces it removes (buffers only).
    affected: Vec<u32>,
    shared: Vec<u32>,
}

impl<'a> State<'a> {
    pub(super) fn new(
        mesh: &'a TriMesh,
        topo: &Topology,
        opts: &'a SimplifyOptions,
        creases: Creases,
        carrier: Option<Sender<Fans>>,
    ) -> Self {
        let pos = &mesh.positions;
        let mut quadric = initial_quadrics(mesh, topo, opts, |_| true);
        creases.add_planes(pos, topo, opts.boundary_weight, &mut quadric);
        let corners = Self::corners(mesh, topo, opts.corner_turn_deg);
        let crease_corners = creases.corners(pos, topo, opts.corner_turn_deg);
        let locked = (0..pos.len()).map(|v| corners[v] || crease_corners[v]);
        let verts = quadric.into_iter().zip(locked).enumerate();
        let verts = verts
            .map(|(v, (quadric, locked))| Vertex {
                locked,
                quadric,
                ..Vertex::new(pos[v], topo.boundary[v])
            })
            .collect();
        Self::with_vertices(mesh, topo, opts, creases, verts, carrier)
    }

    /// The state of `mesh` with its vertices' records given (positions, quadrics and
    /// locks from an earlier simplification: `halves`).
    pub(super) fn with_vertices(
        mesh: &TriMesh,
        topo: &Topology,
        opts: &'a SimplifyOptions,
        creases: Creases,
        verts: Vec<Vertex>,
        carrier: Option<Sender<Fans>>,
    ) -> Self {
        let nf = mesh.triangles.len();
        let mut vfaces: Vec<FaceList> = topo
            .face_valence
            .iter()
            .map(|&n| FaceList::with_capacity(n as usize))
            .collect();
        for (f, t) in mesh.triangles.iter().enumerate() {
            for &v in t {
                vfaces[v as usize].push(f as u32);
            }
        }
        State {
            opts,
            cos_turn: opts.max_normal_turn_deg.to_radians().cos(),
            alive_vertices: verts.len(),
            verts,
            faces: mesh.triangles.clone(),
            face_alive: vec![true; nf],
            vfaces,
            creases,
            fans: Fans::default(),
            carrier,
            absorbed_by: Vec::new(),
            collapses: 0,
            affected: Vec::new(),
            shared: Vec::new(),
        }
    }

    /// Keeps vertex `v` where it is: no collapse removes or moves it.
    pub(super) fn lock(&mut self, v: usize) {
        if let Some(vertex) = self.verts.get_mut(v) {
            vertex.locked = true;
        }
    }

    /// Takes vertex `v` out of every collapse (`Vertex::frozen`).
    pub(super) fn freeze(&mut self, v: usize) {
        if let Some(vertex) = self.verts.get_mut(v) {
            vertex.frozen = true;
        }
    }

    /// The records of the vertices left, in their order (that of `finish`'s mesh), frozen
    /// ones freed.
    pub(super) fn survivors(&self) -> Vec<Vertex> {
        let alive = self.verts.iter().filter(|v| v.alive);
        alive
            .map(|v| Vertex {
                frozen: false,
                ..*v
            })
            .collect()
    }

    /// Per vertex, the alive vertex its collapses led into (itself while alive): where its
    /// point lies when the points were not carried.
    pub(super) fn representatives(&self) -> Vec<u32> {
        let n = self.verts.len();
        let mut rep: Vec<u32> = (0..n as u32)
            .map(|v| match self.absorbed_by.get(v as usize) {
                Some(&k) if k != REMOVED => k,
                _ => v,
            })
            .collect();
        // Path halving: every step points a vertex at its grandparent.
        for v in 0..n {
            let mut r = v;
            while rep[r] as usize != r {
                rep[r] = rep[rep[r] as usize];
                r = rep[r] as usize;
            }
            rep[v] = r as u32;
        }
        rep
    }

    /// Boundary vertices where the boundary turns by more than `turn_deg` (the angle
    /// between the two boundary edges, seen from inside, is below 180 - turn).
    pub(super) fn corners(mesh: &TriMesh, topo: &Topology, turn_deg: f64) -> Vec<bool> {
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

    pub(super) fn run_pass(&mut self, target: usize) -> usize {
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
        // Four children per node: half the levels of a binary heap, each level's children
        // in one or two cache lines. On 135k points (some 400k entries, most pops missing
        // the cache) the pops went from 6.1 to 2.4 % of a fit's samples, the
        // simplification from 1.24 to 1.14 s (medians of 6), the same collapses.
        let mut heap: QuaternaryHeap<Entry> = QuaternaryHeap::from(entries);
        let before = self.collapses;
        let mut scratch = Scratch::default();
        while self.alive_vertices > target {
            let Some(Reverse(queued)) = heap.pop() else {
                break;
            };
            if !self.is_current(&queued) {
                continue;
            }
            let (a, b) = queued.edge();
            let Some(c) = self.candidate(a, b) else {
                continue;
            };
            if !self.allowed(&c, &mut scratch) {
                continue;
            }
            self.collapse(&c);
            self.neighbours_into(c.keep, &mut scratch.ring_keep);
            for &x in &scratch.ring_keep {
                self.push(&mut heap, c.keep, x);
            }
            // Every collapse leaves the entries of the edges it changed behind in the heap,
            // unreachable until popped; dropping them in bulk keeps the heap near the
            // edge count (about 3 per vertex) instead of the pushes so far, and the
            // sift-downs, which miss the cache, in a smaller array.
            if heap.len() > STALE_HEAP_FACTOR * self.alive_vertices {
                heap.retain(|e| self.is_current(&e.0));
            }
        }
        self.collapses - before
    }

    /// Whether a heap entry still stands for an edge as it is (both ends alive and not
    /// collapsed into since it was queued).
    fn is_current(&self, e: &Queued) -> bool {
        let (a, b) = e.edge();
        let (a, b) = (a as usize, b as usize);
        let (a, b) = (&self.verts[a], &self.verts[b]);
        a.alive && b.alive && a.version == e.versions[0] && b.version == e.versions[1]
    }

    fn push(&self, heap: &mut QuaternaryHeap<Entry>, a: u32, b: u32) {
        if let Some(e) = self.entry(a, b) {
            heap.push(e);
        }
    }

    fn entry(&self, a: u32, b: u32) -> Option<Entry> {
        let (a, b) = (a.min(b), a.max(b));
        let c = self.candidate(a, b)?;
        let cost = if c.cost.is_finite() { c.cost } else { f64::MAX };
        Some(Reverse(Queued {
            key: (u128::from(cost.to_bits()) << 64) | (u128::from(a) << 32) | u128::from(b),
            versions: [
                self.verts[a as usize].version,
                self.verts[b as usize].version,
            ],
        }))
    }

    fn edge_is_interior(&self, a: u32, b: u32) -> bool {
        self.shared_faces(a, b).count() == 2
    }

    /// The live faces with both `a` and `b` as corners.
    fn shared_faces(&self, a: u32, b: u32) -> impl Iterator<Item = u32> + '_ {
        self.vfaces[a as usize]
            .iter()
            .copied()
            .filter(move |&f| self.faces[f as usize].contains(&b))
    }

    /// The vertices sharing a face with `v`, sorted, into `ring`.
    fn neighbours_into(&self, v: u32, ring: &mut Vec<u32>) {
        ring.clear();
        ring.extend(
            self.vfaces[v as usize]
                .iter()
                .flat_map(|&f| self.faces[f as usize])
                .filter(|&x| x != v),
        );
        ring.sort_unstable();
        ring.dedup();
    }

    /// Which end stays and where it goes: a locked or boundary end stays in place when the
    /// other is free or interior (the boundary keeps its shape), otherwise the lower index
    /// stays and moves to the quadric's minimiser (on the edge where that is singular).
    fn candidate(&self, a: u32, b: u32) -> Option<Candidate> {
        let (va, vb) = (&self.verts[a as usize], &self.verts[b as usize]);
        if (va.locked && vb.locked) || va.frozen || vb.frozen {
            return None;
        }
        let q = va.quadric.sum(&vb.quadric);
        // A locked end stays whatever the other is; a locked interior end and a boundary
        // end would move the boundary inwards or remove the locked vertex: no collapse.
        let pinned_inside = |l: &Vertex, o: &Vertex| l.locked && !l.boundary && o.boundary;
        if pinned_inside(va, vb) || pinned_inside(vb, va) {
            return None;
        }
        let fixed = if va.locked {
            Some((a, b))
        } else if vb.locked {
            Some((b, a))
        } else if va.boundary && !vb.boundary {
            Some((a, b))
        } else if vb.boundary && !va.boundary {
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
            Some((k, r)) => (k, r, self.verts[k as usize].pos),
            None => {
                let (pa, pb) = (va.pos, vb.pos);
                let mid = (pa + pb) * 0.5;
                let reach = 2.0 * (pa - pb).length();
                let x = q
                    .minimiser(mid, reach)
                    .unwrap_or_else(|| q.segment_minimiser(pa, pb));
                (a.min(b), a.max(b), x)
            }
        };
        let length2 = (va.pos - vb.pos).length_squared();
        Some(Candidate {
            keep,
            remove,
            position,
            cost: q.error(position) + self.opts.isotropy * length2 * length2,
            quadric: q,
        })
    }

    /// The topological and geometric guards of the module comment.
    fn allowed(&self, c: &Candidate, scratch: &mut Scratch) -> bool {
        let (k, r) = (c.keep, c.remove);
        let (ki, ri) = (k as usize, r as usize);
        if self.alive_vertices <= 4 {
            return false;
        }
        let shared = self.shared_faces(k, r).count();
        let on_boundary = match shared {
            1 => true,
            2 => false,
            _ => return false,
        };
        if self.verts[ki].boundary && self.verts[ri].boundary && !on_boundary {
            return false;
        }
        let boundary = |v: u32| self.verts[v as usize].boundary;
        if !self.creases.allows(k, r, boundary) {
            return false;
        }
        let opposite = &mut scratch.opposite;
        opposite.clear();
        opposite.extend(
            self.shared_faces(k, r)
                .flat_map(|f| self.faces[f as usize])
                .filter(|&x| x != k && x != r),
        );
        opposite.sort_unstable();
        self.neighbours_into(k, &mut scratch.ring_keep);
        self.neighbours_into(r, &mut scratch.ring_remove);
        // The link condition: the rings share exactly the vertices opposite the edge.
        let ring_keep = &scratch.ring_keep;
        let common = scratch
            .ring_remove
            .iter()
            .filter(|x| ring_keep.binary_search(x).is_ok());
        if !opposite.iter().eq(common) {
            return false;
        }
        if on_boundary && self.boundary_loop_at_most(k, r, self.opts.min_boundary_loop.max(3)) {
            return false;
        }
        if !self.face_counts_allowed(k, r, shared, opposite) {
            return false;
        }
        self.geometry_allowed(c)
    }

    fn face_counts_allowed(&self, k: u32, r: u32, shared: usize, opposite: &[u32]) -> bool {
        let (ki, ri) = (k as usize, r as usize);
        let merged = self.vfaces[ki].len() + self.vfaces[ri].len() - 2 * shared;
        let max = self.opts.max_faces_per_vertex;
        let (lo, hi) = if self.verts[ki].boundary || self.verts[ri].boundary {
            (2, max.saturating_sub(1))
        } else {
            (3, max)
        };
        if merged < lo || merged > hi {
            return false;
        }
        opposite.iter().all(|&o| {
            let min = if self.verts[o as usize].boundary {
                2
            } else {
                3
            };
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
            let before = t.map(|v| self.verts[v as usize].pos);
            let after = t.map(|v| {
                if v == k || v == r {
                    c.position
                } else {
                    self.verts[v as usize].pos
                }
            });
            let (n0, n1) = (triangle_area_normal(before), triangle_area_normal(after));
            let (l0, l1) = (n0.length(), n1.length());
            if l1 <= 0.0 || (l0 > 0.0 && n0.dot(n1) < self.cos_turn * l0 * l1) {
                return false;
            }
            worst_before = worst_before.min(triangle_quality(before));
            worst_after = worst_after.min(triangle_quality(after));
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
        // Buffers kept between collapses (an allocation each per collapse otherwise).
        let mut affected = std::mem::take(&mut self.affected);
        affected.clear();
        affected.extend_from_slice(&self.vfaces[ki]);
        affected.extend(self.vfaces[ri].iter().copied().filter(|f| {
            let t = self.faces[*f as usize];
            !t.contains(&k)
        }));
        let mut shared = std::mem::take(&mut self.shared);
        shared.clear();
        shared.extend(self.shared_faces(k, r));
        for &f in &shared {
            self.face_alive[f as usize] = false;
            for v in self.faces[f as usize] {
                self.vfaces[v as usize].retain(|g| *g != f);
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
        let removed_boundary = self.verts[ri].boundary;
        let kept = &mut self.verts[ki];
        kept.pos = c.position;
        kept.quadric = c.quadric;
        kept.boundary |= removed_boundary;
        kept.version += 1;
        let removed = &mut self.verts[ri];
        removed.alive = false;
        removed.version += 1;
        self.creases.merge(k, r);
        self.alive_vertices -= 1;
        self.collapses += 1;
        if self.carrier.is_some() {
            self.carry_points(k, &affected);
        } else {
            if self.absorbed_by.is_empty() {
                self.absorbed_by = vec![REMOVED; self.verts.len()];
            }
            self.absorbed_by[ri] = k;
        }
        self.affected = affected;
        self.shared = shared;
    }

    /// Queues the new fan around `k` and the faces whose points move onto it for the
    /// carrying thread, and sends a full batch.
    fn carry_points(&mut self, k: u32, affected: &[u32]) {
        let fan = self.vfaces[k as usize].iter().map(|&f| {
            (
                f,
                self.faces[f as usize].map(|v| self.verts[v as usize].pos),
            )
        });
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
    pub(super) fn stop_carrying(&mut self) {
        self.send_fans();
        self.carrier = None;
    }

    pub(super) fn finish(self, land_face: &[u32], land_bary: &[[f64; 3]]) -> Simplified {
        let mut control_of = vec![REMOVED; self.verts.len()];
        let mut positions = Vec::with_capacity(self.alive_vertices);
        for (v, vertex) in self.verts.iter().enumerate() {
            if vertex.alive {
                control_of[v] = positions.len() as u32;
                positions.push(vertex.pos);
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
        let locked_corners = self.verts.iter().filter(|v| v.locked).count();
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
