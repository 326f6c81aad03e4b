//! The seams of a new region and the strips that join them to the previous control mesh's
//! rim (`extend`): the region's faces (grown where it would pinch), its seams (runs of its
//! boundary where older data goes on), the previous rim loops at their limit points, the
//! rim run along each seam, and the strip of triangles between the two.

use crate::mesh::topology::{Topology, NONE};
use crate::remesh::boundary_loops;
use crate::TriMesh;
use glam::DVec3;
use rustc_hash::FxHashMap;

/// A seam whose median distance to the previous rim exceeds this many mean rim edges does
/// not run along the rim: the new region is an island the strip cannot join.
const MAX_SEAM_GAP_EDGES: f64 = 2.0;

/// Share of a seam's vertices whose nearest rim vertex must lie in the rim run the strip
/// covers (the rest are corners of the seam near the run's ends).
const MIN_SEAM_IN_RUN: f64 = 0.8;

/// Share of a rim loop's vertices a closed seam must be nearest to.
const MIN_LOOP_HIT: f64 = 0.5;

/// Rounds of growing the region around its pinches at most.
const MAX_PINCH_ROUNDS: usize = 8;

/// The faces of the new region: those with a point on new ground, and every face around a
/// vertex where the region would pinch (meet itself at a vertex only: its boundary could
/// not be walked, nor the joined mesh be a manifold).
pub(super) fn region_faces(component: &TriMesh, topo: &Topology, is_new: &[bool]) -> Vec<bool> {
    let mut in_region: Vec<bool> = component
        .triangles
        .iter()
        .map(|t| t.iter().any(|&v| is_new[v as usize]))
        .collect();
    let mut faces_of: Vec<Vec<u32>> = vec![Vec::new(); component.positions.len()];
    for (f, t) in component.triangles.iter().enumerate() {
        for &v in t {
            faces_of[v as usize].push(f as u32);
        }
    }
    for _ in 0..MAX_PINCH_ROUNDS {
        let mut out = vec![0u8; component.positions.len()];
        for (f, t) in component.triangles.iter().enumerate() {
            if !in_region[f] {
                continue;
            }
            for k in 0..3 {
                let twin = topo.twin[3 * f + k];
                if twin == NONE || !in_region[twin as usize / 3] {
                    out[t[k] as usize] = out[t[k] as usize].saturating_add(1);
                }
            }
        }
        let pinches: Vec<usize> = (0..out.len()).filter(|&v| out[v] > 1).collect();
        if pinches.is_empty() {
            break;
        }
        for v in pinches {
            for &f in &faces_of[v] {
                in_region[f as usize] = true;
            }
        }
    }
    in_region
}

/// A run of the region's boundary where older data goes on, in the direction the region's
/// faces run it; `closed` when it is a whole boundary loop.
pub(super) struct Seam {
    pub vertices: Vec<u32>,
    pub closed: bool,
}

/// The region's seams; `None` where its boundary pinches (a vertex with two boundary edges
/// out).
pub(super) fn seams(topo: &Topology, in_region: &[bool]) -> Option<Vec<Seam>> {
    // Per start vertex: the boundary edge of the region out of it and whether it is a seam
    // edge (an old face beyond it) rather than the data's own rim.
    let mut next: FxHashMap<u32, (u32, bool)> = FxHashMap::default();
    for (f, t) in topo.triangles.iter().enumerate() {
        if !in_region[f] {
            continue;
        }
        for k in 0..3 {
            let twin = topo.twin[3 * f + k];
            let seam = twin != NONE && !in_region[twin as usize / 3];
            if (twin == NONE || seam) && next.insert(t[k], (t[(k + 1) % 3], seam)).is_some() {
                return None;
            }
        }
    }
    let mut starts: Vec<u32> = next.keys().copied().collect();
    starts.sort_unstable();
    let mut seen = rustc_hash::FxHashSet::default();
    let mut seams = Vec::new();
    for start in starts {
        if seen.contains(&start) {
            continue;
        }
        // The loop through `start`, as (vertex, edge out of it is a seam) pairs.
        let mut ring = Vec::new();
        let mut v = start;
        while seen.insert(v) {
            let &(w, seam) = next.get(&v)?;
            ring.push((v, seam));
            v = w;
        }
        if v != start {
            return None;
        }
        let Some(rim_at) = ring.iter().position(|&(_, seam)| !seam) else {
            seams.push(Seam {
                vertices: ring.iter().map(|&(v, _)| v).collect(),
                closed: true,
            });
            continue;
        };
        // From just after a rim edge, each maximal run of seam edges is a seam.
        ring.rotate_left(rim_at + 1);
        let len = ring.len();
        let mut k = 0;
        while k < len {
            if !ring[k].1 {
                k += 1;
                continue;
            }
            let mut vertices = vec![ring[k].0];
            while k < len && ring[k].1 {
                vertices.push(ring[(k + 1) % len].0);
                k += 1;
            }
            seams.push(Seam {
                vertices,
                closed: false,
            });
        }
    }
    Some(seams)
}

