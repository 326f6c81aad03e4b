//! Local refits of an object's control mesh: when a scan changes ground the control mesh
//! already covers (a new version of a scan, a corrected registration), only the controls
//! whose support meets changed data, and one ring around them, are solved again; every
//! other control stays where it is, and so does the surface over it.
//!
//! The data points are the merge's vertices, one per grid cell, so the previous fit's
//! points are matched to the new merge by cell: a kept cell keeps its point's foot point
//! as the start, a cell that appeared starts from a neighbouring cell's foot point, a cell
//! that went loses its point. Changed points find their feet on the previous surface; the
//! free controls are those their basis rows touch, plus their neighbours in the control
//! mesh; the points over faces whose patch depends on a free control (the only ones whose
//! surface moves) enter squared-distance rounds like the whole-object fit's (point-to-plane
//! with a small tangential share, the umbrella fairness), with the fixed controls' share of
//! every row moved to the right-hand side. Not done here: the whole-object fit's holding of
//! the data's rim on the surface's boundary curve, and its surface-to-data samples.

use crate::fit::distance::{solve_distance_direct, DistanceProblem};
use crate::fit::engine::umbrella_laplacian_with_creases;
use crate::fit::{Budget, Csr, FitOutcome, FitStatus, StepStats};
use crate::mesh::simplify::SurfaceTopology;
use crate::pipeline::geometric::foot_point;
use crate::pipeline::merge::{CellKey, Merged};
use crate::pipeline::object::{LayoutReport, ObjectTimes, RoundReport};
use crate::pipeline::worker::{FittedPatch, ObjectInfo, WarmDecision};
use crate::pipeline::{PatchFit, SurfaceModel};
use crate::surface::loop_limit::LoopLimitSurface;
use crate::surface::{Derivatives, SurfaceParam, TriSurface};
use glam::DVec3;
use rayon::prelude::*;
use rustc_hash::FxHashMap;

/// The previous fit a local refit starts from.
pub(super) struct Previous<'a> {
    pub surface: &'a LoopLimitSurface,
    pub controls: &'a [DVec3],
    pub data: &'a [DVec3],
    pub params: &'a [SurfaceParam],
    pub errors: &'a [f64],
    /// Each previous data point's merge cell.
    pub cells: &'a [CellKey],
}

/// How the refit solves.
pub(super) struct LocalOptions {
    /// Squared-distance rounds at most.
    pub rounds: usize,
    /// The rounds stop once one lowers the RMS of the moving points by less than this.
    pub min_gain: f64,
    /// Share of the point-to-point term beside the point-to-plane one.
    pub tangential: f64,
    /// Fairness weight relative to the data (as the whole-object fit's `smoothing`).
    pub smoothing: f64,
}

/// A refit's result: the new data, controls and feet, and what it touched.
pub(super) struct LocalFit {
    pub data: Vec<DVec3>,
    pub controls: Vec<DVec3>,
    pub params: Vec<SurfaceParam>,
    pub errors: Vec<f64>,
    /// The controls solved again (sorted).
    pub free_controls: Vec<u32>,
    /// Data points whose position changed or appeared.
    pub changed_points: usize,
    /// Data points whose surface may move (their feet were found again).
    pub moving_points: usize,
    /// RMS and largest distance of the moving points on the previous surface, then after
    /// each round taken.
    pub rounds: Vec<(f64, f64)>,
}

/// The new data matched to the previous fit by cell.
struct Matched {
    data: Vec<DVec3>,
    params: Vec<SurfaceParam>,
    /// The previous point each point was matched to, `None` for a changed one.
    same_as: Vec<Option<usize>>,
}

fn match_data(previous: &Previous, cells: &[CellKey], positions: &[DVec3]) -> Matched {
    let old: FxHashMap<CellKey, usize> = previous
        .cells
        .iter()
        .enumerate()
        .map(|(k, c)| (*c, k))
        .collect();
    let mut m = Matched {
        data: Vec::with_capacity(positions.len()),
        params: Vec::with_capacity(positions.len()),
        same_as: Vec::with_capacity(positions.len()),
    };
    for (c, p) in cells.iter().zip(positions) {
        let kept = old.get(c).copied();
        // A new cell with no previous neighbour lies off the ground the control mesh
        // covers (or on a part the previous fit's cleaning left out): it is left out.
        let Some(k) = kept.or_else(|| neighbours(*c).find_map(|n| old.get(&n).copied())) else {
            continue;
        };
        m.data.push(*p);
        m.params.push(previous.params[k]);
        m.same_as.push(kept.filter(|&k| previous.data[k] == *p));
    }
    m
}

