//! The data's rim and the surface's boundary: rim points' feet held on the boundary
//! curve of the control mesh, and which data points lie on or near the data's boundary.

use crate::mesh::topology::Topology;
use crate::surface::loop_limit::LoopLimitSurface;
use crate::surface::{SurfaceParam, TriSurface};
use crate::TriMesh;
use glam::DVec3;
use rayon::prelude::*;

/// The data's rim held on the surface's rim: each data point on the data's boundary keeps
/// its foot point on a boundary edge of its control face (where that face has one), so
/// the limit surface's boundary curve is fitted to the data's boundary. Left free, those
/// foot points slide inside and nothing stops the surface from running on past the rim
/// (on bun_zipper by up to 2 % of the diagonal over the holes).
pub(super) struct Rim {
    /// Per control face: which of its edges k (corner k to k + 1) are on the boundary (a
    /// face at a corner of the rim has two).
    edges_of_face: Vec<[bool; 3]>,
    /// Per control vertex: the boundary edges (face, k) through it. A rim point's foot at
    /// a corner of a face whose own boundary edge lies across it (a long face of a coarse
    /// CAD mesh, standing on the rim by one corner only) is held where the boundary passes
    /// that corner: on CGAL-style low-poly parts the held feet were otherwise whole face
    /// heights away from points lying on the boundary.
    edges_at_vertex: Vec<Vec<(u32, u8)>>,
    /// The control faces.
    faces: Vec<[u32; 3]>,
    /// The data points on the data's boundary.
    points: Vec<usize>,
}

/// Feet held by their parts (a whole fit's `Feet`, a local refit's `LocalFeet`).
pub(super) struct FeetMut<'a> {
    pub params: &'a mut [SurfaceParam],
    pub normals: &'a mut [DVec3],
    pub distances: &'a mut [f64],
}

/// Gauss-Newton steps along a boundary edge.
const RIM_STEPS: usize = 4;

impl Rim {
    /// `control_twins`: the control mesh's half-edge twins (`NONE` on the boundary);
    /// `data_boundary`: per data point, whether it is on the data's boundary.
    pub(super) fn new(faces: &[[u32; 3]], control_twins: &[u32], data_boundary: &[bool]) -> Rim {
        let edges_of_face: Vec<[bool; 3]> = control_twins
            .chunks(3)
            .map(|t| [0, 1, 2].map(|k| t.get(k) == Some(&crate::mesh::topology::NONE)))
            .collect();
        let vertices = faces.iter().flatten().max().map_or(0, |&v| v as usize + 1);
        let mut edges_at_vertex = vec![Vec::new(); vertices];
        for (f, (t, edges)) in faces.iter().zip(&edges_of_face).enumerate() {
            for k in (0..3).filter(|&k| edges[k]) {
                for v in [t[k], t[(k + 1) % 3]] {
                    edges_at_vertex[v as usize].push((f as u32, k as u8));
                }
            }
        }
        let points = (0..data_boundary.len())
            .filter(|&p| data_boundary[p])
            .collect();
        Rim {
            edges_of_face,
            edges_at_vertex,
            faces: faces.to_vec(),
            points,
        }
    }

    /// No boundary edge and no rim point, over `faces` control faces: surface samples
    /// then take the faces' insides only. A local refit holds no rim points on the
    /// boundary curve, and boundary samples alone pull the curve towards the nearest data
    /// with nothing to hold it out (measured on a tube grown by 40 rings: the max error
    /// 3.8e-3 with them, 2.6e-3 without, against 1.75e-3 from scratch).
    pub(super) fn without_boundary(faces: usize) -> Rim {
        Rim {
            edges_of_face: vec![[false; 3]; faces],
            edges_at_vertex: Vec::new(),
            faces: Vec::new(),
            points: Vec::new(),
        }
    }

    /// Moves each rim point's foot parameter onto the nearest boundary edge near it (see
    /// `edges_near`; the nearest point of the edge's limit curve, by Gauss-Newton along
    /// it) and updates its normal and distance; only the rim points `only` marks (all
    /// without).
    pub(super) fn hold_where(
        &self,
        feet: FeetMut,
        surface: &LoopLimitSurface,
        controls: &[DVec3],
        data: &[DVec3],
        only: Option<&[bool]>,
    ) {
        let evaluate = surface.evaluator(controls);
        let points: Vec<usize> = self
            .points
            .iter()
            .copied()
            .filter(|&p| only.is_none_or(|o| o.get(p) == Some(&true)))
            .collect();
        let held: Vec<Option<(SurfaceParam, DVec3, f64)>> = points
            .par_iter()
            .map(|&p| {
                let param = feet.params[p];
                self.edges_near(param)
                    .filter_map(|(start, k)| {
                        let held = hold_on_edge(&*evaluate, start, k, data[p])?;
                        // A rim point whose own face's edge lies far off (a control face
                        // between two small holes of a broken scan) is left free: the hold
                        // pulls a rim along its data, never across to another.
                        let t3 = self.faces.get(start.face as usize)?;
                        let (a, b) = (t3[k] as usize, t3[(k + 1) % 3] as usize);
                        let edge = controls.get(a)?.distance(*controls.get(b)?);
                        (held.2 <= feet.distances[p] + 0.5 * edge).then_some(held)
                    })
                    .min_by(|x, y| x.2.total_cmp(&y.2))
                    .map(|(at, n, d)| (at, n.unwrap_or(feet.normals[p]), d))
            })
            .collect();
        for (&p, h) in points.iter().zip(held) {
            if let Some((param, n, dist)) = h {
                feet.params[p] = param;
                feet.normals[p] = n;
                feet.distances[p] = dist;
            }
        }
    }

