//! Inverse Loop subdivision: the paper's exact left inverse (equation 1 plus the inverted
//! boundary rule) and the least-squares coarse net.

use super::detect::{DetectError, Hierarchy, Level};
use super::loop_subdiv::{loop_beta, loop_step, SparseOperator};
use super::topology::{Topology, TopologyError, NONE};
use super::TriMesh;
use glam::DVec3;
use std::collections::HashMap;

/// How coarse positions are recovered from fine ones.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum InverseMethod {
    /// The exact inverse of the subdivision rules (the fine mesh must be a subdivision).
    Exact,
    /// The coarse points whose subdivision is closest to the fine ones in least squares.
    Lsq,
}

impl InverseMethod {
    /// Every method, in the order a user interface lists them.
    pub const ALL: [InverseMethod; 2] = [InverseMethod::Exact, InverseMethod::Lsq];

    /// The method's name in configs and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            InverseMethod::Exact => "exact",
            InverseMethod::Lsq => "lsq",
        }
    }
}

impl std::fmt::Display for InverseMethod {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for InverseMethod {
    type Err = crate::names::UnknownName;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        InverseMethod::ALL
            .into_iter()
            .find(|m| m.name() == s)
            .ok_or_else(|| {
                crate::names::UnknownName::new(s, InverseMethod::ALL.map(InverseMethod::name))
            })
    }
}

/// Why a mesh cannot be coarsened as asked.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum InverseError {
    /// Fewer subdivision levels were found than asked for; `reason` is the detector's
    /// account of the first level that failed, when there is one.
    #[error(
        "input has no Loop subdivision connectivity at depth {wanted} (found {found}): {}",
        reason.as_ref().map_or_else(|| "unknown".to_string(), ToString::to_string)
    )]
    NotSubdivided {
        /// Levels asked for.
        wanted: usize,
        /// Levels found.
        found: usize,
        /// Why the next level was not found.
        #[source]
        reason: Option<DetectError>,
    },
    /// The mesh (or a recovered coarse mesh) is not a manifold.
    #[error(transparent)]
    Topology(#[from] TopologyError),
}

impl InverseError {
    /// A stable snake_case name of the variant, for machine-readable reports.
    pub fn kind(&self) -> &'static str {
        match self {
            Self::NotSubdivided { .. } => "not_subdivided",
            Self::Topology(_) => "topology",
        }
    }
}

/// Paper's equation 1 weights (mu, eta) for an interior even vertex of valence `l`.
pub(crate) fn inverse_weights(l: usize) -> (f64, f64) {
    let beta = loop_beta(l);
    let alpha = 1.0 - l as f64 * beta;
    let mu = 5.0 / (8.0 * alpha - 3.0);
    let eta = (alpha - 1.0) / (l as f64 * (alpha - 0.375));
    (mu, eta)
}

/// The exact inverse of one level as an operator from fine to coarse vertices.
pub fn exact_inverse_operator(fine: &Topology, level: &Level) -> SparseOperator {
    exact_inverse_rows(fine, &level.coarse_to_fine)
}

/// `exact_inverse_operator` for a fine mesh whose coarse vertices are known without
/// detection (a resampling lattice's): `coarse_to_fine` maps each coarse vertex to its
/// even fine vertex. The rule reads only that vertex's ring in `fine`.
pub(crate) fn exact_inverse_rows(fine: &Topology, coarse_to_fine: &[u32]) -> SparseOperator {
    let mut op = SparseOperator {
        input_len: fine.vertex_count,
        row_start: vec![0],
        ..Default::default()
    };
    for &a in coarse_to_fine {
        let ring = fine.ring(a);
        if ring.is_empty() || fine.is_corner(a) {
            op.cols.push(a);
            op.weights.push(1.0);
        } else if fine.is_boundary(a) {
            op.cols.extend([a, ring[0], ring[ring.len() - 1]]);
            op.weights.extend([2.0, -0.5, -0.5]);
        } else {
            let (mu, eta) = inverse_weights(ring.len());
            op.cols.push(a);
            op.weights.push(mu);
            op.cols.extend_from_slice(ring);
            op.weights.extend(std::iter::repeat_n(eta, ring.len()));
        }
        op.row_start.push(op.cols.len() as u32);
    }
    op
}

