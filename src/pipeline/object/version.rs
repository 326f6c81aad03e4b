//! A new version of a fitted object (the daemon's warm start): which of its points changed
//! against the previous fit, the local refit around them (`local`), and local refinement
//! where the update leaves points beyond the tolerance.

use super::local::{
    free_controls, refit_around, refit_refined, LocalFeet, LocalFit, LocalOptions, RefinedRefit,
};
use super::model::{
    control_target, limit_surface, ms_since, LocalUpdate, ObjectError, ObjectFit, ObjectOptions,
    PreviousFit, RoundReport,
};
use super::refine::{refined_mesh, Fitted, RefineRound, Splits};
use super::solve::rms;
use crate::mesh::simplify::SurfaceTopology;
use crate::surface::loop_limit::LoopLimitSurface;
use crate::surface::{SurfaceParam, TriSurface};
use crate::TriMesh;
use glam::DVec3;
use rayon::prelude::*;
use std::time::Instant;

/// A new point has changed when its signed distance to the previous surface differs from
/// that of the previous data near it by more than this many times the previous fit's RMS:
/// a rescan's own noise moves a residual by about the RMS, a changed part by far more.
pub(super) const CHANGE_FACTOR: f64 = 3.0;

/// A control face has changed when its points' mean shift exceeds this many standard
/// errors of that mean: unchanged data (a rescan's noise) crosses it on about one face in
/// 16,000.
const FACE_SHIFT_ERRORS: f64 = 4.0;

/// Shifts under this share of the previous RMS are rounding (identical data): the spread
/// used for the faces' test is never taken smaller.
const ROUNDING_SHARE: f64 = 1e-3;

/// A change freeing more than this share of the controls goes to the whole fit: its
/// rounds cost about what the local ones would, and they also hold the rim and sample the
/// surface where no data point sees it.
pub(super) const MAX_FREE_SHARE: f64 = 0.5;

/// A new version of a fitted object refitted where it changed from `previous` (its
/// control mesh at the fitted positions, crease edges and RMS), `params` each point's
/// start on it (the previous foot of the previous data point nearest to it,
/// `reference`). Which points changed: `changed_points`.
/// Where the update leaves points beyond `opts.refine.tolerance`, their control faces are
/// split (up to the control budget) and refitted locally again. `None` when the change
/// frees more than `MAX_FREE_SHARE` of the controls, or the previous RMS is not known: the
/// whole fit then runs.
pub fn refit_where_changed(
    component: TriMesh,
    previous: PreviousFit,
    params: Vec<SurfaceParam>,
    reference: &[DVec3],
    opts: &ObjectOptions,
) -> Result<Option<ObjectFit>, ObjectError> {
    let PreviousFit {
        control_mesh,
        crease_edges,
        rms: previous_rms,
        surface: previous_surface,
    } = previous;
    let start = Instant::now();
    let n = component.positions.len();
    if params.len() != n || reference.len() != n {
        return Err(ObjectError::ParamCount {
            params: params.len().min(reference.len()),
            points: n,
        });
    }
    // Written so that a NaN RMS counts as unknown.
    if previous_rms.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
        return Ok(None);
    }
    let topologies = [
        SurfaceTopology::of(&component).map_err(ObjectError::NotManifold)?,
        SurfaceTopology::of(control_mesh).map_err(ObjectError::NotManifold)?,
    ];
    let surface = limit_surface(control_mesh, crease_edges, previous_surface)?;
    let surface_ms = ms_since(start);
    let controls = control_mesh.positions.clone();
    let data = &component.positions;
    let t = Instant::now();
    let start_params = params.clone();
    let mut feet = LocalFeet::at(params, vec![0.0; n]);
    let all: Vec<usize> = (0..n).collect();
    feet.find(&surface, &controls, data, &all);
    let changed = changed_points(
        &surface,
        &controls,
        [data, reference],
        &start_params,
        &feet,
        previous_rms,
    );
    let initial_errors = feet.errors.clone();
    let free = free_controls(&surface, &feet.params, &changed);
    if free.iter().filter(|&&f| f).count() as f64 > MAX_FREE_SHARE * controls.len() as f64 {
        return Ok(None);
    }
    let first_fit_ms = ms_since(t);
    let t = Instant::now();
    let first = refit_around(
        &surface,
        &controls,
        data,
        Some(&component),
        feet,
        changed.len(),
        &free,
        &LocalOptions::version_of(opts),
    );
    let mut state = Refitted::new(
        surface,
        control_mesh.clone(),
        first,
        free,
        opts.refine.tolerance,
    );
    let rounds_ms = ms_since(t);
    let t = Instant::now();
    state.refine_where_changed(
        &component,
        &changed,
        &initial_errors,
        CHANGE_FACTOR * previous_rms,
        opts,
    );
    let refine_ms = ms_since(t);
    let mut fit = state.into_fit(component, topologies);
    fit.times.surface_ms = surface_ms;
    fit.times.first_fit_ms = first_fit_ms;
    fit.times.rounds_ms = rounds_ms;
    fit.times.refine_ms = refine_ms;
    fit.times.total_ms = ms_since(start);
    Ok(Some(fit))
}

