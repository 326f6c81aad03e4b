//! The rounds of a planar-domain fit: the first fit at the mapped parameters (the engine,
//! with the configured method and budget; CG as the direct solve, `first_fit`), then per
//! round the foot points of the data on the current surface and a refit there, while a
//! round lowers the geometric RMS by at least `fit.correction.min_gain` and the next round
//! is predicted to (`next_round_predicted_below`).
//!
//! The refit is squared-distance minimisation (`fit::distance`: point-to-plane with the
//! tangential share `fit.correction.tangential`), as on the scan path: point-to-point refits
//! at the foot points (`kind = "parameters"`) let the surface slide only as far as one
//! parameter correction moves the points, and on bun045 (DMS degree 2, 2004 controls) they
//! still gained 4 % per round after four rounds (181 -> 152 um).

use super::error::ScatteredError;
use super::info::PlanarStages;
use crate::fit::distance::{
    solve_distance, solve_distance_round, CholeskyPattern, DistanceProblem,
};
use crate::fit::{Budget, Collocation, FitOutcome, Method};
use crate::pipeline::scan::{Correction, CorrectionConfig};
use crate::pipeline::worker::FitConfig;
use crate::pipeline::PipelineError;
use crate::scattered_fit::{
    collocation_matrix, fairness_operator, feet_with_derivatives, fit_scattered, initial_net,
    InitialNet, ScatteredOptions,
};
use crate::surface::dms::PlanarSurface;
use crate::surface::SurfaceParam;
use glam::DVec3;

/// Newton steps per foot point and round.
pub(super) const NEWTON_STEPS: usize = 6;

/// The first fit's options, the same for scans and subdivided inputs: the scan path's
/// smoothing scaled by data points per control, so the fairness term weighs alike at any
/// control count; the engine runs no correction rounds, `fit_rounds` does them.
pub(super) fn first_fit_options(
    fit: &FitConfig,
    budget: &Budget,
    surface: &dyn PlanarSurface,
    points: usize,
    initial: InitialNet,
) -> ScatteredOptions {
    ScatteredOptions {
        method: fit.method,
        budget: budget.clone(),
        smoothing: fit.scan.smoothing * points as f64 / surface.control_count().max(1) as f64,
        correction_rounds: 0,
        newton_steps: NEWTON_STEPS,
        initial,
    }
}

/// Preconditioned CG steps and relative residual of a distance round when the direct
/// solve is refused (the scan path's values).
const ROUND_MAX_ITERATIONS: usize = 200;
const ROUND_REL_TOL: f64 = 1e-6;

/// The rounds' result: the best round's surface and the data's foot points on it.
pub(super) struct Rounds {
    /// The first fit's engine outcome, its controls those of the best round.
    pub(super) outcome: FitOutcome,
    pub(super) params: Vec<SurfaceParam>,
    pub(super) errors: Vec<f64>,
    /// Geometric RMS after each round.
    pub(super) rms: Vec<f64>,
    pub(super) stages: PlanarStages,
}

/// The data's feet on the surface of `controls` (from `params`): each foot, its unit
/// normal and its distance, and the RMS distance.
struct Feet {
    params: Vec<SurfaceParam>,
    normals: Vec<DVec3>,
    errors: Vec<f64>,
    rms: f64,
}

fn feet_and_errors(
    surface: &dyn PlanarSurface,
    controls: &[DVec3],
    params: &[SurfaceParam],
    data: &[DVec3],
) -> Feet {
    let feet = feet_with_derivatives(surface, controls, params, data, NEWTON_STEPS);
    let errors: Vec<f64> = feet
        .iter()
        .zip(data)
        .map(|((_, d), x)| (d.position - *x).length())
        .collect();
    let rms = (errors.iter().map(|e| e * e).sum::<f64>() / errors.len().max(1) as f64).sqrt();
    Feet {
        normals: feet
            .iter()
            .map(|(_, d)| d.du.cross(d.dv).normalize_or_zero())
            .collect(),
        params: feet.into_iter().map(|(p, _)| p).collect(),
        errors,
        rms,
    }
}

/// One squared-distance round at the feet of the surface of `controls`.
#[allow(clippy::too_many_arguments)]
fn distance_round(
    surface: &dyn PlanarSurface,
    controls: &[DVec3],
    feet: &Feet,
    data: &[DVec3],
    fairness: &Collocation,
    smoothing: f64,
    tangential: f64,
    stages: &mut PlanarStages,
    pattern: &mut CholeskyPattern,
) -> Vec<DVec3> {
    let basis = stages
        .rows
        .time(|| collocation_matrix(surface, &feet.params));
    stages.solves.time(|| {
        distance_solve(
            &basis, controls, feet, data, fairness, smoothing, tangential, pattern,
        )
    })
}

#[allow(clippy::too_many_arguments)]
fn distance_solve(
    basis: &crate::fit::Csr,
    controls: &[DVec3],
    feet: &Feet,
    data: &[DVec3],
    fairness: &Collocation,
    smoothing: f64,
    tangential: f64,
    pattern: &mut CholeskyPattern,
) -> Vec<DVec3> {
    let tangential = vec![tangential; data.len()];
    let problem = DistanceProblem {
        basis,
        data,
        normals: &feet.normals,
        tangential: &tangential,
        curvature: None,
        fairness: Some(fairness),
        smoothing,
    };
    solve_distance_round(&problem, pattern, Some(controls)).unwrap_or_else(|| {
        solve_distance(
            &problem,
            controls.to_vec(),
            ROUND_MAX_ITERATIONS,
            ROUND_REL_TOL,
        )
        .0
    })
}