/// The 26 cells around `c`.
fn neighbours(c: CellKey) -> impl Iterator<Item = CellKey> {
    (0..27)
        .filter(|&k| k != 13)
        .map(move |k| [c[0] + k % 3 - 1, c[1] + (k / 3) % 3 - 1, c[2] + k / 9 - 1])
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

/// The feet of `points` (indices into `data`) on the surface of `controls`, written into
/// `params`, `normals` and `errors`.
fn find_feet(
    surface: &LoopLimitSurface,
    controls: &[DVec3],
    data: &[DVec3],
    points: &[usize],
    feet: &mut Feet,
) {
    let evaluate = surface.evaluator(controls);
    let found: Vec<(SurfaceParam, DVec3, f64)> = points
        .par_iter()
        .with_min_len(256)
        .map(|&i| foot(surface, &*evaluate, data[i], feet.params[i]))
        .collect();
    for (&i, (param, normal, distance)) in points.iter().zip(found) {
        feet.params[i] = param;
        feet.normals[i] = normal;
        feet.errors[i] = distance;
    }
}

struct Feet {
    params: Vec<SurfaceParam>,
    normals: Vec<DVec3>,
    errors: Vec<f64>,
}

/// RMS and largest of the `points`' errors.
fn rms_of(errors: &[f64], points: &[usize]) -> (f64, f64) {
    let sum: f64 = points.iter().map(|&i| errors[i] * errors[i]).sum();
    let max = points.iter().fold(0.0f64, |m, &i| m.max(errors[i]));
    ((sum / points.len().max(1) as f64).sqrt(), max)
}

/// Refits the controls around the data that changed (see the module docs); `None` when no
/// point of the new merge lies on ground the previous fit covered.
pub(super) fn refit(
    previous: &Previous,
    cells: &[CellKey],
    positions: &[DVec3],
    opts: &LocalOptions,
) -> Option<LocalFit> {
    let matched = match_data(previous, cells, positions);
    let n = matched.data.len();
    if n == 0 {
        return None;
    }
    let surface = previous.surface;
    let m = surface.control_count();
    let data = &matched.data;
    let mut feet = Feet {
        params: matched.params.clone(),
        normals: vec![DVec3::ZERO; n],
        errors: matched
            .same_as
            .iter()
            .map(|k| k.map_or(0.0, |k| previous.errors[k]))
            .collect(),
    };
    let changed: Vec<usize> = (0..n).filter(|&i| matched.same_as[i].is_none()).collect();
    let mut controls = previous.controls.to_vec();
    find_feet(surface, &controls, data, &changed, &mut feet);

    let free = free_controls(surface, &feet.params, &changed);
    let moving_face = moving_faces(surface, &free);
    let moving: Vec<usize> = (0..n)
        .filter(|&i| moving_face[feet.params[i].face as usize])
        .collect();
    find_feet(surface, &controls, data, &moving, &mut feet);
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
        let mut trial = Feet {
            params: feet.params.clone(),
            normals: feet.normals.clone(),
            errors: feet.errors.clone(),
        };
        find_feet(surface, &next, data, &moving, &mut trial);
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
    Some(LocalFit {
        data: matched.data,
        controls,
        params: feet.params,
        errors: feet.errors,
        free_controls: free_ids,
        changed_points: changed.len(),
        moving_points: moving.len(),
        rounds,
    })
}

/// The controls the basis rows of the `changed` points touch, and their neighbours.
fn free_controls(
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
        feet: &Feet,
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

/// The previous update's object fit, kept for the next local refit.
pub(super) struct LastFit {
    pub fit: PatchFit,
    /// Each data point's merge cell.
    pub cells: Vec<CellKey>,
    pub data_topology: SurfaceTopology,
    pub control_topology: SurfaceTopology,
}

impl LastFit {
    /// The object fit of an update with its points' cells, read off the merge the fit's
    /// data came from; `None` for a fit of another model or a point not from the merge.
    pub(super) fn of(fitted: &FittedPatch, merged: &Merged) -> Option<LastFit> {
        let info = fitted.object.as_ref()?;
        if !matches!(fitted.fit.model, SurfaceModel::Mesh(_)) {
            return None;
        }
        let bits = |p: &DVec3| [p.x.to_bits(), p.y.to_bits(), p.z.to_bits()];
        let cell_at: FxHashMap<[u64; 3], CellKey> = merged
            .mesh
            .positions
            .iter()
            .zip(&merged.cells)
            .map(|(p, c)| (bits(p), *c))
            .collect();
        let cells = fitted
            .fit
            .data
            .iter()
            .map(|p| cell_at.get(&bits(p)).copied())
            .collect::<Option<Vec<CellKey>>>()?;
        Some(LastFit {
            fit: fitted.fit.clone(),
            cells,
            data_topology: info.data_topology,
            control_topology: info.control_topology,
        })
    }

    /// The refit's result in the form the worker's outputs read.
    pub(super) fn refitted(&self, local: &LocalFit, budget: Budget, fit_ms: f64) -> FittedPatch {
        let n = local.errors.len().max(1) as f64;
        let max = local.errors.iter().fold(0.0f64, |m, &e| m.max(e));
        let rms = (local.errors.iter().map(|e| e * e).sum::<f64>() / n).sqrt();
        let within = local
            .errors
            .iter()
            .filter(|&&e| e <= budget.tolerance)
            .count();
        let last = StepStats {
            k: local.rounds.len() - 1,
            max_error: max,
            mean_error: local.errors.iter().sum::<f64>() / n,
            rms_error: rms,
            within_tolerance_pct: 100.0 * within as f64 / n,
            elapsed_ms: fit_ms,
        };
        let status = if budget.met(&last) {
            FitStatus::Met
        } else {
            FitStatus::Stalled
        };
        let fit = PatchFit {
            outcome: FitOutcome {
                controls: local.controls.clone(),
                iterations: last.k,
                steps: vec![last],
                status,
            },
            controls: local.controls.clone(),
            data: local.data.clone(),
            params: local.params.clone(),
            geometric_errors: local.errors.clone(),
            warm_start: true,
            prepare_ms: 0.0,
            fit_ms,
            ..self.fit.clone()
        };
        let info = ObjectInfo {
            reason: "local refit of the previous control mesh".into(),
            warm: WarmDecision::Used,
            data_topology: self.data_topology,
            control_topology: self.control_topology,
            rounds: local
                .rounds
                .iter()
                .map(|&(rms, max)| RoundReport { rms, max })
                .collect(),
            times: ObjectTimes {
                rounds_ms: fit_ms,
                total_ms: fit_ms,
                ..Default::default()
            },
            layout: LayoutReport::default(),
            refinement: Vec::new(),
        };
        FittedPatch {
            fit,
            scan: None,
            budget,
            levels: 0,
            refinement: Vec::new(),
            object: Some(info),
            scattered: None,
            planar_shown: None,
        }
    }
}
