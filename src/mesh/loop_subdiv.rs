//! Forward Loop subdivision (spec 01): Loop's original beta, boundary rules, corners fixed;
//! optionally crease edges with Hoppe et al.'s (1994) rules.

use super::topology::{Topology, TopologyError, NONE};
use super::TriMesh;
use glam::DVec3;

/// Loop's original vertex weight for an interior vertex of valence `l`.
pub fn loop_beta(l: usize) -> f64 {
    let l = l as f64;
    let c = 3.0 / 8.0 + 0.25 * (2.0 * std::f64::consts::PI / l).cos();
    (5.0 / 8.0 - c * c) / l
}

/// A sparse linear operator: row i of the output is `sum w * input[j]`.
#[derive(Clone, Debug, Default)]
pub struct SparseOperator {
    /// Length of the input vector.
    pub input_len: usize,
    /// Row i's entries are `row_start[i]..row_start[i + 1]`.
    pub row_start: Vec<u32>,
    /// Input index of every entry.
    pub cols: Vec<u32>,
    /// Weight of every entry.
    pub weights: Vec<f64>,
}

impl SparseOperator {
    /// Number of output rows.
    pub fn rows(&self) -> usize {
        self.row_start.len().saturating_sub(1)
    }

    /// Row i as (input indices, weights).
    pub fn row(&self, i: usize) -> (&[u32], &[f64]) {
        let (a, b) = (self.row_start[i] as usize, self.row_start[i + 1] as usize);
        (&self.cols[a..b], &self.weights[a..b])
    }

    /// The operator applied to points.
    pub fn apply(&self, x: &[DVec3]) -> Vec<DVec3> {
        (0..self.rows())
            .map(|i| {
                let (c, w) = self.row(i);
                c.iter().zip(w).map(|(&j, &w)| x[j as usize] * w).sum()
            })
            .collect()
    }

    fn push_row(&mut self, entries: impl IntoIterator<Item = (u32, f64)>) {
        for (c, w) in entries {
            self.cols.push(c);
            self.weights.push(w);
        }
        self.row_start.push(self.cols.len() as u32);
    }
}

/// One level of subdivision: the fine connectivity and the operator fine = S * coarse.
#[derive(Clone, Debug)]
pub struct LoopStep {
    /// The fine triangles.
    pub triangles: Vec<[u32; 3]>,
    /// Fine positions = operator * coarse positions.
    pub operator: SparseOperator,
}

/// Fine connectivity and subdivision operator. Output vertices: the V input vertices in
/// input order, then one odd vertex per edge in the order of `Topology::edges`.
pub fn loop_step(topo: &Topology) -> LoopStep {
    loop_step_with_creases(topo, &[]).0
}

/// Which rule moves a vertex, by its sharp (boundary or crease) edges (Hoppe et al. 1994).
enum EvenRule {
    Smooth,
    /// Along its two sharp edges, to these neighbours.
    Crease(u32, u32),
    Corner,
}

fn even_rule(topo: &Topology, v: u32, is_crease: &impl Fn(u32, u32) -> bool) -> EvenRule {
    let ring = topo.ring(v);
    if topo.is_boundary(v) {
        let inner = &ring[1..ring.len() - 1];
        if topo.is_corner(v) || inner.iter().any(|&r| is_crease(v, r)) {
            EvenRule::Corner
        } else {
            EvenRule::Crease(ring[0], ring[ring.len() - 1])
        }
    } else {
        let sharp: Vec<u32> = ring.iter().copied().filter(|&r| is_crease(v, r)).collect();
        match sharp.as_slice() {
            [] | [_] => EvenRule::Smooth,
            &[a, b] => EvenRule::Crease(a, b),
            _ => EvenRule::Corner,
        }
    }
}

