//! The solves of a whole-object fit: rows of the Loop limit surface at the data's
//! parameters, the first point-to-point fit, foot points and the squared-distance rounds.
//! (The scan path has its own versions of these in `pipeline::scan_solve`, private there
//! and tied to its grid plans; these are the plain sparse forms.)

use crate::fit::distance::{solve_distance, solve_distance_direct, DistanceProblem};
use crate::fit::normal_matrix::{Fairness, ScalarMatrix};
use crate::fit::{Collocation, Csr};
use crate::pipeline::geometric::foot_point;
use crate::surface::loop_limit::LoopLimitSurface;
use crate::surface::{SurfaceParam, TriSurface};
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
            let (mut lens, mut cols, mut vals) = (Vec::with_capacity(chunk.len()), vec![], vec![]);
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
    let mut m = Csr {
        nrows: params.len(),
        ncols: surface.control_count(),
        row_ptr: Vec::with_capacity(params.len() + 1),
        ..Default::default()
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

/// One squared-distance solve at the current foot points.
pub(super) struct DistanceRound<'a> {
    pub surface: &'a LoopLimitSurface,
    pub data: &'a [DVec3],
    pub fairness: &'a Collocation,
    pub smoothing: f64,
    pub tangential: &'a [f64],
    pub max_iterations: usize,
}

impl DistanceRound<'_> {
    pub(super) fn solve(&self, feet: &Feet, start: Vec<DVec3>) -> Option<Vec<DVec3>> {
        let rows = rows_at(self.surface, &feet.params);
        let problem = DistanceProblem {
            basis: &rows,
            data: self.data,
            normals: &feet.normals,
            tangential: self.tangential,
            fairness: Some(self.fairness),
            smoothing: self.smoothing,
        };
        let x = match solve_distance_direct(&problem) {
            Some(x) => x,
            None => solve_distance(&problem, start, self.max_iterations, CG_REL_TOL).0,
        };
        x.iter().all(|p| p.is_finite()).then_some(x)
    }
}

/// Foot points of every data point: parameters, unit normals and distances.
pub(super) struct Feet {
    pub params: Vec<SurfaceParam>,
    pub normals: Vec<DVec3>,
    pub distances: Vec<f64>,
}

impl Feet {
    /// Newton on the limit surface from `start`, crossing faces through `step`.
    pub(super) fn find(
        surface: &LoopLimitSurface,
        controls: &[DVec3],
        data: &[DVec3],
        start: &[SurfaceParam],
    ) -> Feet {
        let evaluate = surface.evaluator(controls);
        let found: Vec<(SurfaceParam, DVec3, f64)> = data
            .par_iter()
            .zip(start.par_iter())
            .with_min_len(256)
            .map(|(p, s)| {
                let (param, d) = foot_point(surface, &*evaluate, *p, *s);
                let r = d.position - *p;
                // Where the tangents degenerate the residual is the best normal at hand.
                let n =
                    d.du.cross(d.dv)
                        .try_normalize()
                        .unwrap_or_else(|| r.try_normalize().unwrap_or(DVec3::Z));
                (param, n, r.length())
            })
            .collect();
        let mut feet = Feet {
            params: Vec::with_capacity(found.len()),
            normals: Vec::with_capacity(found.len()),
            distances: Vec::with_capacity(found.len()),
        };
        for (param, n, d) in found {
            feet.params.push(param);
            feet.normals.push(n);
            feet.distances.push(d);
        }
        feet
    }

    pub(super) fn rms(&self) -> f64 {
        rms(&self.distances)
    }

    pub(super) fn max(&self) -> f64 {
        self.distances.iter().fold(0.0, |m, &d| m.max(d))
    }
}

pub(super) fn rms(e: &[f64]) -> f64 {
    if e.is_empty() {
        return 0.0;
    }
    (e.iter().map(|d| d * d).sum::<f64>() / e.len() as f64).sqrt()
}
