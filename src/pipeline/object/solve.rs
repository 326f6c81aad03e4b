//! The solves of a whole-object fit: rows of the Loop limit surface at the data's
//! parameters, the first point-to-point fit, foot points and the squared-distance rounds.
//! (The scan path has its own versions of these in `pipeline::scan_solve`, private there
//! and tied to its grid plans; these are the plain sparse forms.)

use super::rim::{FeetMut, Rim};
use crate::fit::distance::{
    solve_distance, solve_distance_round, CholeskyPattern, DistanceProblem,
};
use crate::fit::normal_matrix::{Fairness, ScalarMatrix};
use crate::fit::{Collocation, Csr};
use crate::mesh::distance::MeshDistance;
use crate::pipeline::geometric::{curvature_term, foot_point};
use crate::surface::loop_limit::LoopLimitSurface;
use crate::surface::{Derivatives, SurfaceParam, TriSurface};
use crate::TriMesh;
use glam::DVec3;
use rayon::prelude::*;

/// Relative residual at which the fallback CG of a solve stops.
const CG_REL_TOL: f64 = 1e-8;

/// The basis rows at `params` as a sparse matrix (rows built in parallel chunks).
pub(super) fn rows_at(surface: &LoopLimitSurface, params: &[SurfaceParam]) -> Csr {
    let parts: Vec<(Vec<usize>, Vec<u32>, Vec<f64>)> = params
        .par_chunks(2048)
        .map(|chunk| {
            let mut row = Vec::new();
            // A regular patch has 12 columns; an irregular one more, which grows the arrays.
            let (mut lens, mut cols, mut vals) = (
                Vec::with_capacity(chunk.len()),
                Vec::with_capacity(12 * chunk.len()),
                Vec::with_capacity(12 * chunk.len()),
            );
            for p in chunk {
                surface.basis_row(*p, &mut row);
                let before = cols.len();
                for &(c, w) in row.iter().filter(|e| e.1 != 0.0) {
                    cols.push(c);
                    vals.push(w);
                }
                lens.push(cols.len() - before);
            }
            (lens, cols, vals)
        })
        .collect();
    // Sized exactly: grown by doubling, the two arrays of a 557k-point fit held up to
    // twice their entries at the peak of the fit's memory.
    let entries: usize = parts.iter().map(|p| p.1.len()).sum();
    let mut m = Csr {
        nrows: params.len(),
        ncols: surface.control_count(),
        row_ptr: Vec::with_capacity(params.len() + 1),
        col_idx: Vec::with_capacity(entries),
        values: Vec::with_capacity(entries),
    };
    m.row_ptr.push(0);
    let mut end = 0;
    for (lens, cols, vals) in parts {
        for len in lens {
            end += len;
            m.row_ptr.push(end);
        }
        m.col_idx.extend(cols);
        m.values.extend(vals);
    }
    m
}

/// Point-to-point least squares with the fairness term: the controls whose limit surface
/// passes nearest the data at fixed parameters. `None` if neither the factorisation nor
/// CG gives finite controls.
pub(super) fn point_fit(
    rows: &Csr,
    data: &[DVec3],
    fairness: &Collocation,
    smoothing: f64,
    start: Vec<DVec3>,
    max_iterations: usize,
) -> Option<Vec<DVec3>> {
    let fair = || Fairness {
        l: fairness.n(),
        lt: fairness.nt(),
        smoothing,
    };
    if let Ok(x) = ScalarMatrix::assemble(rows, data, Some(fair()), true).solve_direct() {
        return Some(x);
    }
    let (x, _) = ScalarMatrix::assemble(rows, data, Some(fair()), false).solve_pcg(
        start,
        max_iterations,
        CG_REL_TOL,
    );
    x.iter().all(|p| p.is_finite()).then_some(x)
}

/// One squared-distance solve at the current foot points, with the surface-to-data
/// samples as further points.
pub(super) struct DistanceRound<'a> {
    pub surface: &'a LoopLimitSurface,
    pub data: &'a [DVec3],
    pub fairness: &'a Collocation,
    pub smoothing: f64,
    pub tangential: &'a [f64],
    /// Per data point, or none: the curvature's term of its squared distance.
    pub curvature: Option<&'a [[f64; 6]]>,
    pub max_iterations: usize,
    pub samples: &'a Samples,
    /// Tangential share of the samples' point-to-point term.
    pub sample_tangential: f64,
}