/// The first fit at `params`. With CG (the default method) it is the direct solve of the
/// same normal equations: the first fit only starts the rounds, which factorise a matrix of
/// the same size and sparsity anyway, and CG capped at the budget's steps stops short of
/// that least-squares fit (in the stop-29 profile of bun045_tri, DMS degree 2, the capped
/// CG took 7.6 % of the fit). CG runs as configured when the factorisation fails.
fn first_fit(
    surface: &dyn PlanarSurface,
    params: &[SurfaceParam],
    data: &[DVec3],
    options: &ScatteredOptions,
) -> Result<FitOutcome, PipelineError> {
    let last = |fitted: crate::scattered_fit::ScatteredFit| {
        fitted
            .rounds
            .into_iter()
            .last()
            .ok_or(ScatteredError::EmptyDomain)
    };
    if options.method == Method::Cg {
        let direct = ScatteredOptions {
            method: Method::Direct,
            ..options.clone()
        };
        if let Ok(fitted) = fit_scattered(surface, params, data, &direct, None) {
            return Ok(last(fitted)?);
        }
    }
    let fitted =
        fit_scattered(surface, params, data, options, None).map_err(ScatteredError::Fit)?;
    Ok(last(fitted)?)
}

/// True when the next round is not worth running: rounds are a fixed-point iteration, so
/// their relative gains shrink by a near-constant ratio, and the last gain times the last
/// ratio predicts the next one. Once that is under `min_gain` the next round would gain
/// less than `fit_rounds` asks of a round, so it is not run (where the ratio does not shrink
/// the prediction is the last gain, and the plain `min_gain` test decides).
fn next_round_predicted_below(gains: &[f64], min_gain: f64) -> bool {
    match gains {
        [.., before, last] if *before > 0.0 && *last > 0.0 => {
            last * (last / before).min(1.0) < min_gain
        }
        _ => false,
    }
}

/// The first fit at `params`, then the rounds (module docs); a round that does not lower
/// the RMS is not kept.
pub(super) fn fit_rounds(
    surface: &dyn PlanarSurface,
    params: Vec<SurfaceParam>,
    data: &[DVec3],
    mut options: ScatteredOptions,
    correction: &CorrectionConfig,
) -> Result<Rounds, PipelineError> {
    let mut stages = PlanarStages::default();
    let mut outcome = stages
        .first_fit
        .time(|| first_fit(surface, &params, data, &options))?;
    let mut feet = stages
        .feet
        .time(|| feet_and_errors(surface, &outcome.controls, &params, data));
    let mut rms_history = vec![feet.rms];
    let fairness = Collocation::new(fairness_operator(surface));
    let mut gains = Vec::new();
    // One symbolic analysis for the rounds' normal matrices (`CholeskyPattern`).
    let mut pattern = CholeskyPattern::default();
    for _ in 0..correction.rounds {
        let controls = match correction.kind {
            Correction::Distance => distance_round(
                surface,
                &outcome.controls,
                &feet,
                data,
                &fairness,
                options.smoothing,
                correction.tangential,
                &mut stages,
                &mut pattern,
            ),
            Correction::Parameters => {
                options.initial = InitialNet::Given(outcome.controls.clone());
                let refit = stages
                    .solves
                    .time(|| fit_scattered(surface, &feet.params, data, &options, None))
                    .map_err(ScatteredError::Fit)?;
                refit
                    .rounds
                    .into_iter()
                    .last()
                    .ok_or(ScatteredError::EmptyDomain)?
                    .controls
            }
        };
        let next = stages
            .feet
            .time(|| feet_and_errors(surface, &controls, &feet.params, data));
        rms_history.push(next.rms);
        let best = feet.rms;
        let gain = (best - next.rms) / best.max(f64::MIN_POSITIVE);
        if next.rms < best {
            feet = next;
            outcome.controls = controls;
        }
        gains.push(gain);
        if gain < correction.min_gain || next_round_predicted_below(&gains, correction.min_gain) {
            break;
        }
    }
    Ok(Rounds {
        outcome,
        params: feet.params,
        errors: feet.errors,
        rms: rms_history,
        stages,
    })
}

/// The first round's start: the previous version's controls where it gave them, the plane
/// of the data (`InitialNet::Affine`) elsewhere.
pub(super) fn start_net(
    surface: &dyn PlanarSurface,
    params: &[SurfaceParam],
    data: &[DVec3],
    previous: Option<Vec<Option<DVec3>>>,
) -> InitialNet {
    let Some(start) = previous else {
        return InitialNet::Affine;
    };
    let plane_fill = if start.iter().any(Option::is_none) {
        initial_net(surface, params, data, &InitialNet::Affine)
    } else {
        Vec::new()
    };
    InitialNet::Given(
        start
            .into_iter()
            .enumerate()
            .map(|(k, c)| {
                c.or_else(|| plane_fill.get(k).copied())
                    .unwrap_or(DVec3::ZERO)
            })
            .collect(),
    )
}