/// The previous control mesh's boundary loops at the limit points.
pub(super) struct Rims<'a> {
    /// Each loop in the direction its faces run it.
    loops: Vec<Vec<u32>>,
    /// Per vertex on a loop: (loop, index in it).
    at: FxHashMap<u32, (usize, usize)>,
    limit: &'a [DVec3],
    mean_edge: f64,
}

/// Why a seam has no rim run (`Rims::run_along`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub(super) enum SeamMiss {
    /// Its median distance to the previous rim exceeds `MAX_SEAM_GAP_EDGES` mean rim edges
    /// (or the previous control mesh has no rim).
    FarFromRim,
    /// A closed seam nearest to less than `MIN_LOOP_HIT` of its rim loop.
    PartOfLoop,
    /// An open seam that ends near another rim loop than the one it starts at.
    TwoLoops,
    /// An open seam with less than `MIN_SEAM_IN_RUN` of its vertices nearest to the run
    /// between its ends.
    OffRun,
    /// Its run shares rim vertices with another seam's.
    SharedRun,
}

impl SeamMiss {
    pub(super) fn describe(self) -> &'static str {
        match self {
            Self::FarFromRim => "too far from the previous rim",
            Self::PartOfLoop => "closed along too little of a rim loop",
            Self::TwoLoops => "between two rim loops",
            Self::OffRun => "off the rim run between its ends",
            Self::SharedRun => "on a rim run another seam takes",
        }
    }
}

/// The rim vertices a strip joins a seam to, in the seam's direction.
pub(super) struct Run {
    pub vertices: Vec<u32>,
}

impl<'a> Rims<'a> {
    pub(super) fn new(topo: &Topology, limit: &'a [DVec3]) -> Self {
        let loops = boundary_loops(topo);
        let mut at = FxHashMap::default();
        let (mut length, mut edges) = (0.0, 0usize);
        for (l, ring) in loops.iter().enumerate() {
            for (i, &v) in ring.iter().enumerate() {
                at.insert(v, (l, i));
                let w = ring[(i + 1) % ring.len()];
                length += limit[v as usize].distance(limit[w as usize]);
                edges += 1;
            }
        }
        Rims {
            loops,
            at,
            limit,
            mean_edge: length / edges.max(1) as f64,
        }
    }

    /// The rim vertices along `seam` (positions `at` its data points): from the one
    /// nearest the seam's first vertex, against the rim's own direction (the strip's two
    /// sides run opposite ways), to the one nearest its last; why not when the seam does
    /// not run along one rim loop.
    pub(super) fn run_along(&self, seam: &Seam, at: &[DVec3]) -> Result<Run, SeamMiss> {
        let nearest: Vec<(u32, f64)> = seam
            .vertices
            .iter()
            .map(|&v| {
                let p = at[v as usize];
                self.at
                    .keys()
                    .map(|&r| (r, self.limit[r as usize].distance_squared(p)))
                    .min_by(|a, b| a.1.total_cmp(&b.1).then(a.0.cmp(&b.0)))
                    .map(|(r, d)| (r, d.sqrt()))
            })
            .collect::<Option<_>>()
            .ok_or(SeamMiss::FarFromRim)?;
        let mut gaps: Vec<f64> = nearest.iter().map(|n| n.1).collect();
        let k = gaps.len() / 2;
        gaps.select_nth_unstable_by(k, f64::total_cmp);
        if gaps[k] > MAX_SEAM_GAP_EDGES * self.mean_edge {
            return Err(SeamMiss::FarFromRim);
        }
        let (first_loop, first) = self.at[&nearest[0].0];
        let ring = &self.loops[first_loop];
        let len = ring.len();
        let back = |i: usize| (first + len - i) % len;
        let offset = |r: u32| -> Option<usize> {
            let (l, i) = self.at[&r];
            (l == first_loop).then_some((first + len - i) % len)
        };
        let count = if seam.closed {
            // A closed seam closes a hole of the previous control mesh: its loop, not a
            // longer one it merely passes near (most of the loop's vertices are nearest
            // to some seam vertex).
            let mut hit: Vec<u32> = nearest.iter().map(|n| n.0).collect();
            hit.sort_unstable();
            hit.dedup();
            let on_loop = hit.iter().filter(|&&r| offset(r).is_some()).count();
            if (on_loop as f64) < MIN_LOOP_HIT * len as f64 {
                return Err(SeamMiss::PartOfLoop);
            }
            len
        } else {
            let last = offset(nearest[nearest.len() - 1].0).ok_or(SeamMiss::TwoLoops)?;
            let inside = nearest
                .iter()
                .filter(|n| offset(n.0).is_some_and(|o| o <= last))
                .count();
            if (inside as f64) < MIN_SEAM_IN_RUN * nearest.len() as f64 {
                return Err(SeamMiss::OffRun);
            }
            last + 1
        };
        let mut vertices: Vec<u32> = (0..count).map(|i| ring[back(i)]).collect();
        if vertices.len() == 1 {
            // A strip of one rim vertex would hang its fan off that vertex alone, a pinch
            // of the joined mesh: the run takes the rim edge on the side nearer the seam,
            // before its start or after its end.
            let (first_at, last_at) = (at[seam.vertices[0] as usize], {
                let v = seam.vertices[seam.vertices.len() - 1];
                at[v as usize]
            });
            let before = ring[(first + 1) % len];
            let after = ring[back(1)];
            if self.limit[before as usize].distance(first_at)
                < self.limit[after as usize].distance(last_at)
            {
                vertices.insert(0, before);
            } else {
                vertices.push(after);
            }
        }
        Ok(Run { vertices })
    }
}