/// The one-level subdivision operator of the coarse mesh with rows in fine vertex order.
fn subdivision_in_fine_order(
    level: &Level,
    fine_count: usize,
) -> Result<SparseOperator, TopologyError> {
    let coarse_topo = Topology::build(level.coarse_to_fine.len(), &level.coarse_triangles)?;
    let step = loop_step(&coarse_topo);
    let nc = level.coarse_to_fine.len();
    let mut odd_of_edge: HashMap<(u32, u32), u32> = HashMap::with_capacity(fine_count);
    for (v, &[p, q]) in level.odd_endpoints.iter().enumerate() {
        if p != NONE {
            odd_of_edge.insert((p.min(q), p.max(q)), v as u32);
        }
    }
    // Row index in `step` for each fine vertex.
    let mut row_of_fine = vec![NONE; fine_count];
    for (c, &f) in level.coarse_to_fine.iter().enumerate() {
        row_of_fine[f as usize] = c as u32;
    }
    for (e, (a, b, _)) in coarse_topo.edges().into_iter().enumerate() {
        if let Some(&f) = odd_of_edge.get(&(a.min(b), a.max(b))) {
            row_of_fine[f as usize] = (nc + e) as u32;
        }
    }
    let mut op = SparseOperator {
        input_len: nc,
        row_start: vec![0],
        ..Default::default()
    };
    for &r in &row_of_fine {
        if r != NONE {
            let (c, w) = step.operator.row(r as usize);
            op.cols.extend_from_slice(c);
            op.weights.extend_from_slice(w);
        }
        op.row_start.push(op.cols.len() as u32);
    }
    Ok(op)
}

/// Least-squares coarse positions: minimise |S C - F|^2 by conjugate gradients on the
/// normal equations, started from the exact inverse (which is already optimal on exact data).
fn lsq_level(
    level: &Level,
    fine_positions: &[DVec3],
    start: Vec<DVec3>,
) -> Result<Vec<DVec3>, TopologyError> {
    let s = subdivision_in_fine_order(level, fine_positions.len())?;
    let nc = start.len();
    let apply_s = |c: &[DVec3]| s.apply(c);
    let apply_st = |r: &[DVec3]| {
        let mut out = vec![DVec3::ZERO; nc];
        for (i, ri) in r.iter().enumerate().take(s.rows()) {
            let (cols, w) = s.row(i);
            for (&j, &w) in cols.iter().zip(w) {
                out[j as usize] += *ri * w;
            }
        }
        out
    };
    let mut x = start;
    let sx = apply_s(&x);
    let resid: Vec<DVec3> = fine_positions
        .iter()
        .zip(&sx)
        .map(|(f, s)| *f - *s)
        .collect();
    let mut r = apply_st(&resid);
    let mut p = r.clone();
    let dot = |a: &[DVec3], b: &[DVec3]| -> DVec3 { a.iter().zip(b).map(|(x, y)| *x * *y).sum() };
    let mut rr = dot(&r, &r);
    let rhs_scale = dot(&apply_st(fine_positions), &apply_st(fine_positions))
        .max_element()
        .max(1e-300);
    for _ in 0..500 {
        if rr.max_element() <= 1e-28 * rhs_scale {
            break;
        }
        let sp = apply_s(&p);
        let q = apply_st(&sp);
        let pq = dot(&p, &q);
        let alpha = DVec3::select(pq.cmpgt(DVec3::ZERO), rr / pq, DVec3::ZERO);
        for i in 0..nc {
            x[i] += alpha * p[i];
            r[i] -= alpha * q[i];
        }
        let rr_new = dot(&r, &r);
        let beta = DVec3::select(rr.cmpgt(DVec3::ZERO), rr_new / rr, DVec3::ZERO);
        for i in 0..nc {
            p[i] = r[i] + beta * p[i];
        }
        rr = rr_new;
    }
    Ok(x)
}

/// Result of coarsening: the coarse mesh and the hierarchy that produced it.
pub struct Coarsened {
    /// The coarsest mesh.
    pub mesh: TriMesh,
    /// The levels recovered on the way.
    pub hierarchy: Hierarchy,
}