    /// Which edges k (corner k to k + 1) of control face `face` are on the boundary.
    pub(super) fn boundary_edges_of(&self, face: usize) -> [bool; 3] {
        self.edges_of_face.get(face).copied().unwrap_or_default()
    }

    /// The boundary edges a foot at `param` may be held on, each with the parameter its
    /// search starts from: the edges of its own face (from the foot's projection onto
    /// them), and, where the foot lies nearer one corner than the rest of the face (its
    /// weight there at least one half), the other faces' boundary edges through that
    /// corner (from the corner). Only the near corner's: a face's other corners may lie on
    /// another boundary loop (a control face between two holes of a broken scan), and the
    /// hold pulls a rim along its data, never across to another.
    fn edges_near(&self, param: SurfaceParam) -> impl Iterator<Item = (SurfaceParam, usize)> + '_ {
        let face = param.face as usize;
        let own = self.boundary_edges_of(face);
        let own_edges = (0..3).filter(move |&k| own[k]).map(move |k| (param, k));
        let weights = [param.u, param.v, 1.0 - param.u - param.v];
        let near = (0..3).find(|&c| weights[c] >= 0.5);
        let corner = near.and_then(|c| Some(self.faces.get(face)?[c]));
        let at = corner
            .and_then(|v| self.edges_at_vertex.get(v as usize))
            .map_or(&[][..], |e| &e[..]);
        let through_corner = at
            .iter()
            .filter(move |&&(f, _)| f as usize != face)
            .filter_map(move |&(f, k)| {
                let k = k as usize;
                // Weight 1 at the edge's end on the shared corner.
                let on_k = self.faces.get(f as usize)?[k] == corner?;
                let mut w = [0.0; 3];
                w[if on_k { k } else { (k + 1) % 3 }] = 1.0;
                let start = SurfaceParam {
                    face: f,
                    u: w[0],
                    v: w[1],
                };
                Some((start, k))
            });
        own_edges.chain(through_corner)
    }

    /// Whether data point `p` is on the rim (for its share of the point-to-point term).
    pub(super) fn marks(&self, count: usize) -> Vec<bool> {
        let mut m = vec![false; count];
        for &p in &self.points {
            m[p] = true;
        }
        m
    }
}

/// The point of edge k (corner k to k + 1) of `param`'s face nearest to `q`, by
/// Gauss-Newton along the edge from the projection of `param` onto it: the parameter, the
/// unit normal there (if the tangents span a plane) and the distance. `None` when the
/// tangent along the edge vanishes at the start.
fn hold_on_edge(
    evaluate: &(dyn Fn(SurfaceParam) -> crate::surface::Derivatives + Sync),
    param: SurfaceParam,
    k: usize,
    q: DVec3,
) -> Option<(SurfaceParam, Option<DVec3>, f64)> {
    let w = [param.u, param.v, 1.0 - param.u - param.v];
    let sum = w[k] + w[(k + 1) % 3];
    let mut t = if sum > 0.0 { w[k] / sum } else { 0.5 };
    let at = |t: f64| {
        let mut w = [0.0; 3];
        w[k] = t;
        w[(k + 1) % 3] = 1.0 - t;
        SurfaceParam {
            face: param.face,
            u: w[0],
            v: w[1],
        }
    };
    let mut d = evaluate(at(t));
    for step in 0..RIM_STEPS {
        // d/dt of the position along the edge in (u, v) terms.
        let along = match k {
            0 => d.du - d.dv,
            1 => d.dv,
            _ => -d.du,
        };
        let len2 = along.length_squared();
        if len2 <= 0.0 {
            if step == 0 {
                return None;
            }
            break;
        }
        t = (t - (d.position - q).dot(along) / len2).clamp(0.0, 1.0);
        d = evaluate(at(t));
    }
    let n = d.du.cross(d.dv).try_normalize();
    Some((at(t), n, (d.position - q).length()))
}

/// Per vertex: whether it lies within `rings` rings of the mesh's boundary.
pub(super) fn near_boundary(mesh: &TriMesh, rings: usize) -> Vec<bool> {
    let Ok(topo) = Topology::from_mesh(mesh) else {
        return vec![false; mesh.positions.len()];
    };
    near_boundary_in(&topo, rings)
}

/// [`near_boundary`] on the mesh's half-edge topology, built already.
pub(super) fn near_boundary_in(topo: &Topology, rings: usize) -> Vec<bool> {
    let mut near = topo.boundary.clone();
    let mut front: Vec<u32> = (0..near.len() as u32)
        .filter(|&v| near[v as usize])
        .collect();
    for _ in 0..rings {
        let mut next = Vec::new();
        for &v in &front {
            for &x in topo.ring(v) {
                if !near[x as usize] {
                    near[x as usize] = true;
                    next.push(x);
                }
            }
        }
        front = next;
    }
    near
}
