//! Local refits of an object's control mesh when a scan changes ground the control mesh
//! already covers (a new version of a scan, a corrected registration): the session's side
//! of `pipeline::object`'s local refit.
//!
//! The data points are the merge's vertices, one per grid cell, so the previous fit's
//! points are matched to the new merge by cell: a kept cell keeps its point's foot point
//! as the start, a cell that appeared starts from a neighbouring cell's foot point, a cell
//! that went loses its point. A point whose position changed or appeared is a changed
//! point of the refit.

use crate::fit::{Budget, FitOutcome, FitStatus, StepStats};
use crate::mesh::simplify::SurfaceTopology;
use crate::pipeline::merge::{CellKey, Merged};
use crate::pipeline::object::{
    free_controls, refit_around, LayoutReport, LocalFeet, LocalFit, LocalOptions, ObjectTimes,
    RoundReport,
};
use crate::pipeline::worker::{FittedPatch, ObjectInfo, WarmDecision};
use crate::pipeline::{PatchFit, SurfaceModel};
use crate::surface::loop_limit::LoopLimitSurface;
use crate::surface::SurfaceParam;
use glam::DVec3;
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

/// Refits the controls around the data that changed (see the module docs); `None` when no
/// point of the new merge lies on ground the previous fit covered. Returns the matched data
/// with the fit.
pub(super) fn refit(
    previous: &Previous,
    cells: &[CellKey],
    positions: &[DVec3],
    opts: &LocalOptions,
) -> Option<(Vec<DVec3>, LocalFit)> {
    let matched = match_data(previous, cells, positions);
    let n = matched.data.len();
    if n == 0 {
        return None;
    }
    let surface = previous.surface;
    let errors = matched
        .same_as
        .iter()
        .map(|k| k.map_or(0.0, |k| previous.errors[k]))
        .collect();
    let mut feet = LocalFeet::at(matched.params, errors);
    let changed: Vec<usize> = (0..n).filter(|&i| matched.same_as[i].is_none()).collect();
    feet.find(surface, previous.controls, &matched.data, &changed);
    let free = free_controls(surface, &feet.params, &changed);
    let fit = refit_around(
        surface,
        previous.controls,
        &matched.data,
        None,
        feet,
        changed.len(),
        &free,
        opts,
    );
    Some((matched.data, fit))
}

/// A local refit may fit its data at most this much worse (RMS) than the previous fit.
const MAX_LOCAL_RMS_RISE: f64 = 1.1;

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

    /// Why a local refit is not kept, if it is not (`fits_worse`).
    pub(super) fn fits_worse(&self, local: &LocalFit) -> Option<String> {
        fits_worse(self.fit.geometric_rms(), local.rounds.last().map(|r| r.0))
    }

    /// The refit's result in the form the worker's outputs read.
    pub(super) fn refitted(
        &self,
        (data, local): &(Vec<DVec3>, LocalFit),
        budget: Budget,
        fit_ms: f64,
    ) -> FittedPatch {
        let last = StepStats::from_distances(
            local.rounds.len() - 1,
            &local.errors,
            budget.tolerance,
            fit_ms,
        );
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
            data: data.clone(),
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
            local: None,
            stray: None,
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

/// Why a local refit whose last round left RMS `after` is not kept, if it is not: it fits
/// the new data over `MAX_LOCAL_RMS_RISE` times worse than the previous fit (RMS `before`)
/// fitted its own. An update over the same ground (a scan replaced, its
/// registration corrected) fits about as well from scratch, so a refit left well above it
/// did not follow the change (the bunny's bun045 moved 30 um, merged with a trial
/// weighting of the triangle fill that kept the topology: 40.8 um locally, 35.0 um from
/// scratch, 35.2 um before), and the whole fit runs.
fn fits_worse(before: f64, after: Option<f64>) -> Option<String> {
    let after = after.unwrap_or(f64::INFINITY);
    // Written so that a NaN refuses the refit.
    let as_well = after <= MAX_LOCAL_RMS_RISE * before;
    (!as_well).then(|| {
        format!(
            "the local refit fits the data with RMS {after:.3e}, over {MAX_LOCAL_RMS_RISE} \
             times the previous fit's {before:.3e}"
        )
    })
}

#[cfg(test)]
mod tests {
    use super::fits_worse;

    #[test]
    fn a_local_refit_fitting_clearly_worse_than_before_is_not_kept() {
        let before = 3.5355339e-5;
        assert_eq!(fits_worse(before, Some(3.6e-5)), None);
        assert_eq!(fits_worse(before, Some(2e-5)), None);
        let why = fits_worse(before, Some(4.1e-5)).expect("refused");
        assert!(
            why.contains("4.100e-5") && why.contains("3.536e-5"),
            "{why}"
        );
        assert!(fits_worse(before, Some(f64::NAN)).is_some());
        assert!(fits_worse(before, None).is_some());
    }
}
