//! Fitting B-patches and DMS splines (any `PlanarSurface`) to scattered (parameter, point)
//! data through the fitting engine (`fit::fit`), with foot-point parameter correction
//! between rounds: every round fits at fixed parameters, then moves each parameter to the
//! foot point of its data point on the new surface (Newton on |S(u) - p|^2 with the
//! surface's second derivatives) and refits from the previous controls.
//!
//! PIA needs a map from data residuals to control updates. On subdivision-lattice data the
//! caller passes the inverse-subdivision operator (the paper's setting). For scattered data
//! the default is the column average `delta_i = sum_j N_ji r_j / sum_j N_ji`: every control
//! moves by the mean residual of the data it influences (weighted by its basis value).
//! Its iteration matrix `I - D^-1 N^T N` (D the column sums) has eigenvalues in [0, 1):
//! N^T N has row sums D, so D^-1 N^T N is non-negative with unit row sums, and it is
//! similar to the positive semi-definite D^-1/2 N^T N D^-1/2. It converges to the least
//! squares fit whenever N has full column rank.
//!
//! This module sits beside `fit` and `surface` (it uses both); the pipeline calls
//! `fit_scattered` with a surface built from the config.

use crate::fit::engine::{umbrella_laplacian_of_edges, PiaOperator};
use crate::fit::{fit, Budget, Collocation, Csr, FitError, FitOutcome, FitProblem, Method};
use crate::surface::dms::PlanarSurface;
use crate::surface::{Derivatives, SurfaceParam, TriSurface};
use glam::{DVec2, DVec3};
use rayon::prelude::*;
use std::time::Instant;

/// Where the controls start.
#[derive(Clone, Debug, Default)]
pub enum InitialNet {
    /// The least-squares affine map of the data over the domain, at the Greville sites:
    /// the spline of that plane exactly.
    #[default]
    Affine,
    /// Each control at the data point whose domain point is nearest its Greville site.
    NearestData,
    /// These controls, in the surface's control order (their count must match).
    Given(Vec<DVec3>),
}

/// How `fit_scattered` fits.
#[derive(Clone, Debug)]
pub struct ScatteredOptions {
    /// The engine's solver, used in every round.
    pub method: Method,
    /// When each round's fit stops (applied per round, not over all rounds).
    pub budget: Budget,
    /// Weight of the umbrella fairness term over the control net (0: none).
    pub smoothing: f64,
    /// Foot-point correction rounds after the first fit.
    pub correction_rounds: usize,
    /// Newton steps per foot point and round.
    pub newton_steps: usize,
    /// Where the controls of the first round start.
    pub initial: InitialNet,
}

impl Default for ScatteredOptions {
    fn default() -> Self {
        Self {
            method: Method::Cg,
            budget: Budget::default(),
            smoothing: 0.0,
            correction_rounds: 0,
            newton_steps: 6,
            initial: InitialNet::Affine,
        }
    }
}

/// The result of `fit_scattered`.
#[derive(Clone, Debug)]
pub struct ScatteredFit {
    /// The controls after the last round.
    pub controls: Vec<DVec3>,
    /// The parameters after the last correction round.
    pub params: Vec<SurfaceParam>,
    /// One engine outcome per round (round 0 at the given parameters).
    pub rounds: Vec<FitOutcome>,
    /// Collocation and fairness assembly, summed over rounds.
    pub assembly_ms: f64,
    /// Time in the fitting engine, summed over rounds.
    pub solve_ms: f64,
    /// Time moving parameters to foot points, summed over rounds.
    pub correction_ms: f64,
}

/// Why `fit_scattered` failed.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ScatteredFitError {
    /// The parameter and data slices differ in length.
    #[error("{params} parameters for {points} data points")]
    Count {
        /// Number of parameters given.
        params: usize,
        /// Number of data points given.
        points: usize,
    },
    /// No data points were given.
    #[error("no data points")]
    Empty,
    /// The initial net's size does not match the surface's control count.
    #[error("initial net has {found} points, the surface {expected} controls")]
    InitialShape {
        /// Points in the initial net.
        found: usize,
        /// Controls the surface has.
        expected: usize,
    },
    /// The fitting engine failed in one round.
    #[error("fit round {round}")]
    Fit {
        /// The round that failed (0: the fit at the given parameters).
        round: usize,
        /// The engine's error.
        #[source]
        source: FitError,
    },
}

