//! The rounds of a planar-domain fit: the first fit at the mapped parameters (the engine,
//! with the configured method and budget), then per round the foot points of the data on
//! the current surface and a refit there, while a round lowers the geometric RMS by at least
//! `fit.correction.min_gain`.
//!
//! The refit is squared-distance minimisation (`fit::distance`: point-to-plane with the
//! tangential share `fit.correction.tangential`), as on the scan path: point-to-point refits
//! at the foot points (`kind = "parameters"`) let the surface slide only as far as one
//! parameter correction moves the points, and on bun045 (DMS degree 2, 2004 controls) they
//! still gained 4 % per round after four rounds (181 -> 152 um).

use super::error::ScatteredError;
use crate::fit::distance::{solve_distance, solve_distance_direct, DistanceProblem};
use crate::fit::{Collocation, FitOutcome};
use crate::pipeline::scan::{Correction, CorrectionConfig};
use crate::pipeline::PipelineError;
use crate::scattered_fit::{
    collocation_matrix, fairness_operator, fit_scattered, foot_points, InitialNet, ScatteredOptions,
};
use crate::surface::dms::PlanarSurface;
use crate::surface::SurfaceParam;
use glam::DVec3;
use rayon::prelude::*;

/// Newton steps per foot point and round.
pub(super) const NEWTON_STEPS: usize = 6;

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
}

/// Foot points of `data` on the surface of `controls` (from `params`) and the distances.
fn feet_and_errors(
    surface: &dyn PlanarSurface,
    controls: &[DVec3],
    params: &[SurfaceParam],
    data: &[DVec3],
) -> (Vec<SurfaceParam>, Vec<f64>, f64) {
    let feet = foot_points(surface, controls, params, data, NEWTON_STEPS);
    let eval = surface.evaluator(controls);
    let errors: Vec<f64> = feet
        .par_iter()
        .zip(data.par_iter())
        .map(|(p, x)| (eval(*p).position - *x).length())
        .collect();
    let rms = (errors.iter().map(|e| e * e).sum::<f64>() / errors.len().max(1) as f64).sqrt();
    (feet, errors, rms)
}

/// One squared-distance round at the foot points `feet` of the surface of `controls`.
fn distance_round(
    surface: &dyn PlanarSurface,
    controls: &[DVec3],
    feet: &[SurfaceParam],
    data: &[DVec3],
    fairness: &Collocation,
    smoothing: f64,
    tangential: f64,
) -> Vec<DVec3> {
    let basis = collocation_matrix(surface, feet);
    let eval = surface.evaluator(controls);
    let normals: Vec<DVec3> = feet
        .par_iter()
        .map(|p| {
            let d = eval(*p);
            d.du.cross(d.dv).normalize_or_zero()
        })
        .collect();
    let tangential = vec![tangential; data.len()];
    let problem = DistanceProblem {
        basis: &basis,
        data,
        normals: &normals,
        tangential: &tangential,
        fairness: Some(fairness),
        smoothing,
    };
    solve_distance_direct(&problem).unwrap_or_else(|| {
        solve_distance(
            &problem,
            controls.to_vec(),
            ROUND_MAX_ITERATIONS,
            ROUND_REL_TOL,
        )
        .0
    })
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
    let fitted =
        fit_scattered(surface, &params, data, &options, None).map_err(ScatteredError::Fit)?;
    let mut outcome = fitted
        .rounds
        .into_iter()
        .last()
        .ok_or(ScatteredError::EmptyDomain)?;
    let (mut feet, mut errors, mut best) =
        feet_and_errors(surface, &outcome.controls, &params, data);
    let mut rms_history = vec![best];
    let fairness = Collocation::new(fairness_operator(surface));
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
            ),
            Correction::Parameters => {
                options.initial = InitialNet::Given(outcome.controls.clone());
                let refit = fit_scattered(surface, &feet, data, &options, None)
                    .map_err(ScatteredError::Fit)?;
                refit
                    .rounds
                    .into_iter()
                    .last()
                    .ok_or(ScatteredError::EmptyDomain)?
                    .controls
            }
        };
        let (next_feet, next_errors, rms) = feet_and_errors(surface, &controls, &feet, data);
        rms_history.push(rms);
        let gain = (best - rms) / best.max(f64::MIN_POSITIVE);
        if rms < best {
            (feet, errors, best) = (next_feet, next_errors, rms);
            outcome.controls = controls;
        }
        if gain < correction.min_gain {
            break;
        }
    }
    Ok(Rounds {
        outcome,
        params: feet,
        errors,
        rms: rms_history,
    })
}
