//! Local refits of a fitted control mesh: when new data differ from the old only in places
//! (a new version of an object with a part changed, a scan replaced in an object session),
//! only the controls whose support meets changed data, and one ring around them, are
//! solved again; every other control stays where it is, and so does the surface over it.
//!
//! Changed points find their feet on the previous surface; the free controls are those
//! their basis rows touch, plus their neighbours in the control mesh; the points over faces
//! whose patch depends on a free control (the only ones whose surface moves) enter
//! squared-distance rounds like the whole-object fit's (point-to-plane with a small
//! tangential share, the umbrella fairness), with the fixed controls' share of every row
//! moved to the right-hand side. Not done here: the whole fit's holding of the data's rim
//! on the surface's boundary curve and its surface-to-data samples, which is why a change
//! over much of the control mesh goes to the whole fit instead.

use super::model::{
    control_target, limit_surface, ms_since, LocalUpdate, ObjectError, ObjectFit, ObjectOptions,
    RoundReport,
};
use super::refine::{refined_mesh, Fitted, RefineRound};
use super::solve::rms;
use crate::fit::distance::{solve_distance_direct, DistanceProblem};
use crate::fit::engine::umbrella_laplacian_with_creases;
use crate::fit::Csr;
use crate::mesh::simplify::SurfaceTopology;
use crate::pipeline::geometric::foot_point;
use crate::surface::loop_limit::LoopLimitSurface;
use crate::surface::{Derivatives, SurfaceParam, TriSurface};
use crate::TriMesh;
use glam::DVec3;
use rayon::prelude::*;
use rustc_hash::FxHashSet;
use std::time::Instant;

/// A new point has changed when its distance to the previous surface exceeds that of the
/// previous data near it by more than this many times the previous fit's RMS: a rescan's
/// own noise moves a residual by about the RMS, a changed part by far more.
const CHANGE_FACTOR: f64 = 3.0;

/// A change freeing more than this share of the controls goes to the whole fit: its
/// rounds cost about what the local ones would, and they also hold the rim and sample the
/// surface where no data point sees it.
const MAX_FREE_SHARE: f64 = 0.5;

/// How a local refit solves.
pub(crate) struct LocalOptions {
    /// Squared-distance rounds at most.
    pub rounds: usize,
    /// The rounds stop once one lowers the RMS of the moving points by less than this.
    pub min_gain: f64,
    /// Share of the point-to-point term beside the point-to-plane one.
    pub tangential: f64,
    /// Fairness weight relative to the data (as the whole-object fit's `smoothing`).
    pub smoothing: f64,
}

impl LocalOptions {
    /// The rounds, gain, tangential share and fairness of a whole-object fit.
    pub(crate) fn of(opts: &ObjectOptions) -> Self {
        Self {
            rounds: opts.rounds.max(1),
            min_gain: opts.min_gain,
            tangential: opts.tangential,
            smoothing: opts.smoothing,
        }
    }
}

/// Every data point's foot on a surface: parameter, unit normal and distance.
pub(crate) struct LocalFeet {
    pub params: Vec<SurfaceParam>,
    pub normals: Vec<DVec3>,
    pub errors: Vec<f64>,
}

impl LocalFeet {
    /// Feet at `params` with the distances `errors`, their normals not known yet (found
    /// again, with the feet, for every point a refit moves).
    pub(crate) fn at(params: Vec<SurfaceParam>, errors: Vec<f64>) -> Self {
        let normals = vec![DVec3::ZERO; params.len()];
        Self {
            params,
            normals,
            errors,
        }
    }

    /// Finds the feet of `points` (indices into `data`) on the surface of `controls`,
    /// starting from their present parameters.
    pub(crate) fn find(
        &mut self,
        surface: &LoopLimitSurface,
        controls: &[DVec3],
        data: &[DVec3],
        points: &[usize],
    ) {
        let evaluate = surface.evaluator(controls);
        let found: Vec<(SurfaceParam, DVec3, f64)> = points
            .par_iter()
            .with_min_len(256)
            .map(|&i| foot(surface, &*evaluate, data[i], self.params[i]))
            .collect();
        for (&i, (param, normal, distance)) in points.iter().zip(found) {
            self.params[i] = param;
            self.normals[i] = normal;
            self.errors[i] = distance;
        }
    }
}