/// The collocation rows at `params` (parallel over chunks).
pub fn collocation_matrix(surface: &dyn TriSurface, params: &[SurfaceParam]) -> Csr {
    const CHUNK: usize = 2048;
    let rows: Vec<Vec<(u32, f64)>> = params
        .par_chunks(CHUNK)
        .flat_map_iter(|chunk| {
            chunk.iter().map(|p| {
                let mut row = Vec::new();
                surface.basis_row(*p, &mut row);
                row
            })
        })
        .collect();
    Csr::from_rows(surface.control_count(), rows.iter().map(|r| r.as_slice()))
}

/// Umbrella Laplacian over the control net: row i is `P_i - mean(neighbours)`.
pub fn fairness_operator(surface: &dyn PlanarSurface) -> Csr {
    umbrella_laplacian_of_edges(surface.control_count(), surface.control_net_edges())
}

/// The column-average PIA update `D^-1 N^T r` (module docs); controls without data stay.
pub fn column_average_update(basis: &Collocation, residuals: &[DVec3]) -> Vec<DVec3> {
    let nt = basis.nt();
    (0..nt.nrows)
        .map(|i| {
            let range = nt.row_ptr[i]..nt.row_ptr[i + 1];
            let weight: f64 = nt.values[range.clone()].iter().sum();
            if weight <= 0.0 {
                return DVec3::ZERO;
            }
            let sum: DVec3 = range
                .map(|k| residuals[nt.col_idx[k] as usize] * nt.values[k])
                .sum();
            sum / weight
        })
        .collect()
}

/// The starting controls of `kind`.
pub fn initial_net(
    surface: &dyn PlanarSurface,
    params: &[SurfaceParam],
    data: &[DVec3],
    kind: &InitialNet,
) -> Vec<DVec3> {
    let sites = surface.greville_sites();
    let domain: Vec<DVec2> = params.iter().map(|p| surface.domain_point(*p)).collect();
    match kind {
        InitialNet::Given(controls) => controls.clone(),
        InitialNet::Affine => {
            let map = affine_fit(&domain, data);
            sites.iter().map(|s| map(*s)).collect()
        }
        InitialNet::NearestData => sites
            .iter()
            .map(|s| {
                domain
                    .iter()
                    .zip(data)
                    .min_by(|a, b| {
                        a.0.distance_squared(*s)
                            .total_cmp(&b.0.distance_squared(*s))
                    })
                    .map_or(DVec3::ZERO, |(_, p)| *p)
            })
            .collect(),
    }
}

/// Least-squares affine map domain -> space (the mean where the domain points are
/// collinear).
fn affine_fit(domain: &[DVec2], data: &[DVec3]) -> impl Fn(DVec2) -> DVec3 {
    let m = domain.len().max(1) as f64;
    let cx = domain.iter().sum::<DVec2>() / m;
    let cp = data.iter().sum::<DVec3>() / m;
    let (mut sxx, mut sxy, mut syy) = (0.0, 0.0, 0.0);
    let (mut bx, mut by) = (DVec3::ZERO, DVec3::ZERO);
    for (x, p) in domain.iter().zip(data) {
        let (dx, dp) = (*x - cx, *p - cp);
        sxx += dx.x * dx.x;
        sxy += dx.x * dx.y;
        syy += dx.y * dx.y;
        bx += dp * dx.x;
        by += dp * dx.y;
    }
    let det = sxx * syy - sxy * sxy;
    let (gx, gy) = if det > 1e-14 * (sxx + syy).powi(2) {
        ((bx * syy - by * sxy) / det, (by * sxx - bx * sxy) / det)
    } else {
        (DVec3::ZERO, DVec3::ZERO)
    };
    move |x: DVec2| cp + gx * (x.x - cx.x) + gy * (x.y - cx.y)
}

/// Foot points: from each parameter, Newton steps on `|S(u) - p|^2 / 2` (Gauss-Newton where
/// the Hessian is not positive definite), each step halved until the distance drops.
pub fn foot_points(
    surface: &dyn TriSurface,
    controls: &[DVec3],
    params: &[SurfaceParam],
    data: &[DVec3],
    steps: usize,
) -> Vec<SurfaceParam> {
    feet_with_derivatives(surface, controls, params, data, steps)
        .into_iter()
        .map(|(p, _)| p)
        .collect()
}

/// A Newton step that moves the surface point less than this share of its distance to the
/// data point ends the search: sliding t along the surface changes a distance d by about
/// t^2 / (2 d), here under 1e-6 of it.
const FOOT_STEP_SHARE: f64 = 1e-3;