/// The points of a new version that changed. Each point's shift is its signed distance to
/// the previous surface less that of the previous data point nearest to it (`reference`,
/// whose foot is the point's start parameter in `start`). A point has
/// changed when its shift exceeds `CHANGE_FACTOR` previous RMS; so has every point of a
/// control face whose points' mean shift exceeds `FACE_SHIFT_ERRORS` standard errors of
/// such a mean (from the shifts' spread, a robust one: changed parts are a minority),
/// which finds a change too shallow for any one point, such as a part moved by less than
/// the noise.
pub(super) fn changed_points(
    surface: &LoopLimitSurface,
    controls: &[DVec3],
    [data, reference]: [&[DVec3]; 2],
    start: &[SurfaceParam],
    feet: &LocalFeet,
    previous_rms: f64,
) -> Vec<usize> {
    let n = data.len();
    let evaluate = surface.evaluator(controls);
    let shift: Vec<f64> = (0..n)
        .into_par_iter()
        .map(|i| {
            let old = evaluate(start[i]);
            let old_normal = old.du.cross(old.dv).normalize_or_zero();
            let foot = evaluate(feet.params[i]).position;
            (data[i] - foot).dot(feet.normals[i]) - (reference[i] - old.position).dot(old_normal)
        })
        .collect();
    let spread = robust_spread(&shift).max(ROUNDING_SHARE * previous_rms);
    let faces = surface.domain_face_count();
    let (mut sum, mut count) = (vec![0.0; faces], vec![0usize; faces]);
    for (p, s) in feet.params.iter().zip(&shift) {
        sum[p.face as usize] += s;
        count[p.face as usize] += 1;
    }
    let face_changed: Vec<bool> = sum
        .iter()
        .zip(&count)
        .map(|(&s, &k)| {
            k > 0 && (s / k as f64).abs() * (k as f64).sqrt() > FACE_SHIFT_ERRORS * spread
        })
        .collect();
    (0..n)
        .filter(|&i| {
            shift[i].abs() > CHANGE_FACTOR * previous_rms
                || face_changed[feet.params[i].face as usize]
        })
        .collect()
}

/// The standard deviation of `values` estimated from their median absolute deviation (of
/// the finite ones; 0 without any).
fn robust_spread(values: &[f64]) -> f64 {
    let median = |v: &mut Vec<f64>| {
        if v.is_empty() {
            return 0.0;
        }
        let k = v.len() / 2;
        v.select_nth_unstable_by(k, f64::total_cmp);
        v[k]
    };
    let mut v: Vec<f64> = values.iter().copied().filter(|x| x.is_finite()).collect();
    let centre = median(&mut v);
    let mut deviations: Vec<f64> = v.iter().map(|x| (x - centre).abs()).collect();
    // 1.4826: the MAD of a normal distribution in standard deviations.
    1.4826 * median(&mut deviations)
}

/// A local refit in progress: the surface, controls and feet so far, and what was touched.
pub(super) struct Refitted {
    surface: LoopLimitSurface,
    /// The control mesh the last refit started from.
    start_mesh: TriMesh,
    controls: Vec<DVec3>,
    params: Vec<SurfaceParam>,
    errors: Vec<f64>,
    /// Per control: solved again by some refit (new controls always are).
    moved: Vec<bool>,
    update: LocalUpdate,
    /// The moving points' RMS and max before and after each round of the first refit.
    rounds: Vec<RoundReport>,
    /// The first refit, then each refinement's.
    refinement: Vec<RefineRound>,
    tolerance: Option<f64>,
}