impl DistanceRound<'_> {
    /// The solve, through `pattern`: the rounds of one fit share its symbolic analysis.
    pub(super) fn solve(
        &self,
        feet: &Feet,
        start: Vec<DVec3>,
        pattern: &mut CholeskyPattern,
    ) -> Option<Vec<DVec3>> {
        let s = self.samples;
        let params: Vec<SurfaceParam> = feet.params.iter().chain(&s.params).copied().collect();
        let data: Vec<DVec3> = self.data.iter().chain(&s.targets).copied().collect();
        let normals: Vec<DVec3> = feet.normals.iter().chain(&s.normals).copied().collect();
        let tangential: Vec<f64> = self
            .tangential
            .iter()
            .copied()
            .chain(std::iter::repeat_n(self.sample_tangential, s.params.len()))
            .collect();
        let rows = rows_at(self.surface, &params);
        let problem = DistanceProblem {
            basis: &rows,
            data: &data,
            normals: &normals,
            tangential: &tangential,
            curvature: self.curvature,
            fairness: Some(self.fairness),
            smoothing: self.smoothing,
        };
        let x = match solve_distance_round(&problem, pattern, Some(&start)) {
            Some(x) => x,
            None => solve_distance(&problem, start, self.max_iterations, CG_REL_TOL).0,
        };
        x.iter().all(|p| p.is_finite()).then_some(x)
    }

    /// The round's result `next` with the data's foot points on it (from `start`, the rim
    /// held by `rim`) and its two-sided RMS (the samples measured to the data by
    /// `nearest`), when that is below `before`.
    pub(super) fn judge(
        &self,
        next: Vec<DVec3>,
        start: &[SurfaceParam],
        rim: &Rim,
        nearest: Option<&MeshDistance>,
        before: f64,
    ) -> Option<(Feet, Vec<DVec3>, f64)> {
        let with_curvature = self.curvature.is_some();
        let mut feet = Feet::find(self.surface, &next, self.data, (start, with_curvature));
        feet.hold_rim(rim, self.surface, &next, self.data);
        let on_samples = match nearest {
            Some(nearest) => self.samples.distances_at(self.surface, &next, nearest),
            None => Vec::new(),
        };
        let after = two_sided_rms(&feet.distances, &on_samples);
        (after < before).then_some((feet, next, after))
    }
}

/// Where a control face is sampled, as (u, v): the centres of its quarters (the children
/// of its midpoint split): the middle one, then those at corners 0, 1 and 2.
const SAMPLE_AT: [(f64, f64); 4] = [
    (1.0 / 3.0, 1.0 / 3.0),
    (2.0 / 3.0, 1.0 / 6.0),
    (1.0 / 6.0, 2.0 / 3.0),
    (1.0 / 6.0, 1.0 / 6.0),
];

/// The surface-to-data term (the squared distance of Cheng, Wang et al. 2004 taken from
/// the surface's side): sample points of the limit surface where no foot point sees it,
/// each pulled to its nearest point of the data mesh. Sampled are: every quarter of a
/// control face that holds no foot point (all four quarters of a face holding fewer feet
/// than that), and the boundary curve at each boundary control vertex and boundary edge
/// midpoint.
///
/// Data-to-surface terms see the surface only where the data's feet land. Elsewhere it is
/// held by nothing but the fairness term, and no foot point sees it bulge:
/// - a patch the feet have slid off: on bun_zipper such patches stood 1.4 mm (0.56 % of
///   the diagonal) off the data;
/// - the part of a patch between sparse feet: a decimated mesh has few vertices where it
///   is flat, and decimated-max's patches stood 1.0 % of the diagonal off its large flat
///   triangles, 4-11 feet on each face but none on parts of it;
/// - the boundary curve between the data's rim points, which the rim hold fits only where
///   they are: on camelhead and chin_tri it ran up to 1.1 % of the diagonal past a sparse
///   or ragged rim. From outside the data the nearest data point is on the rim, so a
///   sample there pulls the curve back onto it; inside it pulls only across the surface.
///
/// Each sample weighs as one data point, so where feet are dense the data decide.
pub(super) struct Samples {
    /// The samples' parameters on the surface.
    pub params: Vec<SurfaceParam>,
    /// Their nearest points on the data mesh.
    pub targets: Vec<DVec3>,
    /// The direction of the squared distance's gradient there: the data triangle's
    /// normal, or the direction to the nearest point where that is an edge or a corner.
    pub normals: Vec<DVec3>,
    /// Their distances to the data on the surface they were found on.
    pub distances: Vec<f64>,
    /// Control faces sampled.
    pub faces: usize,
}

