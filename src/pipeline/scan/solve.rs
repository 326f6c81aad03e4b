//! The solves of a scan fit: the first point-to-point fit, the squared-distance rounds'
//! solves and the foot points between them. Grid fits assemble their normal equations
//! through a `StencilPlan` of the grid's covered cells, built once per fit: every round then
//! skips grouping rows, gathering neighbours and recomputing the fairness term.

use crate::fit::distance::{solve_distance, solve_distance_direct, DistanceProblem};
use crate::fit::normal_matrix::{Fairness, ScalarMatrix};
use crate::fit::stencil_matrix::{StencilPlan, StencilRows};
use crate::fit::{
    fit, Budget, Collocation, Csr, FitOutcome, FitProblem, FitStatus, Method, StepStats,
};
use crate::pipeline::collocation::{collocation, collocation_rows};
use crate::pipeline::geometric;
use crate::pipeline::{FitOptions, PipelineError};
use crate::surface::grid_spline::{GridEvaluator, GridSpline};
use crate::surface::{Derivatives, SurfaceParam, TriSurface};
use glam::DVec3;
use rayon::prelude::*;
use std::time::Instant;

/// A grid fit's assembly plan and where each cell slot's stencil sits in it. The plan
/// carries the fairness term with its weight: solves through it must use that `smoothing`.
pub(super) struct GridStencils<'a> {
    grid: &'a GridSpline,
    of_slot: Vec<u32>,
    plan: StencilPlan,
    smoothing: f64,
}

impl<'a> GridStencils<'a> {
    pub(super) fn new(grid: &'a GridSpline, fairness: &Collocation, smoothing: f64) -> Self {
        Self::with_rows(grid, fairness, smoothing, &[]).0
    }

    /// `new` and the data rows at `params` (`rows`), built side by side: the rows need only
    /// the cell table, not the plan.
    pub(super) fn with_rows(
        grid: &'a GridSpline,
        fairness: &Collocation,
        smoothing: f64,
        params: &[SurfaceParam],
    ) -> (Self, Option<StencilRows>) {
        let (stencils, of_slot) = grid.stencil_table();
        let fair = Fairness {
            l: fairness.n(),
            lt: fairness.nt(),
            smoothing,
        };
        let (plan, rows) = rayon::join(
            || StencilPlan::new(grid.control_count(), stencils, Some(fair)),
            || rows_at(grid, &of_slot, params),
        );
        let built = Self {
            grid,
            of_slot,
            plan,
            smoothing,
        };
        (built, rows)
    }

    /// The data rows at `params`; `None` if one lies outside the covered cells (the
    /// general assembly then takes over).
    fn rows(&self, params: &[SurfaceParam]) -> Option<StencilRows> {
        rows_at(self.grid, &self.of_slot, params)
    }
}

/// `GridStencils::rows` from the grid and its cell table.
fn rows_at(grid: &GridSpline, of_slot: &[u32], params: &[SurfaceParam]) -> Option<StencilRows> {
    // Written in place: collecting `Option`s would gather the rows in pieces and copy
    // them twice (into one vector, then apart), fresh memory each time.
    let mut stencil = vec![0u32; params.len()];
    let mut weights = vec![[0.0; 12]; params.len()];
    let all_inside = stencil
        .par_iter_mut()
        .zip(weights.par_iter_mut())
        .zip(params)
        .with_min_len(1024)
        .all(|((s, w), p)| match grid.stencil_row(of_slot, *p) {
            Some((g, values)) => {
                (*s, *w) = (g, values);
                true
            }
            None => false,
        });
    all_inside.then_some(StencilRows { stencil, weights })
}

/// Data rows as the general sparse matrix or as stencil rows of a plan.
enum Rows<'a> {
    General(Csr),
    Stencil(StencilRows, &'a StencilPlan),
}

impl<'a> Rows<'a> {
    fn at(
        surface: &dyn TriSurface,
        stencils: Option<&'a GridStencils>,
        params: &[SurfaceParam],
        smoothing: f64,
    ) -> Self {
        debug_assert!(stencils.is_none_or(|s| s.smoothing == smoothing));
        match stencils.and_then(|s| Some((s.rows(params)?, &s.plan))) {
            Some((rows, plan)) => Rows::Stencil(rows, plan),
            None => Rows::General(collocation_rows(surface, params)),
        }
    }

    fn mul_vec3(&self, x: &[DVec3], out: &mut [DVec3]) {
        match self {
            Rows::General(n) => n.mul_vec3(x, out),
            Rows::Stencil(rows, plan) => rows.mul_vec3(plan, x, out),
        }
    }

    fn general(&self) -> std::borrow::Cow<'_, Csr> {
        match self {
            Rows::General(n) => std::borrow::Cow::Borrowed(n),
            Rows::Stencil(rows, plan) => std::borrow::Cow::Owned(rows.to_csr(plan)),
        }
    }
}