/// Inverse Loop `levels` times. Coarse vertices come in the order of the even vertices.
pub fn coarsen(
    mesh: &TriMesh,
    levels: usize,
    method: InverseMethod,
) -> Result<Coarsened, InverseError> {
    let fine_topo = Topology::from_mesh(mesh)?;
    let (hierarchy, err) = Hierarchy::detect(&fine_topo, levels);
    if hierarchy.depth() < levels {
        return Err(InverseError::NotSubdivided {
            wanted: levels,
            found: hierarchy.depth(),
            reason: err,
        });
    }
    let mut positions = mesh.positions.clone();
    let mut topo = fine_topo;
    for level in &hierarchy.levels {
        let exact = exact_inverse_operator(&topo, level).apply(&positions);
        positions = match method {
            InverseMethod::Exact => exact,
            InverseMethod::Lsq => lsq_level(level, &positions, exact)?,
        };
        topo = Topology::build(level.coarse_to_fine.len(), &level.coarse_triangles)?;
    }
    let triangles = hierarchy
        .levels
        .last()
        .map_or_else(|| mesh.triangles.clone(), |l| l.coarse_triangles.clone());
    Ok(Coarsened {
        mesh: TriMesh::new(positions, triangles),
        hierarchy,
    })
}

/// `R^L`: the composed exact inverse from the finest vertices to the coarsest, as one operator.
pub fn composed_exact_inverse(
    fine: &Topology,
    hierarchy: &Hierarchy,
) -> Result<SparseOperator, TopologyError> {
    let mut composed: Option<SparseOperator> = None;
    let mut topo = fine.clone();
    for level in &hierarchy.levels {
        let r = exact_inverse_operator(&topo, level);
        composed = Some(match composed {
            None => r,
            Some(prev) => compose(&r, &prev),
        });
        topo = Topology::build(level.coarse_to_fine.len(), &level.coarse_triangles)?;
    }
    Ok(composed.unwrap_or_else(|| identity(fine.vertex_count)))
}

fn identity(n: usize) -> SparseOperator {
    SparseOperator {
        input_len: n,
        row_start: (0..=n as u32).collect(),
        cols: (0..n as u32).collect(),
        weights: vec![1.0; n],
    }
}

/// `outer * inner` as one operator.
pub(crate) fn compose(outer: &SparseOperator, inner: &SparseOperator) -> SparseOperator {
    let mut op = SparseOperator {
        input_len: inner.input_len,
        row_start: vec![0],
        ..Default::default()
    };
    let mut acc: HashMap<u32, f64> = HashMap::new();
    for i in 0..outer.rows() {
        acc.clear();
        let (c, w) = outer.row(i);
        for (&j, &wj) in c.iter().zip(w) {
            let (ci, wi) = inner.row(j as usize);
            for (&k, &wk) in ci.iter().zip(wi) {
                *acc.entry(k).or_insert(0.0) += wj * wk;
            }
        }
        let mut entries: Vec<(u32, f64)> = acc.iter().map(|(&k, &w)| (k, w)).collect();
        entries.sort_unstable_by_key(|e| e.0);
        for (k, w) in entries {
            op.cols.push(k);
            op.weights.push(w);
        }
        op.row_start.push(op.cols.len() as u32);
    }
    op
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn inverse_method_names_parse_back() {
        for m in InverseMethod::ALL {
            assert_eq!(m.name().parse::<InverseMethod>(), Ok(m));
        }
        assert!("exactly".parse::<InverseMethod>().is_err());
    }

    #[test]
    fn weights_match_the_spec_table() {
        let (mu, eta) = inverse_weights(6);
        assert!((mu - 2.5).abs() < 1e-12 && (eta + 0.25).abs() < 1e-12);
        let (mu, eta) = inverse_weights(3);
        assert!((mu - 10.0).abs() < 1e-9 && (eta + 3.0).abs() < 1e-9);
        for l in 3..16 {
            let (mu, eta) = inverse_weights(l);
            assert!((mu + l as f64 * eta - 1.0).abs() < 1e-12);
        }
    }
}
