//! Stages 4 and 5 of a scan fit: the first fit (or a warm start that needs none) and the
//! foot-point correction rounds after it.

use super::edge_band::near_edges;
use super::feet::WarmFeet;
use super::solve::{assembled_fit, foot_points, rms, run_fit, DistanceRound, Feet, GridStencils};
use super::types::{Correction, Domain, ScanOptions};
use crate::fit::{Collocation, FitOutcome, FitStatus, Method, StepStats};
use crate::pipeline::{FitOptions, PipelineError, SurfaceModel};
use crate::remesh::FilledPatch;
use crate::surface::{SurfaceParam, TriSurface};
use crate::TriMesh;
use glam::{DVec2, DVec3};
use std::cell::OnceCell;
use std::time::Instant;

/// Width of the band along the data's edges where distance rounds keep the larger
/// tangential share, in control spacings. On chin with the default rounds (the test
/// `the_edge_band_lowers_the_rms_without_raising_the_maximum`): 71.9 um RMS with the band
/// against 75.9 um with the edge share everywhere, and a 0.74 mm largest error against
/// 1.45 mm with the interior share everywhere. Three rings of samples (about this width on
/// the Stanford scans) did as well; six rings (a whole spacing) ended chin 0.6 um higher.
const EDGE_BAND_SPACINGS: f64 = 0.5;

/// Share of the net a warm start must provide to skip the first fit: with nearly all
/// controls from a previous surface that covered this domain, its foot points are better
/// parameters than the projection.
const WARM_SKIP_MIN_SHARE: f64 = 0.9;

/// Cap on p/n (controls per data point) in the fresh-noise allowance of a warm start
/// (`warm_fit`): keeps sqrt((1 + p/n) / (1 - p/n)) finite on nets as dense as the data
/// (at most sqrt(3)).
const MAX_CONTROL_SHARE: f64 = 0.5;

/// What the solves of one scan fit share.
pub(super) struct Problem<'a> {
    pub(super) opts: &'a FitOptions<'a>,
    pub(super) scan: &'a ScanOptions,
    pub(super) model: &'a SurfaceModel,
    pub(super) data: &'a [DVec3],
    pub(super) fairness: &'a Collocation,
    /// The fairness weight, scaled to the data and control counts.
    pub(super) smoothing: f64,
}

impl Problem<'_> {
    fn surface(&self) -> &dyn TriSurface {
        self.model.as_surface()
    }
}

/// A grid fit's assembly plan, built on first use: a warm start the previous surface
/// already fits needs no solve.
pub(super) struct LazyStencils<'a> {
    model: &'a SurfaceModel,
    fairness: &'a Collocation,
    smoothing: f64,
    cell: OnceCell<Option<GridStencils<'a>>>,
}

impl<'a> LazyStencils<'a> {
    pub(super) fn new(problem: &Problem<'a>) -> Self {
        Self {
            model: problem.model,
            fairness: problem.fairness,
            smoothing: problem.smoothing,
            cell: OnceCell::new(),
        }
    }

    fn get(&self) -> Option<&GridStencils<'a>> {
        self.cell
            .get_or_init(|| match self.model {
                SurfaceModel::Grid(grid) => {
                    Some(GridStencils::new(grid, self.fairness, self.smoothing))
                }
                _ => None,
            })
            .as_ref()
    }
}

/// Where the data's edges are: the rims, in the plane of the map.
pub(super) struct EdgeBand<'a> {
    pub(super) part: &'a TriMesh,
    pub(super) patch: &'a FilledPatch,
    /// Plane positions of the data vertices.
    pub(super) plane: &'a [DVec2],
    pub(super) domain: &'a Domain,
}

impl EdgeBand<'_> {
    /// Per data point, the tangential share of the distance rounds: stiffer near the data's
    /// edges (outer rim and holes).
    fn shares(&self, scan: &ScanOptions) -> Vec<f64> {
        let rims: Vec<&[u32]> = std::iter::once(self.patch.outer.as_slice())
            .chain(self.patch.hole_loops.iter().map(|h| h.as_slice()))
            .collect();
        let radius = EDGE_BAND_SPACINGS * control_spacing(self.domain, scan.config.lattice);
        near_edges(self.part, self.plane, &rims, radius)
            .iter()
            .map(|&near| match near {
                true => scan.correction.tangential_edge,
                false => scan.correction.tangential,
            })
            .collect()
    }
}