/// The point-to-point fit of `pia` and `lspia` (and of `parameters` correction rounds)
/// through the engine, step by step with the budget checked after each.
pub(super) fn run_fit(
    surface: &dyn TriSurface,
    params: &[SurfaceParam],
    data: &[DVec3],
    fairness: &Collocation,
    smoothing: f64,
    start: Vec<DVec3>,
    opts: &FitOptions,
) -> Result<FitOutcome, PipelineError> {
    let basis = collocation(surface, params);
    let problem = FitProblem {
        basis: &basis,
        data,
        smoothing,
        fairness: Some(fairness),
        pia_operator: None,
        on_step: opts.on_step,
    };
    let budget: &Budget = &opts.budget;
    Ok(fit(&problem, start, opts.method, budget)?)
}

/// Relative residual of the normal equations at which an assembled first fit stops. Not
/// looser: at 1e-5 the controls over sparse gaps, held only by the fairness term (CG's
/// slowest modes), stayed off and bun045's shown surface bulged 2.1 mm from the data
/// (0.39 mm at 1e-6) though every RMS was the same.
const FIRST_FIT_REL_TOL: f64 = 1e-6;

/// The point-to-point fit of `cg` and `direct` through the assembled normal equations
/// N^T N + s L^T L (one scalar matrix for x, y and z; Jacobi-preconditioned CG from the
/// start net, or a sparse Cholesky): a CG step then reads ~37 entries per control instead
/// of going through all data points twice, so converging costs a few ms where the
/// engine's CGLS spent ~100 ms on a 40k-point scan. The budget is checked on the result
/// (the engine checks it after every step): this fit is only the start of the rounds.
/// `rows`: the stencil rows at `params` when the caller built them with the plan
/// (`GridStencils::with_rows`).
#[allow(clippy::too_many_arguments)]
pub(super) fn assembled_fit(
    surface: &dyn TriSurface,
    stencils: Option<&GridStencils>,
    params: &[SurfaceParam],
    data: &[DVec3],
    fairness: &Collocation,
    smoothing: f64,
    start: Vec<DVec3>,
    opts: &FitOptions,
    rows: Option<StencilRows>,
) -> FitOutcome {
    let t0 = Instant::now();
    let basis = match (rows, stencils) {
        (Some(rows), Some(s)) => Rows::Stencil(rows, &s.plan),
        _ => Rows::at(surface, stencils, params, smoothing),
    };
    let budget = &opts.budget;
    let stats = |k: usize, x: &[DVec3]| {
        let mut fitted = vec![DVec3::ZERO; data.len()];
        basis.mul_vec3(x, &mut fitted);
        fitted.iter_mut().zip(data).for_each(|(f, p)| *f = *p - *f);
        let s = StepStats::from_residuals(
            k,
            &fitted,
            budget.tolerance,
            t0.elapsed().as_secs_f64() * 1e3,
        );
        if let Some(hook) = opts.on_step {
            hook(&s);
        }
        s
    };
    let first = stats(0, &start);
    if budget.met(&first) {
        return FitOutcome {
            controls: start,
            steps: vec![first],
            status: FitStatus::Met,
            iterations: 0,
        };
    }
    let fair = Some(Fairness {
        l: fairness.n(),
        lt: fairness.nt(),
        smoothing,
    });
    let direct = (opts.method == Method::Direct)
        .then(|| {
            ScalarMatrix::assemble(&basis.general(), data, fair, true)
                .solve_direct()
                .ok()
        })
        .flatten();
    let (controls, k) = match direct {
        Some(x) => (x, 1),
        None => {
            let matrix = match &basis {
                Rows::General(n) => ScalarMatrix::assemble(n, data, fair, false),
                Rows::Stencil(rows, plan) => plan.assemble_scalar(rows, data),
            };
            matrix.solve_pcg(start, budget.max_iterations.max(1), FIRST_FIT_REL_TOL)
        }
    };
    let last = stats(k.max(1), &controls);
    let status = if budget.met(&last) {
        FitStatus::Met
    } else if k >= budget.max_iterations {
        FitStatus::Capped
    } else {
        FitStatus::Stalled
    };
    FitOutcome {
        controls,
        steps: vec![first, last],
        status,
        iterations: 1,
    }
}

/// Up to this many control points a distance round is solved by a sparse factorisation.
const DIRECT_ROUND_MAX_CONTROLS: usize = 1000;

/// Relative residual of the normal equations at which a distance round's CG stops. At
/// 3e-6 the five Stanford scans end in the same rounds and RMS (within 0.4 um) with ~40 %
/// fewer steps, but the least-held controls (over sparse gaps) converge last: meshlab's
/// shown surface then stood 0.59 mm from the data instead of 0.45 mm. 1e-4 once left
/// bun000 at 80 um RMS and chin at 112 um instead of 66 and 83.
const ROUND_REL_TOL: f64 = 1e-6;

/// What a distance round solves at the current foot points.
pub(super) struct DistanceRound<'a> {
    pub surface: &'a dyn TriSurface,
    pub stencils: Option<&'a GridStencils<'a>>,
    pub data: &'a [DVec3],
    pub fairness: &'a Collocation,
    pub smoothing: f64,
    /// Per data point (`edge_band`: larger along the data's edges).
    pub tangential: &'a [f64],
    pub max_iterations: usize,
}