impl Samples {
    /// No samples (a fit without the term).
    pub(super) fn none() -> Samples {
        Samples {
            params: Vec::new(),
            targets: Vec::new(),
            normals: Vec::new(),
            distances: Vec::new(),
            faces: 0,
        }
    }

    /// The samples' distances to the data (`nearest`) on the surface at `controls`
    /// (infinite where there is none).
    pub(super) fn distances_at(
        &self,
        surface: &LoopLimitSurface,
        controls: &[DVec3],
        nearest: &MeshDistance,
    ) -> Vec<f64> {
        let evaluate = surface.evaluator(controls);
        self.params
            .par_iter()
            .with_min_len(64)
            .map(|&p| {
                nearest
                    .distance(evaluate(p).position)
                    .unwrap_or(f64::INFINITY)
            })
            .collect()
    }

    /// Samples of the surface at `controls` where the data's foot parameters `feet` leave
    /// it unseen; `rim` gives the control faces' boundary edges.
    pub(super) fn find(
        surface: &LoopLimitSurface,
        controls: &[DVec3],
        feet: &[SurfaceParam],
        rim: &Rim,
        data: &TriMesh,
        nearest: &MeshDistance,
        only: Option<&[bool]>,
    ) -> Samples {
        let nf = surface.domain_face_count();
        let mut count = vec![0usize; nf];
        // Per face, a bit per quarter (in `SAMPLE_AT`'s order) holding a foot point.
        let mut covered = vec![0u8; nf];
        for p in feet {
            if let Some(c) = count.get_mut(p.face as usize) {
                *c += 1;
                covered[p.face as usize] |= 1 << quarter(p.u, p.v);
            }
        }
        let mut faces = 0;
        let mut params = Vec::new();
        for (f, (&held, &quarters)) in count.iter().zip(&covered).enumerate() {
            if only.is_some_and(|o| !o.get(f).copied().unwrap_or(false)) {
                continue;
            }
            let sparse = held < SAMPLE_AT.len();
            let before = params.len();
            for (q, &(u, v)) in SAMPLE_AT.iter().enumerate() {
                if sparse || quarters & (1 << q) == 0 {
                    params.push(SurfaceParam {
                        face: f as u32,
                        u,
                        v,
                    });
                }
            }
            faces += usize::from(params.len() > before);
            // The boundary curve: each boundary edge at its first corner and midpoint
            // (every boundary vertex starts exactly one boundary edge).
            let edges = rim.boundary_edges_of(f);
            for k in (0..3).filter(|&k| edges[k]) {
                for t in [1.0, 0.5] {
                    let mut w = [0.0; 3];
                    w[k] = t;
                    w[(k + 1) % 3] = 1.0 - t;
                    params.push(SurfaceParam {
                        face: f as u32,
                        u: w[0],
                        v: w[1],
                    });
                }
            }
        }
        let evaluate = surface.evaluator(controls);
        let found: Vec<Option<(SurfaceParam, DVec3, DVec3, f64)>> = params
            .par_iter()
            .with_min_len(64)
            .map(|&param| {
                let at = evaluate(param).position;
                let c = nearest.closest(at)?;
                let t = data.triangles.get(c.triangle as usize)?;
                let p = t.map(|v| data.positions[v as usize]);
                let face_normal = (p[1] - p[0]).cross(p[2] - p[0]).try_normalize()?;
                // Off a data edge or corner the distance grows along the offset, not the
                // triangle's normal.
                let n = match (at - c.point).try_normalize() {
                    Some(g) if g.dot(face_normal).abs() < 0.9 => g,
                    _ => face_normal,
                };
                Some((param, c.point, n, at.distance(c.point)))
            })
            .collect();
        let mut samples = Samples::none();
        samples.faces = faces;
        for (param, target, n, d) in found.into_iter().flatten() {
            samples.params.push(param);
            samples.targets.push(target);
            samples.normals.push(n);
            samples.distances.push(d);
        }
        samples
    }
}