/// The distance between neighbouring control points in the plane of the map.
fn control_spacing(domain: &Domain, degree: usize) -> f64 {
    match domain {
        Domain::Grid { spacing } => *spacing,
        Domain::Triangle { corners } => {
            let sides: f64 = (0..3)
                .map(|k| corners[k].distance(corners[(k + 1) % 3]))
                .sum();
            sides / 3.0 / degree.max(1) as f64
        }
    }
}

/// The first fit's result and what the rounds take from it.
pub(super) struct FirstFit {
    pub(super) outcome: FitOutcome,
    pub(super) feet: Feet,
    /// A warm start that already fits as well as the rounds could make it.
    pub(super) warm_fits_already: bool,
    /// The rounds' tangential shares, when computed beside the fit.
    pub(super) band: Option<Vec<f64>>,
}

/// The first fit from `start`; `params` end at the foot points on its surface.
pub(super) fn first_fit<'a>(
    problem: &Problem<'a>,
    stencils: &LazyStencils<'a>,
    band: &EdgeBand,
    start: Vec<DVec3>,
    reused: usize,
    previous_feet: Option<&WarmFeet>,
    params: &mut [SurfaceParam],
) -> Result<FirstFit, PipelineError> {
    let Problem {
        opts, scan, data, ..
    } = problem;
    let surface = problem.surface();
    // A warm start that covers the domain already sits near the fit: its foot points are
    // better parameters than the projection, so it goes straight to the correction rounds.
    let warm_enough = scan.correction.rounds > 0
        && scan.correction.kind == Correction::Distance
        && reused as f64 >= WARM_SKIP_MIN_SHARE * start.len() as f64;
    if warm_enough {
        return Ok(warm_fit(problem, start, previous_feet, params));
    }
    // The assembly plan and the first fit's rows are built side by side, and the
    // rounds' edge band beside the first fit: none of them needs another.
    let first_rows = match (problem.model, opts.method) {
        (SurfaceModel::Grid(grid), Method::Cg | Method::Direct) => {
            let (built, rows) =
                GridStencils::with_rows(grid, problem.fairness, problem.smoothing, params);
            let _ = stencils.cell.set(Some(built));
            rows
        }
        _ => None,
    };
    let plan = stencils.get();
    let (fairness, smoothing) = (problem.fairness, problem.smoothing);
    let (first, band) = rayon::join(
        || -> Result<_, PipelineError> {
            let outcome = match opts.method {
                Method::Cg | Method::Direct => assembled_fit(
                    surface, plan, params, data, fairness, smoothing, start, opts, first_rows,
                ),
                Method::Pia | Method::Lspia => {
                    run_fit(surface, params, data, fairness, smoothing, start, opts)?
                }
            };
            let feet = foot_points(surface, plan, &outcome.controls, data, params);
            Ok((outcome, feet))
        },
        || (scan.correction.rounds > 0).then(|| band.shares(scan)),
    );
    let (outcome, feet) = first?;
    Ok(FirstFit {
        outcome,
        feet,
        warm_fits_already: false,
        band,
    })
}

/// The warm start as the first fit: its controls unchanged, the parameters at their foot
/// points on the previous surface.
fn warm_fit(
    problem: &Problem,
    start: Vec<DVec3>,
    previous_feet: Option<&WarmFeet>,
    params: &mut [SurfaceParam],
) -> FirstFit {
    let Problem {
        opts, scan, data, ..
    } = problem;
    let feet = foot_points(problem.surface(), None, &start, data, params);
    let stats = StepStats::from_residuals(0, &feet.residuals, opts.budget.tolerance, 0.0);
    // The previous surface fits the new version within the rounds' minimum gain of the
    // error it ended at on its own data (a rescan of an unchanged surface): a round
    // would gain less than that, as a stalled fit's next round would. A least-squares
    // fit with p parameters sits below the noise on its own n points and above it on a
    // fresh draw: sigma^2 (1 - p/n) against sigma^2 (1 + p/n). So an unchanged surface
    // rescanned meets its old RMS times sqrt((1 + p/n) / (1 - p/n)) (p ~ one normal
    // offset per control); refitting to close that gap would only fit the new noise
    // (measured on bun000 with fresh 7 um noise: 62.5 -> 59.8 um in two rounds).
    let previous_rms = previous_feet.map_or(0.0, |f| f.rms);
    let share = (start.len() as f64 / data.len().max(1) as f64).min(MAX_CONTROL_SHARE);
    let fresh_noise = ((1.0 + share) / (1.0 - share)).sqrt();
    let warm_fits_already = previous_rms > 0.0
        && rms(&feet.distances()) <= (1.0 + scan.correction.min_gain) * fresh_noise * previous_rms;
    let outcome = FitOutcome {
        status: if opts.budget.met(&stats) {
            FitStatus::Met
        } else if warm_fits_already {
            FitStatus::Stalled
        } else {
            FitStatus::Capped
        },
        controls: start,
        steps: vec![stats],
        iterations: 0,
    };
    FirstFit {
        outcome,
        feet,
        warm_fits_already,
        band: None,
    }
}