impl DistanceRound<'_> {
    /// The controls minimising the round's squared distances from `start`, and the CG
    /// steps taken (1 for a factorisation).
    /// `rows`: the stencil rows at `params` when the foot-point pass made them.
    pub(super) fn solve(
        &self,
        params: &[SurfaceParam],
        rows: Option<StencilRows>,
        normals: &[DVec3],
        start: Vec<DVec3>,
    ) -> (Vec<DVec3>, usize) {
        let rows = match (rows, self.stencils) {
            (Some(rows), Some(s)) => {
                debug_assert_eq!(s.smoothing, self.smoothing);
                Rows::Stencil(rows, &s.plan)
            }
            _ => Rows::at(self.surface, self.stencils, params, self.smoothing),
        };
        // Small nets: one factorisation beats 25-45 preconditioned CG steps (camel head,
        // 559 controls: fit 205 ms vs 428 ms); at ~2000 controls the factorisation is the
        // slower (bun000: 736 ms vs 502 ms).
        if self.surface.control_count() <= DIRECT_ROUND_MAX_CONTROLS {
            let basis = rows.general();
            let problem = DistanceProblem {
                basis: &basis,
                data: self.data,
                normals,
                tangential: self.tangential,
                curvature: None,
                fairness: Some(self.fairness),
                smoothing: self.smoothing,
            };
            return match solve_distance_direct(&problem) {
                Some(x) => (x, 1),
                None => solve_distance(&problem, start, self.max_iterations, ROUND_REL_TOL),
            };
        }
        match &rows {
            Rows::Stencil(r, plan) => plan
                .assemble_blocks(r, self.data, normals, self.tangential)
                .solve_pcg(start, self.max_iterations, ROUND_REL_TOL),
            Rows::General(basis) => {
                let problem = DistanceProblem {
                    basis,
                    data: self.data,
                    normals,
                    tangential: self.tangential,
                    curvature: None,
                    fairness: Some(self.fairness),
                    smoothing: self.smoothing,
                };
                solve_distance(&problem, start, self.max_iterations, ROUND_REL_TOL)
            }
        }
    }
}

/// The data seen from their foot points: residual p - S(foot) and the unit surface normal,
/// and for grid fits the collocation rows there (the next round's solve needs them).
pub(super) struct Feet {
    pub(super) residuals: Vec<DVec3>,
    pub(super) normals: Vec<DVec3>,
    pub(super) rows: Option<StencilRows>,
}

impl Feet {
    pub(super) fn distances(&self) -> Vec<f64> {
        self.residuals.iter().map(|r| r.length()).collect()
    }
}

/// Moves every parameter to its foot point; what a round needs of the surface there comes
/// from the foot-point search's last evaluation, and the rows from the same pass.
pub(super) fn foot_points(
    surface: &dyn TriSurface,
    stencils: Option<&GridStencils>,
    controls: &[DVec3],
    data: &[DVec3],
    params: &mut [SurfaceParam],
) -> Feet {
    match stencils {
        // The grid's own evaluator and steps, not through `dyn`: the Newton search then
        // inlines the evaluation (a pass over a 40k-point scan evaluates ~100k times).
        Some(s) => {
            let evaluator = GridEvaluator::new(s.grid, controls);
            feet_on(s.grid, &|p| evaluator.evaluate(p), stencils, data, params)
        }
        None => feet_on(surface, &*surface.evaluator(controls), None, data, params),
    }
}

/// `foot_points` with the surface and its evaluator as given.
fn feet_on<S: TriSurface + ?Sized>(
    surface: &S,
    evaluate: &(impl Fn(SurfaceParam) -> Derivatives + Sync + ?Sized),
    stencils: Option<&GridStencils>,
    data: &[DVec3],
    params: &mut [SurfaceParam],
) -> Feet {
    let outside = (u32::MAX, [0.0; 12]);
    let (residuals, (normals, (stencil, weights))): (Vec<_>, (Vec<_>, (Vec<_>, Vec<_>))) = data
        .par_iter()
        .zip(params.par_iter_mut())
        .map(|(p, u)| {
            let (foot, d) = geometric::foot_point(surface, evaluate, *p, *u);
            *u = foot;
            let row = stencils.map_or(outside, |s| {
                s.grid.stencil_row(&s.of_slot, foot).unwrap_or(outside)
            });
            (*p - d.position, (d.du.cross(d.dv).normalize_or_zero(), row))
        })
        .unzip();
    let rows = (stencils.is_some() && stencil.iter().all(|&g| g != u32::MAX))
        .then_some(StencilRows { stencil, weights });
    Feet {
        residuals,
        normals,
        rows,
    }
}

pub(super) fn rms(e: &[f64]) -> f64 {
    (e.iter().map(|x| x * x).sum::<f64>() / e.len().max(1) as f64).sqrt()
}
