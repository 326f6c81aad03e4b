//! The sample lattice of `stray::face_strays` with every sample taken once. A lattice of
//! k segments per edge puts (k + 1)(k + 2) / 2 samples on each control face; the corners
//! and the edges' inner samples lie on neighbouring faces as well, the same points of the
//! same surface, so a face-by-face lattice measured them twice (edges) or six times
//! (corners). Over a closed control mesh, 6 segments take 28 samples a face that way and
//! about 18 shared, 3 segments 10 and about 4.5: the distance to the data, the cost of
//! each sample, is asked that much less often.

use crate::surface::SurfaceParam;
use rustc_hash::FxHashMap;

/// The distinct samples of the lattices of a set of faces and, per face, which of them
/// its lattice holds.
pub(super) struct SharedLattice {
    /// Each distinct sample, as the parameter on the first face that holds it.
    pub samples: Vec<SurfaceParam>,
    /// Per face of the set, in its order: the indices into `samples` of its lattice, in
    /// the order `lattice_params` gives that face's parameters.
    pub of_face: Vec<Vec<u32>>,
}

/// The lattice parameters of face `f`, k segments per edge: for j in 0..=k, i in
/// 0..=k - j, (u, v) = (i / k, j / k). The order `face_strays` samples in.
pub(super) fn lattice_params(f: u32, k: usize) -> impl Iterator<Item = SurfaceParam> {
    (0..=k).flat_map(move |j| {
        (0..=k - j).map(move |i| SurfaceParam {
            face: f,
            u: i as f64 / k as f64,
            v: j as f64 / k as f64,
        })
    })
}

/// Where a lattice point of a face lies: on a corner, inside an edge, or inside the face.
enum Site {
    Corner(u32),
    /// The edge's end points, lower index first, and the point's steps from the lower end.
    Edge(u32, u32, usize),
    Inside,
}

/// The site of lattice point (i, j) (u = i / k, v = j / k) of a face with corners `t`:
/// the barycentric weight of corner 0 is u, of corner 1 v, of corner 2 the rest.
fn site(t: [u32; 3], i: usize, j: usize, k: usize) -> Site {
    // Steps towards each corner: (corner 0, corner 1, corner 2) = (i, j, l).
    match (i, j, k - i - j) {
        (_, 0, 0) => Site::Corner(t[0]),
        (0, _, 0) => Site::Corner(t[1]),
        (0, 0, _) => Site::Corner(t[2]),
        // Between corners 0 and 1 the point is i steps from corner 1 towards corner 0.
        (_, _, 0) => edge_site(t[1], t[0], i, k),
        (0, _, _) => edge_site(t[2], t[1], j, k),
        (_, 0, _) => edge_site(t[2], t[0], i, k),
        _ => Site::Inside,
    }
}

/// The point `steps` of `k` from `from` towards `to`, counted from the edge's lower end.
fn edge_site(from: u32, to: u32, steps: usize, k: usize) -> Site {
    if from < to {
        Site::Edge(from, to, steps)
    } else {
        Site::Edge(to, from, k - steps)
    }
}

impl SharedLattice {
    /// The shared lattice of `faces` (indices into `triangles`; those past its end get an
    /// empty lattice) at `k` segments per edge.
    pub(super) fn new(triangles: &[[u32; 3]], faces: &[u32], k: usize) -> Self {
        let k = k.max(1);
        let mut corners: FxHashMap<u32, u32> = FxHashMap::default();
        let mut edges: FxHashMap<(u32, u32), u32> = FxHashMap::default();
        let per_face = (k + 1) * (k + 2) / 2;
        let mut samples = Vec::with_capacity(faces.len() * per_face * 2 / 3);
        let mut of_face = Vec::with_capacity(faces.len());
        for &f in faces {
            let Some(&t) = triangles.get(f as usize) else {
                of_face.push(Vec::new());
                continue;
            };
            let mut indices = Vec::with_capacity(per_face);
            for (p, (i, j)) in lattice_params(f, k).zip(lattice_steps(k)) {
                let add = |samples: &mut Vec<SurfaceParam>| {
                    samples.push(p);
                    samples.len() as u32 - 1
                };
                let index = match site(t, i, j, k) {
                    Site::Corner(v) => *corners.entry(v).or_insert_with(|| add(&mut samples)),
                    Site::Edge(a, b, steps) => {
                        // An edge's k - 1 inner points are stored together, from its lower
                        // end: the first face to reach the edge reserves them all.
                        let base = *edges.entry((a, b)).or_insert_with(|| {
                            let base = samples.len() as u32;
                            samples.extend(std::iter::repeat_n(NOT_YET, k - 1));
                            base
                        });
                        let slot = base as usize + steps - 1;
                        if samples[slot].face == NOT_YET.face {
                            samples[slot] = p;
                        }
                        slot as u32
                    }
                    Site::Inside => add(&mut samples),
                };
                indices.push(index);
            }
            of_face.push(indices);
        }
        Self { samples, of_face }
    }
}

/// A slot of an edge's inner points not filled yet (every slot is filled by the face that
/// reserved it: a face's lattice holds all inner points of its three edges).
const NOT_YET: SurfaceParam = SurfaceParam {
    face: u32::MAX,
    u: 0.0,
    v: 0.0,
};

/// The (i, j) steps of `lattice_params`, in its order.
fn lattice_steps(k: usize) -> impl Iterator<Item = (usize, usize)> {
    (0..=k).flat_map(move |j| (0..=k - j).map(move |i| (i, j)))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two faces sharing edge (1, 2), and a third sharing corner 0 only.
    const FACES: [[u32; 3]; 3] = [[0, 1, 2], [2, 1, 3], [0, 4, 5]];

    fn point(triangles: &[[u32; 3]], p: SurfaceParam, at: &[glam::DVec3]) -> glam::DVec3 {
        let t = triangles[p.face as usize];
        at[t[0] as usize] * p.u + at[t[1] as usize] * p.v + at[t[2] as usize] * (1.0 - p.u - p.v)
    }

    #[test]
    fn every_face_sees_its_whole_lattice_and_shared_points_are_taken_once() {
        let at: Vec<glam::DVec3> = (0..6)
            .map(|v| glam::DVec3::new(v as f64, (v * v) as f64 * 0.3, (v % 3) as f64))
            .collect();
        for k in [1, 2, 3, 6] {
            let lattice = SharedLattice::new(&FACES, &[0, 1, 2, 7], k);
            let per_face = (k + 1) * (k + 2) / 2;
            // Each face's samples are the points of its own lattice, in its order.
            for (n, &f) in [0u32, 1, 2].iter().enumerate() {
                let own: Vec<_> = lattice_params(f, k)
                    .map(|p| point(&FACES, p, &at))
                    .collect();
                let shared: Vec<_> = lattice.of_face[n]
                    .iter()
                    .map(|&s| point(&FACES, lattice.samples[s as usize], &at))
                    .collect();
                assert_eq!(own.len(), shared.len());
                for (a, b) in own.iter().zip(&shared) {
                    assert!(a.distance(*b) < 1e-12, "k {k} face {f}: {a} against {b}");
                }
            }
            // A face past the mesh has no lattice.
            assert!(lattice.of_face[3].is_empty());
            // Distinct samples: three lattices less the shared edge (k + 1 points) and
            // the shared corner.
            assert_eq!(lattice.samples.len(), 3 * per_face - (k + 1) - 1, "k {k}");
            assert!(lattice.samples.iter().all(|p| p.face != NOT_YET.face));
        }
    }
}