/// A point's foot on the surface: parameter, unit normal and distance.
fn foot(
    surface: &LoopLimitSurface,
    evaluate: &(dyn Fn(SurfaceParam) -> Derivatives + Sync),
    point: DVec3,
    start: SurfaceParam,
) -> (SurfaceParam, DVec3, f64) {
    let (param, d) = foot_point(surface, evaluate, point, start);
    let r = d.position - point;
    let normal =
        d.du.cross(d.dv)
            .try_normalize()
            .unwrap_or_else(|| r.try_normalize().unwrap_or(DVec3::Z));
    (param, normal, r.length())
}

/// A local refit's result: the controls and feet, and what it touched.
pub(crate) struct LocalFit {
    pub controls: Vec<DVec3>,
    pub params: Vec<SurfaceParam>,
    pub errors: Vec<f64>,
    /// The controls solved again (sorted).
    pub free_controls: Vec<u32>,
    /// Data points that changed.
    pub changed_points: usize,
    /// Data points whose surface may move (their feet were found again).
    pub moving_points: usize,
    /// RMS and largest distance of the moving points on the previous surface, then after
    /// each round taken.
    pub rounds: Vec<(f64, f64)>,
}

/// RMS and largest of the `points`' errors.
fn rms_of(errors: &[f64], points: &[usize]) -> (f64, f64) {
    let sum: f64 = points.iter().map(|&i| errors[i] * errors[i]).sum();
    let max = points.iter().fold(0.0f64, |m, &i| m.max(errors[i]));
    ((sum / points.len().max(1) as f64).sqrt(), max)
}

/// Refits the controls `free` (see [`free_controls`]) of the surface of `controls` to
/// `data`, every other control kept; `feet` holds every point's foot on that surface
/// (those of the `changed` points found on it).
pub(crate) fn refit_around(
    surface: &LoopLimitSurface,
    controls: &[DVec3],
    data: &[DVec3],
    mut feet: LocalFeet,
    changed: usize,
    free: &[bool],
    opts: &LocalOptions,
) -> LocalFit {
    let n = data.len();
    let m = surface.control_count();
    let mut controls = controls.to_vec();
    let moving_face = moving_faces(surface, free);
    let moving: Vec<usize> = (0..n)
        .filter(|&i| moving_face[feet.params[i].face as usize])
        .collect();
    feet.find(surface, &controls, data, &moving);
    let mut rounds = vec![rms_of(&feet.errors, &moving)];

    let column: Vec<Option<u32>> = {
        let mut next = 0u32;
        free.iter()
            .map(|&f| {
                f.then(|| {
                    next += 1;
                    next - 1
                })
            })
            .collect()
    };
    let free_ids: Vec<u32> = (0..m as u32).filter(|&c| free[c as usize]).collect();
    let laplacian = umbrella_laplacian_with_creases(m, surface.faces(), surface.crease_edges());
    let system = System {
        surface,
        column: &column,
        free_count: free_ids.len(),
        laplacian: &laplacian,
        fairness_scale: (opts.smoothing * n as f64 / m.max(1) as f64).sqrt(),
        tangential: opts.tangential,
    };
    for _ in 0..opts.rounds {
        if free_ids.is_empty() {
            break;
        }
        let Some(solved) = system.solve(data, &moving, &feet, &controls) else {
            break;
        };
        let mut next = controls.clone();
        for (&c, x) in free_ids.iter().zip(solved) {
            next[c as usize] = x;
        }
        let mut trial = LocalFeet {
            params: feet.params.clone(),
            normals: feet.normals.clone(),
            errors: feet.errors.clone(),
        };
        trial.find(surface, &next, data, &moving);
        let before = rounds[rounds.len() - 1].0;
        let (after, max) = rms_of(&trial.errors, &moving);
        if after.is_nan() || after >= before {
            break;
        }
        controls = next;
        feet = trial;
        rounds.push((after, max));
        if before - after < opts.min_gain * before {
            break;
        }
    }
    LocalFit {
        controls,
        params: feet.params,
        errors: feet.errors,
        free_controls: free_ids,
        changed_points: changed,
        moving_points: moving.len(),
        rounds,
    }
}

/// The controls the basis rows of the `changed` points touch, and their neighbours.
pub(crate) fn free_controls(
    surface: &LoopLimitSurface,
    params: &[SurfaceParam],
    changed: &[usize],
) -> Vec<bool> {
    let m = surface.control_count();
    let mut touched = vec![false; m];
    let mut row = Vec::new();
    for &i in changed {
        surface.basis_row(params[i], &mut row);
        for &(c, w) in &row {
            if w != 0.0 {
                touched[c as usize] = true;
            }
        }
    }
    let mut free = touched.clone();
    for f in surface.faces() {
        if f.iter().any(|&v| touched[v as usize]) {
            for &v in f {
                free[v as usize] = true;
            }
        }
    }
    free
}