impl Refitted {
    pub(super) fn new(
        surface: LoopLimitSurface,
        start_mesh: TriMesh,
        first: LocalFit,
        free: Vec<bool>,
        tolerance: Option<f64>,
    ) -> Self {
        let mut state = Self {
            surface,
            start_mesh,
            controls: Vec::new(),
            params: Vec::new(),
            errors: Vec::new(),
            moved: free,
            update: LocalUpdate {
                changed_points: first.changed_points,
                ..LocalUpdate::default()
            },
            rounds: first
                .rounds
                .iter()
                .map(|&(rms, max)| RoundReport { rms, max })
                .collect(),
            refinement: Vec::new(),
            tolerance,
        };
        state.take(first);
        state
    }

    /// Takes over a refit's controls and feet.
    fn take(&mut self, fit: LocalFit) {
        self.update.moving_points += fit.moving_points;
        self.update.rounds += fit.rounds.len() - 1;
        self.controls = fit.controls;
        self.params = fit.params;
        self.errors = fit.errors;
        let max = self.errors.iter().fold(0.0, |m: f64, &e| m.max(e));
        self.refinement.push(RefineRound::of(
            self.controls.len(),
            rms(&self.errors),
            max,
            &self.errors,
            self.tolerance,
        ));
    }

    /// Refinement rounds where the update left points beyond the tolerance: changed points,
    /// and points the refits moved the surface away from by more than `change` (from their
    /// `initial` distance, on the previous surface; a smaller push is the noise of points
    /// near the tolerance, and splitting for it spreads the refit over the object). Their
    /// faces are split (`refine::refined_mesh` restricted to them), and the points over new
    /// faces and the controls around them refitted; a refit that does not lower the RMS is
    /// dropped.
    pub(super) fn refine_where_changed(
        &mut self,
        component: &TriMesh,
        changed: &[usize],
        initial: &[f64],
        change: f64,
        opts: &ObjectOptions,
    ) {
        let Some(tolerance) = opts.refine.tolerance else {
            return;
        };
        let cap = control_target(component.positions.len(), opts);
        let local_opts = LocalOptions::version_of(opts);
        let data = &component.positions;
        let mut is_changed = vec![false; data.len()];
        for &i in changed {
            is_changed[i] = true;
        }
        for _ in 0..opts.refine.rounds {
            if opts.stop.reached(&self.errors) {
                break;
            }
            let mut beyond = vec![false; self.surface.domain_face_count()];
            for (i, (&e, p)) in self.errors.iter().zip(&self.params).enumerate() {
                if e > tolerance && (is_changed[i] || e - initial[i] > change) {
                    beyond[p.face as usize] = true;
                }
            }
            let add = beyond
                .iter()
                .filter(|&&b| b)
                .count()
                .min(cap.saturating_sub(self.controls.len()));
            if add == 0 {
                break;
            }
            let fitted = Fitted {
                component,
                surface: &self.surface,
                controls: &self.controls,
                params: &self.params,
                distances: &self.errors,
            };
            let Some(refined) = refined_mesh(&fitted, add, &opts.layout, Splits::Marked(&beyond))
            else {
                break;
            };
            let Some(RefinedRefit {
                surface,
                free,
                fit: next,
            }) = refit_refined(
                &self.surface,
                &refined,
                component,
                &self.errors,
                false,
                &local_opts,
            )
            else {
                break;
            };
            let (after, before) = (rms(&next.errors), rms(&self.errors));
            if after.partial_cmp(&before) != Some(std::cmp::Ordering::Less) {
                break;
            }
            self.update.added_controls += refined.warm.len() - self.controls.len();
            self.moved.resize(free.len(), true);
            for (moved, free) in self.moved.iter_mut().zip(&free) {
                *moved |= free;
            }
            self.start_mesh = TriMesh::new(refined.warm, surface.faces().to_vec());
            self.surface = surface;
            self.take(next);
        }
    }

    pub(super) fn into_fit(
        self,
        component: TriMesh,
        [data_topology, control_topology]: [SurfaceTopology; 2],
    ) -> ObjectFit {
        let mut update = self.update;
        update.free_controls = self.moved.iter().filter(|&&m| m).count();
        ObjectFit {
            data: component.positions.clone(),
            component,
            simplified: self.start_mesh,
            surface: self.surface,
            rms: rms(&self.errors),
            max: self.errors.iter().fold(0.0, |m, &e| m.max(e)),
            controls: self.controls,
            params: self.params,
            distances: self.errors,
            rounds: self.rounds,
            data_topology,
            control_topology,
            times: Default::default(),
            layout: Default::default(),
            refinement: self.refinement,
            sampled_faces: 0,
            local: Some(update),
            stray: None,
            cleaning: None,
            stray_budgets: Vec::new(),
            faceted: None,
        }
    }
}