/// Triangles between the rim run `p` and the seam `q` (both in the seam's direction, with
/// positions), advancing along whichever is behind by arc length; around a closed seam
/// both close up.
pub(super) fn strip(
    p: &[u32],
    p_at: &[DVec3],
    q: &[u32],
    q_at: &[DVec3],
    closed: bool,
) -> Vec<[u32; 3]> {
    let wrap = |ids: &[u32], at: &[DVec3]| {
        let (mut ids, mut at) = (ids.to_vec(), at.to_vec());
        if closed {
            ids.push(ids[0]);
            at.push(at[0]);
        }
        (ids, at)
    };
    let (p, p_at) = wrap(p, p_at);
    let (q, q_at) = wrap(q, q_at);
    let (tp, tq) = (arc_params(&p_at), arc_params(&q_at));
    let (mut i, mut j) = (0, 0);
    let mut faces = Vec::with_capacity(p.len() + q.len());
    while i + 1 < p.len() || j + 1 < q.len() {
        let advance_q = i + 1 == p.len() || (j + 1 < q.len() && tq[j + 1] <= tp[i + 1]);
        if advance_q {
            faces.push([q[j + 1], q[j], p[i]]);
            j += 1;
        } else {
            faces.push([p[i], p[i + 1], q[j]]);
            i += 1;
        }
    }
    faces
}

/// Each point's arc length along the polyline, as a share of the whole (all 0 for a
/// polyline of no length).
fn arc_params(at: &[DVec3]) -> Vec<f64> {
    let mut t = Vec::with_capacity(at.len());
    let mut sum = 0.0;
    t.push(0.0);
    for w in at.windows(2) {
        sum += w[0].distance(w[1]);
        t.push(sum);
    }
    if sum > 0.0 {
        for x in &mut t {
            *x /= sum;
        }
    }
    t
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A seam of one edge whose two ends are nearest to the same rim vertex: the run takes
    /// a rim edge, so that the joined mesh (previous faces, the region, the strip) is a
    /// manifold. A run of that one vertex hung the strip off it by a vertex alone (the
    /// bunny's fourth view: "vertex 491 is a pinch vertex").
    #[test]
    fn a_seam_of_one_edge_joins_along_a_rim_edge() {
        // Vertices at (i, j, 0) for i, j in 0..=3, faces counter-clockwise seen from +z.
        let mut old = crate::testdata::height_grid(3, |_, _| 0.0);
        for p in &mut old.positions {
            *p *= 3.0;
        }
        let topo = Topology::from_mesh(&old).expect("manifold");
        let rims = Rims::new(&topo, &old.positions);
        // The region: one triangle below the rim vertex (1, 0), its upper edge the seam,
        // run as its face runs it (towards -x).
        let at = [
            DVec3::new(1.3, -0.4, 0.0),
            DVec3::new(0.9, -0.4, 0.0),
            DVec3::new(1.1, -1.2, 0.0),
        ];
        let seam = Seam {
            vertices: vec![0, 1],
            closed: false,
        };
        let run = rims.run_along(&seam, &at).expect("a rim run");
        // The rim edge on the seam's side: from (2, 0) to (1, 0), the seam's direction.
        assert_eq!(run.vertices, vec![2, 1]);
        let m = old.positions.len() as u32;
        let mut faces = old.triangles.clone();
        faces.push([m + 2, m, m + 1]);
        let p_at: Vec<DVec3> = run
            .vertices
            .iter()
            .map(|&v| old.positions[v as usize])
            .collect();
        faces.extend(strip(&run.vertices, &p_at, &[m, m + 1], &at[..2], false));
        let mut positions = old.positions.clone();
        positions.extend(at);
        let joined = TriMesh::new(positions, faces);
        let joined_topo = Topology::from_mesh(&joined).expect("the joined mesh is a manifold");
        // Still a disk: one rim loop, through the region's outer corner.
        let loops = boundary_loops(&joined_topo);
        assert_eq!(loops.len(), 1);
        assert!(loops[0].contains(&(m + 2)));
    }
}