/// Per control face, whether its patch depends on a free control: a Loop patch depends on
/// its corners and their neighbours.
fn moving_faces(surface: &LoopLimitSurface, free: &[bool]) -> Vec<bool> {
    let mut near_free = free.to_vec();
    for f in surface.faces() {
        if f.iter().any(|&v| free[v as usize]) {
            for &v in f {
                near_free[v as usize] = true;
            }
        }
    }
    surface
        .faces()
        .iter()
        .map(|f| f.iter().any(|&v| near_free[v as usize]))
        .collect()
}

/// The squared-distance problem over the free controls.
struct System<'a> {
    surface: &'a LoopLimitSurface,
    /// Each control's column among the free ones.
    column: &'a [Option<u32>],
    free_count: usize,
    laplacian: &'a Csr,
    /// sqrt of the fairness weight: the umbrella rows are scaled by it.
    fairness_scale: f64,
    tangential: f64,
}

impl System<'_> {
    /// The free controls minimising the distance of the `moving` points at their feet and
    /// the fairness of the rows that hold a free control; `None` if the solve fails.
    fn solve(
        &self,
        data: &[DVec3],
        moving: &[usize],
        feet: &LocalFeet,
        controls: &[DVec3],
    ) -> Option<Vec<DVec3>> {
        let mut basis = Csr {
            nrows: 0,
            ncols: self.free_count,
            row_ptr: vec![0],
            ..Default::default()
        };
        let (mut targets, mut normals, mut tangential) = (vec![], vec![], vec![]);
        let push_row = |entries: &mut dyn Iterator<Item = (u32, f64)>,
                        target: DVec3,
                        scale: f64,
                        basis: &mut Csr| {
            let mut fixed = DVec3::ZERO;
            for (c, w) in entries {
                match self.column[c as usize] {
                    Some(col) => {
                        basis.col_idx.push(col);
                        basis.values.push(w * scale);
                    }
                    None => fixed += w * controls[c as usize],
                }
            }
            basis.row_ptr.push(basis.col_idx.len());
            basis.nrows += 1;
            (target - fixed) * scale
        };
        let mut row = Vec::new();
        for &i in moving {
            self.surface.basis_row(feet.params[i], &mut row);
            let mut entries = row.iter().copied().filter(|e| e.1 != 0.0);
            targets.push(push_row(&mut entries, data[i], 1.0, &mut basis));
            normals.push(feet.normals[i]);
            tangential.push(self.tangential);
        }
        // The umbrella rows holding a free control, once per axis: three point-to-plane
        // rows along x, y and z weigh |L P|^2 as the whole-object fit's fairness does.
        let l = self.laplacian;
        for r in 0..l.nrows {
            let span = l.row_ptr[r]..l.row_ptr[r + 1];
            if !l.col_idx[span.clone()]
                .iter()
                .any(|&c| self.column[c as usize].is_some())
            {
                continue;
            }
            for axis in [DVec3::X, DVec3::Y, DVec3::Z] {
                let mut entries = span.clone().map(|e| (l.col_idx[e], l.values[e]));
                targets.push(push_row(
                    &mut entries,
                    DVec3::ZERO,
                    self.fairness_scale,
                    &mut basis,
                ));
                normals.push(axis);
                tangential.push(0.0);
            }
        }
        let problem = DistanceProblem {
            basis: &basis,
            data: &targets,
            normals: &normals,
            tangential: &tangential,
            fairness: None,
            smoothing: 0.0,
        };
        let x = solve_distance_direct(&problem)?;
        (x.len() == self.free_count && x.iter().all(|p| p.is_finite())).then_some(x)
    }
}