/// `foot_points` with the surface's derivatives at each foot (what callers want next:
/// the distance, the normal), so that nobody evaluates the feet again.
pub fn feet_with_derivatives(
    surface: &dyn TriSurface,
    controls: &[DVec3],
    params: &[SurfaceParam],
    data: &[DVec3],
    steps: usize,
) -> Vec<(SurfaceParam, Derivatives)> {
    let eval = surface.evaluator(controls);
    params
        .par_iter()
        .zip(data.par_iter())
        .map(|(&start, &target)| {
            let mut p = start;
            let mut d = eval(p);
            let mut dist2 = (d.position - target).length_squared();
            for _ in 0..steps {
                let r = d.position - target;
                let g = [d.du.dot(r), d.dv.dot(r)];
                let gn = [d.du.dot(d.du), d.du.dot(d.dv), d.dv.dot(d.dv)];
                let full = [
                    gn[0] + d.duu.dot(r),
                    gn[1] + d.duv.dot(r),
                    gn[2] + d.dvv.dot(r),
                ];
                let pd = |h: [f64; 3]| h[0] > 0.0 && h[0] * h[2] - h[1] * h[1] > 0.0;
                let h = if pd(full) { full } else { gn };
                let det = h[0] * h[2] - h[1] * h[1];
                if det.is_nan() || det <= 0.0 {
                    break;
                }
                let mut du = -(h[2] * g[0] - h[1] * g[1]) / det;
                let mut dv = -(h[0] * g[1] - h[1] * g[0]) / det;
                // Converged: a step this small in barycentric units moves nothing visible,
                // nor does one that slides the point a small share of its distance.
                let slide2 = (d.du * du + d.dv * dv).length_squared();
                if du.abs() + dv.abs() < 1e-10 || slide2 <= FOOT_STEP_SHARE.powi(2) * dist2 {
                    break;
                }
                let mut moved = false;
                for _ in 0..5 {
                    let q = surface.step(p, du, dv);
                    let dq = eval(q);
                    let dist2_q = (dq.position - target).length_squared();
                    if dist2_q < dist2 {
                        (p, d, dist2, moved) = (q, dq, dist2_q, true);
                        break;
                    }
                    du *= 0.5;
                    dv *= 0.5;
                }
                if !moved {
                    break;
                }
            }
            (p, d)
        })
        .collect()
}

/// Fits `surface` to `data` at `params` (one per point), then runs the correction rounds.
/// `pia_operator` replaces the column-average PIA update (e.g. inverse subdivision on
/// lattice data).
pub fn fit_scattered(
    surface: &dyn PlanarSurface,
    params: &[SurfaceParam],
    data: &[DVec3],
    options: &ScatteredOptions,
    pia_operator: Option<PiaOperator>,
) -> Result<ScatteredFit, ScatteredFitError> {
    if data.is_empty() {
        return Err(ScatteredFitError::Empty);
    }
    if params.len() != data.len() {
        return Err(ScatteredFitError::Count {
            params: params.len(),
            points: data.len(),
        });
    }
    let t0 = Instant::now();
    let mut controls = initial_net(surface, params, data, &options.initial);
    if controls.len() != surface.control_count() {
        return Err(ScatteredFitError::InitialShape {
            found: controls.len(),
            expected: surface.control_count(),
        });
    }
    let fairness = (options.smoothing > 0.0).then(|| Collocation::new(fairness_operator(surface)));
    let mut assembly_ms = t0.elapsed().as_secs_f64() * 1e3;
    let (mut solve_ms, mut correction_ms) = (0.0, 0.0);
    let mut params = params.to_vec();
    let mut rounds = Vec::with_capacity(options.correction_rounds + 1);
    for round in 0..=options.correction_rounds {
        if round > 0 {
            let t = Instant::now();
            params = foot_points(surface, &controls, &params, data, options.newton_steps);
            correction_ms += t.elapsed().as_secs_f64() * 1e3;
        }
        let t = Instant::now();
        let basis = Collocation::new(collocation_matrix(surface, &params));
        assembly_ms += t.elapsed().as_secs_f64() * 1e3;
        let column_average = |r: &[DVec3]| column_average_update(&basis, r);
        let problem = FitProblem {
            basis: &basis,
            data,
            smoothing: options.smoothing,
            fairness: fairness.as_ref(),
            pia_operator: Some(pia_operator.unwrap_or(&column_average)),
            on_step: None,
        };
        let t = Instant::now();
        let outcome = fit(&problem, controls, options.method, &options.budget)
            .map_err(|source| ScatteredFitError::Fit { round, source })?;
        solve_ms += t.elapsed().as_secs_f64() * 1e3;
        controls = outcome.controls.clone();
        rounds.push(outcome);
    }
    Ok(ScatteredFit {
        controls,
        params,
        rounds,
        assembly_ms,
        solve_ms,
        correction_ms,
    })
}