/// The quarter of a face (the children of its midpoint split, in `SAMPLE_AT`'s order:
/// middle, then the corner children of corners 0, 1, 2) holding face parameter (u, v).
fn quarter(u: f64, v: f64) -> usize {
    if u > 0.5 {
        1
    } else if v > 0.5 {
        2
    } else if u + v < 0.5 {
        3
    } else {
        0
    }
}

/// Foot points of every data point: parameters, unit normals and distances.
pub(super) struct Feet {
    pub params: Vec<SurfaceParam>,
    pub normals: Vec<DVec3>,
    pub distances: Vec<f64>,
    /// The curvature's term of each point's squared distance (`curvature_term`; empty
    /// when not asked for).
    pub curvature: Vec<[f64; 6]>,
}

/// A point's foot on the surface (Newton from `start`): parameter, unit normal, distance
/// and, with `curvature`, the curvature's term of its squared distance (zero without).
pub(super) fn foot(
    surface: &LoopLimitSurface,
    evaluate: &(dyn Fn(SurfaceParam) -> Derivatives + Sync),
    point: DVec3,
    start: SurfaceParam,
    curvature: bool,
) -> (SurfaceParam, DVec3, f64, [f64; 6]) {
    let (param, d) = foot_point(surface, evaluate, point, start);
    let r = d.position - point;
    // Where the tangents degenerate the residual is the best normal at hand.
    let normal =
        d.du.cross(d.dv)
            .try_normalize()
            .unwrap_or_else(|| r.try_normalize().unwrap_or(DVec3::Z));
    let term = if curvature {
        curvature_term(&d, normal, -r)
    } else {
        [0.0; 6]
    };
    (param, normal, r.length(), term)
}

impl Feet {
    /// Newton on the limit surface from `start`, crossing faces through `step`; with
    /// `curvature`, each point's curvature term too (else `curvature` stays empty).
    pub(super) fn find(
        surface: &LoopLimitSurface,
        controls: &[DVec3],
        data: &[DVec3],
        (start, curvature): (&[SurfaceParam], bool),
    ) -> Feet {
        let evaluate = surface.evaluator(controls);
        // Points taken face by face: the evaluator keeps the last leaf patch of an
        // irregular face it evaluated, which serves the next point on that face again.
        let n = data.len().min(start.len());
        let mut order: Vec<u32> = (0..n as u32).collect();
        order.sort_by_key(|&i| start[i as usize].face);
        let by_face: Vec<(SurfaceParam, DVec3, f64, [f64; 6])> = order
            .par_iter()
            .with_min_len(256)
            .map(|&i| {
                foot(
                    surface,
                    &*evaluate,
                    data[i as usize],
                    start[i as usize],
                    curvature,
                )
            })
            .collect();
        let mut feet = Feet {
            params: start[..n].to_vec(),
            normals: vec![DVec3::ZERO; n],
            distances: vec![0.0; n],
            curvature: vec![[0.0; 6]; if curvature { n } else { 0 }],
        };
        for (&i, (param, n, d, c)) in order.iter().zip(by_face) {
            let i = i as usize;
            (feet.params[i], feet.normals[i], feet.distances[i]) = (param, n, d);
            if let Some(slot) = feet.curvature.get_mut(i) {
                *slot = c;
            }
        }
        feet
    }

    /// Holds the feet of the data's rim points on the surface's boundary
    /// (`Rim::hold_where`, every rim point).
    pub(super) fn hold_rim(
        &mut self,
        rim: &Rim,
        surface: &LoopLimitSurface,
        controls: &[DVec3],
        data: &[DVec3],
    ) {
        let parts = FeetMut {
            params: &mut self.params,
            normals: &mut self.normals,
            distances: &mut self.distances,
        };
        rim.hold_where(parts, surface, controls, data, None);
    }

    pub(super) fn rms(&self) -> f64 {
        rms(&self.distances)
    }

    pub(super) fn max(&self) -> f64 {
        self.distances.iter().fold(0.0, |m, &d| m.max(d))
    }
}

/// The RMS over the data's distances to the surface and the samples' distances to the
/// data: what a round minimises, both sides of the distance (a round may move the
/// surface a little farther from the data points to pull a bulge back onto the data).
pub(super) fn two_sided_rms(data: &[f64], samples: &[f64]) -> f64 {
    let squares: f64 = data.iter().chain(samples).map(|d| d * d).sum();
    (squares / (data.len() + samples.len()).max(1) as f64).sqrt()
}

pub(super) fn rms(e: &[f64]) -> f64 {
    two_sided_rms(e, &[])
}