/// A new version of a fitted object refitted where it changed: `control_mesh` is the
/// previous fit's (at its fitted positions) with `crease_edges`, `params` each point's
/// start on it (the previous foot of the previous data point nearest to it, `reference`)
/// and `previous_rms` the previous fit's RMS. A point has changed when its distance to the
/// previous surface exceeds the reference point's by more than `CHANGE_FACTOR` previous
/// RMS. Where changed points stay beyond `opts.refine.tolerance`, their control faces are
/// split (up to the control budget) and refitted locally again. `None` when the change
/// frees more than `MAX_FREE_SHARE` of the controls, or the previous RMS is not known: the
/// whole fit then runs.
pub fn refit_where_changed(
    component: TriMesh,
    control_mesh: TriMesh,
    crease_edges: &[[u32; 2]],
    params: Vec<SurfaceParam>,
    reference: &[DVec3],
    previous_rms: f64,
    opts: &ObjectOptions,
) -> Result<Option<ObjectFit>, ObjectError> {
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
        SurfaceTopology::of(&control_mesh).map_err(ObjectError::NotManifold)?,
    ];
    let surface = limit_surface(&control_mesh, crease_edges, None)?;
    let surface_ms = ms_since(start);
    let controls = control_mesh.positions.clone();
    let data = &component.positions;
    let t = Instant::now();
    let before: Vec<f64> = {
        let evaluate = surface.evaluator(&controls);
        params
            .par_iter()
            .zip(reference)
            .map(|(p, r)| evaluate(*p).position.distance(*r))
            .collect()
    };
    let mut feet = LocalFeet::at(params, vec![0.0; n]);
    let all: Vec<usize> = (0..n).collect();
    feet.find(&surface, &controls, data, &all);
    let changed: Vec<usize> = all
        .into_iter()
        .filter(|&i| feet.errors[i] - before[i] > CHANGE_FACTOR * previous_rms)
        .collect();
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
        feet,
        changed.len(),
        &free,
        &LocalOptions::of(opts),
    );
    let mut state = Refitted::new(surface, control_mesh, first, free, opts.refine.tolerance);
    let rounds_ms = ms_since(t);
    let t = Instant::now();
    state.refine_where_changed(&component, &changed, &initial_errors, opts);
    let refine_ms = ms_since(t);
    let mut fit = state.into_fit(component, topologies);
    fit.times.surface_ms = surface_ms;
    fit.times.first_fit_ms = first_fit_ms;
    fit.times.rounds_ms = rounds_ms;
    fit.times.refine_ms = refine_ms;
    fit.times.total_ms = ms_since(start);
    Ok(Some(fit))
}

/// A local refit in progress: the surface, controls and feet so far, and what was touched.
struct Refitted {
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
    fn new(
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

    /// Refinement rounds where the update left points beyond the tolerance (changed
    /// points, and points the refits moved the surface away from: farther from it than
    /// from the previous surface, their `initial` distance): their faces split
    /// (`refine::refined_mesh` restricted to them), the points over new faces and the
    /// controls around them refitted; a refit that does not lower the RMS is dropped.
    fn refine_where_changed(
        &mut self,
        component: &TriMesh,
        changed: &[usize],
        initial: &[f64],
        opts: &ObjectOptions,
    ) {
        let Some(tolerance) = opts.refine.tolerance else {
            return;
        };
        let cap = control_target(component.positions.len(), opts);
        let local_opts = LocalOptions::of(opts);
        let data = &component.positions;
        let mut is_changed = vec![false; data.len()];
        for &i in changed {
            is_changed[i] = true;
        }
        for _ in 0..opts.refine.rounds {
            let mut beyond = vec![false; self.surface.domain_face_count()];
            for (i, (&e, p)) in self.errors.iter().zip(&self.params).enumerate() {
                if e > tolerance && (is_changed[i] || e > initial[i]) {
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
            let Some(refined) = refined_mesh(&fitted, add, &opts.layout, Some(&beyond)) else {
                break;
            };
            let Ok(surface) = limit_surface(&refined.mesh, &refined.creases, Some(&self.surface))
            else {
                break;
            };
            let sorted = |f: &[u32; 3]| {
                let mut f = *f;
                f.sort_unstable();
                f
            };
            let old: FxHashSet<[u32; 3]> = self.surface.faces().iter().map(sorted).collect();
            let new_face: Vec<bool> = surface
                .faces()
                .iter()
                .map(|f| !old.contains(&sorted(f)))
                .collect();
            let touched: Vec<usize> = (0..data.len())
                .filter(|&i| new_face[refined.params[i].face as usize])
                .collect();
            let mut feet = LocalFeet::at(refined.params, self.errors.clone());
            feet.find(&surface, &refined.warm, data, &touched);
            let free = free_controls(&surface, &feet.params, &touched);
            let next = refit_around(
                &surface,
                &refined.warm,
                data,
                feet,
                touched.len(),
                &free,
                &local_opts,
            );
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

    fn into_fit(
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
        }
    }
}