/// `loop_step` with crease edges (pairs of vertex indices, either order): a crease edge's
/// odd point is its midpoint, a vertex with two sharp edges (crease or boundary) follows
/// 3/4 v + 1/8 (a + b) along them, one with more (or a boundary vertex with a crease) is
/// fixed, a dart (one crease edge) is smooth. Also returns the fine crease edges (the two
/// halves of each interior crease edge).
pub fn loop_step_with_creases(topo: &Topology, creases: &[[u32; 2]]) -> (LoopStep, Vec<[u32; 2]>) {
    let nv = topo.vertex_count;
    let crease_set: std::collections::HashSet<(u32, u32)> =
        creases.iter().map(|&[a, b]| (a.min(b), a.max(b))).collect();
    let is_crease = |a: u32, b: u32| crease_set.contains(&(a.min(b), a.max(b)));
    let edges = topo.edges();
    let mut edge_of_halfedge = vec![NONE; topo.twin.len()];
    for (e, &(_, _, h)) in edges.iter().enumerate() {
        edge_of_halfedge[h as usize] = (nv + e) as u32;
        let t = topo.twin[h as usize];
        if t != NONE {
            edge_of_halfedge[t as usize] = (nv + e) as u32;
        }
    }
    let mut op = SparseOperator {
        input_len: nv,
        row_start: vec![0],
        ..Default::default()
    };
    for v in 0..nv as u32 {
        let ring = topo.ring(v);
        if ring.is_empty() {
            op.push_row([(v, 1.0)]);
            continue;
        }
        match even_rule(topo, v, &is_crease) {
            EvenRule::Corner => op.push_row([(v, 1.0)]),
            EvenRule::Crease(a, b) => op.push_row([(v, 0.75), (a, 0.125), (b, 0.125)]),
            EvenRule::Smooth => {
                let beta = loop_beta(ring.len());
                let alpha = 1.0 - ring.len() as f64 * beta;
                op.push_row(std::iter::once((v, alpha)).chain(ring.iter().map(|&j| (j, beta))));
            }
        }
    }
    let mut fine_creases = Vec::new();
    for (e, &(a, b, h)) in edges.iter().enumerate() {
        let t = topo.twin[h as usize];
        if t == NONE || is_crease(a, b) {
            op.push_row([(a, 0.5), (b, 0.5)]);
            if t != NONE {
                let m = (nv + e) as u32;
                fine_creases.push([a, m]);
                fine_creases.push([m, b]);
            }
        } else {
            let (c, d) = (topo.opposite(h), topo.opposite(t));
            op.push_row([(a, 0.375), (b, 0.375), (c, 0.125), (d, 0.125)]);
        }
    }
    let mut triangles = Vec::with_capacity(topo.triangles.len() * 4);
    for (f, t) in topo.triangles.iter().enumerate() {
        let m = |k: usize| edge_of_halfedge[3 * f + k];
        let (m0, m1, m2) = (m(0), m(1), m(2));
        triangles.push([t[0], m0, m2]);
        triangles.push([t[1], m1, m0]);
        triangles.push([t[2], m2, m1]);
        triangles.push([m0, m1, m2]);
    }
    (
        LoopStep {
            triangles,
            operator: op,
        },
        fine_creases,
    )
}

/// Subdivides `levels` times.
pub fn subdivide(mesh: &TriMesh, levels: usize) -> Result<TriMesh, TopologyError> {
    let mut m = mesh.clone();
    for _ in 0..levels {
        let topo = Topology::from_mesh(&m)?;
        let step = loop_step(&topo);
        m = TriMesh::new(step.operator.apply(&m.positions), step.triangles);
    }
    Ok(m)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn regular_beta_is_one_sixteenth() {
        assert!((loop_beta(6) - 1.0 / 16.0).abs() < 1e-15);
    }

    #[test]
    fn subdivision_keeps_even_vertices_first_and_quadruples_faces() {
        let m = TriMesh::new(
            vec![DVec3::ZERO, DVec3::X, DVec3::Y, DVec3::Z],
            vec![[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]],
        );
        let s = subdivide(&m, 2).expect("manifold");
        assert_eq!(s.triangles.len(), 64);
        assert_eq!(s.positions.len(), 4 + 6 + 24);
        let t = Topology::from_mesh(&s).expect("manifold");
        assert!(t.boundary.iter().all(|b| !b));
    }
}