/// The fit after the correction rounds.
pub(super) struct Corrected {
    pub(super) outcome: FitOutcome,
    /// Each data point's geometric error.
    pub(super) errors: Vec<f64>,
    /// Geometric RMS after the first fit and after each kept round.
    pub(super) correction_rms: Vec<f64>,
}

/// Rounds of correction: refit at the foot points, move the parameters to the new foot
/// points, until the budget holds, a round gains too little, or time is up. `started`: when
/// the fitting began (the budget's time cap counts from there).
pub(super) fn correct<'a>(
    problem: &Problem<'a>,
    stencils: &LazyStencils<'a>,
    band: &EdgeBand,
    first: FirstFit,
    params: &mut Vec<SurfaceParam>,
    started: Instant,
) -> Result<Corrected, PipelineError> {
    let Problem {
        opts, scan, data, ..
    } = problem;
    let surface = problem.surface();
    let FirstFit {
        mut outcome,
        mut feet,
        warm_fits_already,
        band: early_band,
    } = first;
    let mut steps = outcome.steps.clone();
    let mut errors = feet.distances();
    let mut correction_rms = vec![rms(&errors)];
    // Foot-point distances never exceed the distances at the parameters, so a budget met by
    // the first fit holds geometrically too: no correction needed.
    let rounds = if outcome.status == FitStatus::Met || warm_fits_already {
        0
    } else {
        scan.correction.rounds
    };
    let tangential: Vec<f64> = match rounds {
        0 => Vec::new(),
        _ => early_band.unwrap_or_else(|| band.shares(scan)),
    };
    let round = DistanceRound {
        surface,
        stencils: if rounds > 0 { stencils.get() } else { None },
        data,
        fairness: problem.fairness,
        smoothing: problem.smoothing,
        tangential: &tangential,
        max_iterations: opts.budget.max_iterations,
    };
    for _ in 0..rounds {
        let (controls, cg_steps) = match scan.correction.kind {
            Correction::Parameters => {
                let next = run_fit(
                    surface,
                    params,
                    data,
                    problem.fairness,
                    problem.smoothing,
                    outcome.controls.clone(),
                    opts,
                )?;
                let n = next.steps.len().saturating_sub(1);
                (next.controls, n)
            }
            Correction::Distance => round.solve(
                params,
                feet.rows.take(),
                &feet.normals,
                outcome.controls.clone(),
            ),
        };
        let mut trial = params.clone();
        let trial_feet = foot_points(surface, round.stencils, &controls, data, &mut trial);
        let e = trial_feet.distances();
        // A round that does not lower the geometric error is dropped.
        let (before, after) = (rms(&errors), rms(&e));
        if after >= before {
            break;
        }
        let k = steps.last().map_or(0, |s| s.k) + cg_steps.max(1);
        let stats = StepStats::from_residuals(
            k,
            &trial_feet.residuals,
            opts.budget.tolerance,
            started.elapsed().as_secs_f64() * 1e3,
        );
        let met = opts.budget.met(&stats);
        if let Some(hook) = opts.on_step {
            hook(&stats);
        }
        steps.push(stats);
        outcome.controls = controls;
        *params = trial;
        feet = trial_feet;
        errors = e;
        correction_rms.push(rms(&errors));
        if met {
            outcome.status = FitStatus::Met;
            break;
        }
        // The budget's time cap holds for the rounds as for the steps of a fit.
        let elapsed_ms = started.elapsed().as_secs_f64() * 1e3;
        if opts
            .budget
            .max_time_ms
            .is_some_and(|m| elapsed_ms >= m as f64)
        {
            outcome.status = FitStatus::Capped;
            break;
        }
        // Rounds converge: once one gains under `min_gain` the next would gain less (a warm
        // start from the previous version's surface usually stops here after one round).
        if after > (1.0 - scan.correction.min_gain) * before {
            outcome.status = FitStatus::Stalled;
            break;
        }
    }
    outcome.steps = steps;
    outcome.iterations = outcome.steps.len().saturating_sub(1);
    Ok(Corrected {
        outcome,
        errors,
        correction_rms,
    })
}
