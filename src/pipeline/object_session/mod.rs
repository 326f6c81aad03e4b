//! One object scanned view by view: registered scans are added, replaced and removed, and
//! after each change the object has one surface fitted to the merge of all its scans.
//!
//! State: the scans (id, transform, samples in the object frame), the merge grid's cell
//! size (`object_cell`: from the set of scans, not their order, so that cells mean the
//! same place in every update while no coarser scan arrives), the
//! last merged mesh (to say which region changed) and the worker's warm start. Each update
//! merges every scan (`pipeline::merge`) and hands the merged mesh to the worker. The path:
//! while the views look from about one direction (their samples' mean normals within
//! `VIEW_SPREAD_DEG`), the worker's `auto` dispatch chooses (a grid over the planar map for
//! disk-like data, the control mesh once it closes); views from further apart wrap around
//! the object, and a union that wraps around folds on every plane even while it is a disk,
//! so the control mesh takes it. When the merged data covers the same ground as before
//! (`WARM_MAX_COVERAGE_CHANGE`; no handle made or lost, no hole opened), the session
//! refits the previous control mesh locally itself (`local`), and keeps that refit only
//! when it fits and stays on the data as well as the previous fit. Otherwise the previous
//! fit goes to the worker as its warm start: the worker extends the previous control mesh
//! over new ground that joins its rim
//! (`object::extend_over_new_ground`: the previous faces kept, the new region simplified
//! and stitched on, only the controls there and around the seam solved), and fits from
//! scratch when the new ground cannot be joined. So the surface of a set of scans may
//! depend on the order they arrived in, within what the fits' own spread allows.

mod local;
mod views;

pub use crate::pipeline::measure::{
    distance_stats, surface_mesh, surface_points_at_data, DistanceStats, MeshMeasure,
};

use crate::mesh::rigid::RigidTransform;
use crate::pipeline::merge::{MergeChange, MergeField, MergeOptions, Merged, ScanSamples};
use crate::pipeline::object::{refine_where_far, LocalOptions};
use crate::pipeline::object::{ObjectOptions, RoundStop};
use crate::pipeline::worker::{
    fit_patch, outputs_of, Domain, FittedPatch, PatchOutputs, WarmStart, WorkerConfig,
};
use crate::pipeline::{PatchFit, PipelineError};
use crate::remesh::points::PointCloudError;
use crate::TriMesh;
use local::{LastFit, LocalData, Previous, SESSION_ANCHOR};
use serde_json::json;
use std::collections::BTreeMap;
use std::time::Instant;
use views::view_spread_deg;
pub use views::SessionScan;

/// Merged vertices that move less than this share of a cell count as unchanged.
const UNCHANGED_SHARE_OF_CELL: f64 = 1e-3;

/// Views whose directions lie further apart than this (degrees) wrap around the object.
/// A range scan sees the surface facing it, at most about 70 degrees off its axis; two
/// such views 30 degrees apart already hold surface turned 100 degrees from the axis of
/// the other, which no plane projection of the union keeps unfolded.
const VIEW_SPREAD_DEG: f64 = 30.0;

/// A local refit kept (with its summary), or why not (`None`: no reason worth reporting,
/// the whole fit runs as for an update that never tried one).
type LocalOutcome = Result<(FittedPatch, Option<LocalRefit>), Option<String>>;

/// The previous surface is the start of the next fit only when at most this share of the
/// merged cells appeared or went (a new version of a scan over the same ground).
const WARM_MAX_COVERAGE_CHANGE: f64 = 0.05;

/// How a session merges and fits.
#[derive(Clone, Debug, Default)]
pub struct SessionOptions {
    /// The merge of the scans.
    pub merge: MergeOptions,
    /// The worker's configuration (the fit of the merged data).
    pub worker: WorkerConfig,
    /// Measure every scan's distance to the new surface after each update (costs a
    /// tessellation and a point-to-mesh query per scan point).
    pub measure_scans: bool,
    /// Merge and fit every update from scratch (no local merge or refit): the reference
    /// the local updates are measured against.
    pub cold: bool,
}

/// Why an update failed (the session keeps its previous state).
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum SessionError {
    /// The scan has no triangle with area: nothing to merge.
    #[error("scan '{id}' has no usable triangles")]
    EmptyScan {
        /// The scan.
        id: String,
    },
    /// The scan is a point cloud that is no single view's height field (see
    /// `remesh::points`): its points cannot be triangulated for the merge.
    #[error("scan '{id}' is a point cloud that cannot be triangulated: {source}")]
    PointCloud {
        /// The scan.
        id: String,
        /// Why the triangulation refused it.
        #[source]
        source: PointCloudError,
    },
    /// The last scan was removed: there is no object left to fit.
    #[error("the object has no scans left")]
    NoScans,
    /// No scan of that id.
    #[error("no scan '{id}' in the object")]
    UnknownScan {
        /// The id asked for.
        id: String,
    },
    /// The fit of the merged data failed.
    #[error("fitting the merged scans failed")]
    Fit(#[source] PipelineError),
}

impl SessionError {
    /// A stable snake_case name of the variant.
    pub fn kind(&self) -> &'static str {
        match self {
            Self::EmptyScan { .. } => "empty_scan",
            Self::PointCloud { source, .. } => source.kind(),
            Self::NoScans => "no_scans",
            Self::UnknownScan { .. } => "unknown_scan",
            Self::Fit(e) => e.kind(),
        }
    }
}

/// What a local refit touched.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct LocalRefit {
    /// The controls solved again (indices into the surface's controls, sorted); every
    /// other control kept its position.
    pub controls: Vec<u32>,
    /// Merged points that moved or appeared.
    pub changed_points: usize,
    /// Points over the patches the refitted controls move (their feet found again).
    pub moving_points: usize,
    /// Squared-distance rounds taken.
    pub rounds: usize,
}

/// Stage times of one update, in milliseconds.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct UpdateTimes {
    /// The new scan's samples (normals, rim weights, transform).
    pub samples_ms: f64,
    /// Merging every scan into one mesh.
    pub merge_ms: f64,
    /// The worker's fit of the merged mesh.
    pub fit_ms: f64,
    /// surface.json, report.json and the GLB.
    pub outputs_ms: f64,
    /// Measuring the scans against the surface (when asked).
    pub measure_ms: f64,
    /// The whole update.
    pub total_ms: f64,
}

/// A scan's distance to the object's surface.
#[derive(Clone, Debug, serde::Serialize)]
pub struct ScanDistance {
    /// The scan.
    pub id: String,
    /// Its distances' statistics.
    #[serde(flatten)]
    pub stats: DistanceStats,
}

/// What one update produced.
pub struct SessionUpdate {
    /// The object's outputs (report.json carries a `session` key with what is below).
    pub outputs: PatchOutputs,
    /// The fit (the merged data, the surface, the controls).
    pub fit: PatchFit,
    /// `"object"` (control mesh) or `"scan"` (grid over a planar map).
    pub path: &'static str,
    /// Merged vertices and triangles fitted.
    pub merged_vertices: usize,
    /// Triangles of the merged mesh.
    pub merged_triangles: usize,
    /// Where the merged data changed since the previous update.
    pub change: MergeChange,
    /// Merge cells whose vertex was computed again (all of them in a merge from scratch).
    pub recomputed_cells: usize,
    /// The local refit, when the update took one.
    pub local: Option<LocalRefit>,
    /// Why the update fitted from scratch (`None` after a local refit).
    pub cold_because: Option<String>,
    /// Stage times.
    pub times: UpdateTimes,
    /// Every scan's distance to the surface (empty unless `measure_scans`).
    pub scans: Vec<ScanDistance>,
}

/// An object and its scans (see the module docs).
pub struct ObjectSession {
    opts: SessionOptions,
    cell: Option<f64>,
    scans: BTreeMap<String, SessionScan>,
    merged: Option<Merged>,
    warm: Option<WarmStart>,
    /// The merge's grid state, for the next update's local merge.
    field: Option<MergeField>,
    /// The last update's object fit, for the next local refit.
    last: Option<LastFit>,
}

impl ObjectSession {
    /// An object with no scans yet.
    pub fn new(opts: SessionOptions) -> Self {
        Self {
            opts,
            cell: None,
            scans: BTreeMap::new(),
            merged: None,
            warm: None,
            field: None,
            last: None,
        }
    }

    /// The scans, by id.
    pub fn scans(&self) -> &BTreeMap<String, SessionScan> {
        &self.scans
    }

    /// The merge grid's cell size of the last update.
    pub fn cell(&self) -> Option<f64> {
        self.cell
    }

    /// Adds the scan `id` (its mesh in its own frame, and its transform into the object's),
    /// or replaces the scan of that id, and refits.
    pub fn add_scan(
        &mut self,
        id: &str,
        mesh: &TriMesh,
        transform: RigidTransform,
    ) -> Result<SessionUpdate, SessionError> {
        self.add_scans(&[(id, mesh, transform)])
    }

    /// Adds (or replaces) several scans at once and refits once: what a restarted daemon
    /// does with the scans of an object folder. On an error nothing changes.
    pub fn add_scans(
        &mut self,
        scans: &[(&str, &TriMesh, RigidTransform)],
    ) -> Result<SessionUpdate, SessionError> {
        self.change_scans(scans, &[])
    }

    /// The merge grid's cell size for the scans held now (see `object_cell`).
    fn current_cell(&self) -> Option<f64> {
        object_cell(self.scans.values().map(|s| s.spacing), &self.opts.merge)
    }

    /// Removes the scan `id` and refits the rest.
    pub fn remove_scan(&mut self, id: &str) -> Result<SessionUpdate, SessionError> {
        self.change_scans(&[], &[id])
    }

    /// Adds (or replaces) the scans `added`, removes the scans `removed`, and refits once,
    /// merging again only around them (a scan renamed, the same samples under a new id,
    /// changes nothing there): one update for any change of an object folder (a scan
    /// renamed, two deleted, a new one beside a deleted one). With both empty the
    /// surface is refitted where nothing changed: the previous fit comes out again, at the
    /// cost of the outputs (what a daemon does when only a rejected scan came or went).
    /// On an error nothing changes, except that removing the last scan empties the session.
    pub fn change_scans(
        &mut self,
        added: &[(&str, &TriMesh, RigidTransform)],
        removed: &[&str],
    ) -> Result<SessionUpdate, SessionError> {
        let start = Instant::now();
        if !removed.is_empty() && self.scans.is_empty() {
            return Err(SessionError::NoScans);
        }
        if let Some(id) = removed.iter().find(|id| !self.scans.contains_key(**id)) {
            return Err(SessionError::UnknownScan { id: (*id).into() });
        }
        // Meshes first: a point cloud takes its side from the scans it overlaps.
        let mut order: Vec<_> = added.iter().collect();
        order.sort_by_key(|(_, mesh, _)| mesh.triangles.is_empty());
        let mut staged: Vec<(String, SessionScan)> = Vec::with_capacity(added.len());
        for &&(id, mesh, transform) in &order {
            let others: Vec<&ScanSamples> = (self.scans.values().map(|s| &s.samples))
                .chain(staged.iter().map(|(_, s)| &s.samples))
                .collect();
            let scan = SessionScan::of(mesh, transform, &self.opts.merge, &others).map_err(
                |e| match e {
                    None => SessionError::EmptyScan { id: id.into() },
                    Some(source) => SessionError::PointCloud {
                        id: id.into(),
                        source,
                    },
                },
            )?;
            staged.push((id.to_string(), scan));
        }
        let samples_ms = ms_since(start);
        // Each changed id and the scan it held before (`None`: a new id).
        let mut previous = Vec::new();
        for &id in removed {
            previous.push((id.to_string(), self.scans.remove(id)));
        }
        for (id, scan) in staged {
            previous.push((id.clone(), self.scans.insert(id, scan)));
        }
        if self.scans.is_empty() {
            *self = Self::new(self.opts.clone());
            return Err(SessionError::NoScans);
        }
        let mut added_ids: Vec<&str> = added.iter().map(|&(id, _, _)| id).collect();
        let mut gone: Vec<&ScanSamples> = previous
            .iter()
            .filter_map(|(_, p)| p.as_ref().map(|p| &p.samples))
            .collect();
        // A scan renamed (the samples of a removed one under a new id) changes no cell.
        added_ids.retain(|id| {
            let samples = self.scans.get(*id).map(|s| &s.samples);
            match gone.iter().position(|g| Some(*g) == samples) {
                Some(k) => {
                    gone.swap_remove(k);
                    false
                }
                None => true,
            }
        });
        let result = self.update(start, samples_ms, &added_ids, &gone);
        result.inspect_err(|_| {
            for (id, p) in previous.into_iter().rev() {
                match p {
                    Some(p) => self.scans.insert(id, p),
                    None => self.scans.remove(&id),
                };
            }
        })
    }

    /// Merges the scans (locally around `added` and `removed` when the grid is kept),
    /// refits locally or fits from scratch, and measures.
    fn update(
        &mut self,
        start: Instant,
        samples_ms: f64,
        added: &[&str],
        removed: &[&ScanSamples],
    ) -> Result<SessionUpdate, SessionError> {
        let cell = self.current_cell().ok_or(SessionError::NoScans)?;
        let mut times = UpdateTimes {
            samples_ms,
            ..Default::default()
        };
        let t = Instant::now();
        let all: Vec<&ScanSamples> = self.scans.values().map(|s| &s.samples).collect();
        // Taken out: after a failed fit the next update merges from scratch.
        let merged = match self
            .field
            .take()
            .filter(|f| !self.opts.cold && f.cell() == cell)
        {
            Some(mut field) => {
                let new: Vec<&ScanSamples> = added
                    .iter()
                    .filter_map(|id| self.scans.get(*id).map(|s| &s.samples))
                    .collect();
                let merged = field.update(&all, &new, removed, &self.opts.merge);
                self.field = Some(field);
                merged
            }
            None => {
                let mut field = MergeField::new(cell);
                let merged = field.update(&all, &all, &[], &self.opts.merge);
                self.field = (!self.opts.cold).then_some(field);
                merged
            }
        };
        times.merge_ms = ms_since(t);
        let empty = Merged::default();
        // Cells of another size name other places: everything counts as new.
        let before = self.merged.as_ref().filter(|m| m.cell == cell);
        let change = MergeChange::between(
            before.unwrap_or(&empty),
            &merged,
            UNCHANGED_SHARE_OF_CELL * cell,
        );
        let coverage_change =
            (change.added + change.removed) as f64 / merged.mesh.positions.len().max(1) as f64;
        let spread = view_spread_deg(self.scans.values());
        let mut worker = self.opts.worker.clone();
        let coarsest = self.scans.values().map(|s| s.spacing).fold(0.0, f64::max);
        worker.fit.scan.target_controls_pct =
            object_controls_pct(worker.fit.scan.target_controls_pct, cell, coarsest);
        // No fit of the merged views again at a larger budget where it strays: an update
        // is refitted from the previous one when the next view comes, and on the generated
        // sphere session the larger control meshes of the middle views left the last
        // surface 1.52e-4 off the sphere against 0.97e-4
        // (`two_arrival_orders_end_at_the_same_surface`), besides doubling their time.
        worker.fit.scan.stray_budget_steps = 0;
        let wraps = worker.fit.domain == Domain::Auto && spread > VIEW_SPREAD_DEG;
        if wraps {
            worker.fit.domain = Domain::Mesh;
        }
        let t = Instant::now();
        // The merge's cleaned largest part, built once: a local refit fits it, and the
        // next update's topology test reads its holes (`LastFit`).
        let data = (!self.opts.cold).then(|| LocalData::of(&merged)).flatten();
        let mut cold_because = self.why_cold(before.is_some(), coverage_change);
        let tried = match cold_because {
            None => self.refit_locally(&merged, data.as_ref(), &worker)?,
            Some(_) => Err(None),
        };
        let (fitted, local) = match tried {
            Ok(kept) => kept,
            Err(why) => {
                cold_because = cold_because.or(why);
                (self.fit_cold(&merged, &mut worker)?, None)
            }
        };
        times.fit_ms = ms_since(t);
        let path = fitted.path();
        self.last = if self.opts.cold {
            None
        } else {
            // No manifold part: no holes known, so that any hole next rules a refit out.
            LastFit::of(&fitted, &merged, data.map_or(0, |d| d.holes))
        };
        let fit = fitted.fit.clone();
        let t = Instant::now();
        let mut outputs = outputs_of(fitted, &worker, t);
        // The session keeps its own last fit, on a surface built afresh (`LastFit::of`):
        // the fitted one, with every quadtree node its fit and tessellation reached, would
        // stay in memory with the warm start.
        outputs.warm.drop_surfaces();
        times.outputs_ms = ms_since(t);
        let t = Instant::now();
        let scans = self.measure(&fit);
        times.measure_ms = ms_since(t);
        times.total_ms = ms_since(start);
        let mut region = serde_json::to_value(&change).unwrap_or_default();
        region["recomputed_cells"] = json!(merged.recomputed_cells);
        region["corners_evaluated"] = json!(merged.corners_evaluated);
        region["fit"] = json!(if local.is_some() { "local" } else { "whole" });
        region["cold_because"] = json!(cold_because);
        region["local_refit"] = json!(local);
        outputs.report["session"] = json!({
            "scans": self.scans.iter().map(|(id, s)| json!({
                "id": id,
                "vertices": s.vertices,
                "samples": s.samples.points.len(),
                "transform": s.transform.to_row_major(),
            })).collect::<Vec<_>>(),
            "merge": {
                "cell": cell,
                "vertices": merged.mesh.positions.len(),
                "triangles": merged.mesh.triangles.len(),
                "corners_evaluated": merged.corners_evaluated,
                "recomputed_cells": merged.recomputed_cells,
                "dropped_vertices": merged.dropped_vertices,
                "closed_holes": merged.closed_holes,
            },
            "path": path,
            "view_spread_deg": spread,
            "views_wrap_around": wraps,
            "warm_offered": !self.opts.cold,
            "coverage_change": coverage_change,
            "updated_region": region,
            "scan_distances": scans,
            "stages": times,
        });
        self.warm = Some(outputs.warm.clone());
        let update = SessionUpdate {
            outputs,
            fit,
            path,
            merged_vertices: merged.mesh.positions.len(),
            merged_triangles: merged.mesh.triangles.len(),
            change,
            recomputed_cells: merged.recomputed_cells,
            local,
            cold_because,
            times,
            scans,
        };
        self.merged = Some(merged);
        self.cell = Some(cell);
        Ok(update)
    }

    /// Why this update cannot refit the previous control mesh locally (`None`: it can).
    /// The topology and the result are judged by the refit itself (`local`).
    fn why_cold(&self, same_grid: bool, coverage_change: f64) -> Option<String> {
        if self.opts.cold {
            return Some("cold updates asked for".into());
        }
        if self.last.is_none() {
            return Some("no previous object fit".into());
        }
        if !same_grid {
            return Some("the merge cell changed".into());
        }
        if coverage_change > WARM_MAX_COVERAGE_CHANGE {
            return Some(format!(
                "coverage changed: {:.1} % of the merged cells appeared or went",
                100.0 * coverage_change
            ));
        }
        None
    }

    /// The local refit of the previous control mesh of the merge's cleaned largest part.
    /// `Err(why)`: the refit is not kept, the whole fit runs.
    fn refit_locally(
        &self,
        merged: &Merged,
        data: Option<&LocalData>,
        worker: &WorkerConfig,
    ) -> Result<LocalOutcome, SessionError> {
        let t = Instant::now();
        let cold = || Ok(Err(None));
        // `why_cold` let only an object fit through: these fall back for safety alone.
        let Some(last) = self.last.as_ref() else {
            return cold();
        };
        let crate::pipeline::SurfaceModel::Mesh(surface) = &last.fit.model else {
            return cold();
        };
        let budget = worker.fit.budget.resolve(&merged.mesh);
        // As the worker's object fit: no round once the budget holds or its time is up.
        let opts = LocalOptions {
            rounds: worker.fit.correction.rounds.max(1),
            curvature_floor: worker.fit.correction.curvature_floor(),
            smoothing: worker.fit.scan.smoothing,
            stop: RoundStop::of_budget(&budget, t),
            hold_rim: true,
            anchor: SESSION_ANCHOR,
            ..LocalOptions::version_of(&ObjectOptions::default())
        };
        let previous = Previous {
            surface,
            controls: &last.fit.controls,
            data: &last.fit.data,
            params: &last.fit.params,
            errors: &last.fit.geometric_errors,
            cells: &last.cells,
            topology: &last.data_topology,
            holes: last.holes,
        };
        let Some(data) = data else {
            let why = "the merged data's largest part is not a manifold surface";
            return Ok(Err(Some(why.into())));
        };
        let (points, mut local_fit) = match local::refit(&previous, data, &opts) {
            Ok(fitted) => fitted,
            Err(why) => return Ok(Err(Some(why))),
        };
        let mut refined = None;
        if let Some(why) = last.refusal(surface, &local_fit, &data.mesh) {
            // Points left too far: the control mesh refined there once, then judged again.
            let limit = last.largest_error_limit(&data.mesh);
            let Some((refined_surface, refit)) =
                refine_where_far(surface, local_fit, &data.mesh, limit, &opts)
            else {
                return Ok(Err(Some(why)));
            };
            if let Some(again) = last.refusal(&refined_surface, &refit, &data.mesh) {
                return Ok(Err(Some(format!("{why}; refined there: {again}"))));
            }
            (local_fit, refined) = (refit, Some(refined_surface));
        }
        let fitted = (points, local_fit);
        let summary = LocalRefit {
            controls: fitted.1.free_controls.clone(),
            changed_points: fitted.1.changed_points,
            moving_points: fitted.1.moving_points,
            rounds: fitted.1.rounds.len() - 1,
        };
        Ok(Ok((
            last.refitted(&fitted, refined, data.topology, budget, ms_since(t)),
            Some(summary),
        )))
    }

    /// The worker's fit of the merged mesh, from the previous surface when the merged
    /// data covers the same ground.
    fn fit_cold(
        &self,
        merged: &Merged,
        worker: &mut WorkerConfig,
    ) -> Result<FittedPatch, SessionError> {
        // The worker extends the previous control mesh over new ground, refits it where
        // the data changed over the same ground, or fits from scratch.
        let warm = self.warm.as_ref().filter(|_| !self.opts.cold);
        match fit_patch(&merged.mesh, warm, worker) {
            Ok(f) => Ok(f),
            // Views that wrap around without closing can pass the worker's disk test and
            // still fold on any plane: the merged data is no disk, the control mesh takes it.
            Err(
                PipelineError::ScanFailed { .. }
                | PipelineError::MapFailed { .. }
                | PipelineError::NotDiskLike { .. },
            ) if worker.fit.domain == Domain::Auto => {
                worker.fit.domain = Domain::Mesh;
                fit_patch(&merged.mesh, warm, worker).map_err(SessionError::Fit)
            }
            Err(e) => Err(SessionError::Fit(e)),
        }
    }

    /// Every scan's distance to the surface, when asked.
    fn measure(&self, fit: &PatchFit) -> Vec<ScanDistance> {
        if !self.opts.measure_scans {
            return Vec::new();
        }
        let mesh = surface_mesh(fit);
        let surface = MeshMeasure::new(&mesh);
        self.scans
            .iter()
            .map(|(id, s)| ScanDistance {
                id: id.clone(),
                stats: surface.stats(&s.samples.points),
            })
            .collect()
    }
}

/// The merge grid's cell size of an object whose scans have these spacings (median edge
/// lengths): `opts.cell` when set, else `cell_edges` times the coarsest spacing, rounded
/// onto the nearest rung of the ladder 2^(k/8) (rounding up made the bunny's cell 9 %
/// coarser, its merge and control budget smaller, and each scan's median distance to the
/// surface 1.19-1.45x VRIP's instead of 1.03-1.27x). A function of the set of scans, never of their order (the
/// first scan used to decide, and two orders of the bunny's views ended 85 um apart). The
/// coarsest scan decides because a cell finer than a scan's spacing leaves holes where that
/// scan alone covers the object (the averaging radius no longer reaches a sample from every
/// corner); the ladder keeps the cell when a new version of a scan samples a little
/// differently. `None` without scans.
pub fn object_cell(spacings: impl Iterator<Item = f64>, opts: &MergeOptions) -> Option<f64> {
    if opts.cell > 0.0 {
        return Some(opts.cell);
    }
    let coarsest = spacings
        .filter(|s| s.is_finite() && *s > 0.0)
        .fold(None, |m: Option<f64>, s| Some(m.map_or(s, |m| m.max(s))))?;
    let raw = opts.cell_edges * coarsest;
    Some(2f64.powf((raw.log2() * 8.0).round() / 8.0))
}

/// The worker's control budget for the merged data. The budget is a share of the data
/// points, and a merged vertex stands for the (cell / spacing)^2 scan points of its cell
/// (2.25 at the default 1.5 edges): the share is scaled by that, so that an object gets
/// the control density a single scan of it would (on the bunny's five views: 4118
/// controls instead of 2957, the scans' median distance to the surface 0.75-1.00x their
/// distance to bun_zipper instead of 0.96-1.20x).
fn object_controls_pct(scan_pct: f64, cell: f64, spacing: f64) -> f64 {
    let points_per_vertex = if spacing > 0.0 && cell.is_finite() {
        (cell / spacing).powi(2).max(1.0)
    } else {
        1.0
    };
    (scan_pct * points_per_vertex).min(100.0)
}

fn ms_since(t: Instant) -> f64 {
    t.elapsed().as_secs_f64() * 1e3
}

#[cfg(test)]
mod tests {
    use super::{object_cell, MergeOptions};

    #[test]
    fn the_merge_cell_follows_the_coarsest_scan_on_a_ladder_whatever_the_order() {
        let opts = MergeOptions::default();
        // A coarsest spacing whose cell (1.5 spacings) sits on a rung.
        let coarsest = 2f64.powf(-78.0 / 8.0) / 1.5;
        let spacings = [coarsest, 0.9 * coarsest, 0.6 * coarsest];
        let a = object_cell(spacings.into_iter(), &opts).expect("cell");
        let b = object_cell(spacings.into_iter().rev(), &opts).expect("cell");
        assert_eq!(a, b);
        assert!((a.log2() * 8.0 + 78.0).abs() < 1e-9, "{a}");
        // A new version of the coarsest scan sampling 1 % coarser or finer keeps the cell,
        // and the cell stays within half a rung of 1.5 x the coarsest spacing.
        for f in [0.99, 1.01] {
            let c = object_cell([f * coarsest, 0.6 * coarsest].into_iter(), &opts);
            assert_eq!(c, Some(a));
        }
        let half_rung = 2f64.powf(1.0 / 16.0);
        for f in [0.93, 1.0, 1.07] {
            let raw = 1.5 * f * coarsest;
            let c = object_cell([f * coarsest].into_iter(), &opts).expect("cell");
            assert!(c <= raw * half_rung * 1.000001 && c >= raw / half_rung / 1.000001);
        }
        let fixed = MergeOptions {
            cell: 1e-3,
            ..MergeOptions::default()
        };
        assert_eq!(object_cell([7.8e-4].into_iter(), &fixed), Some(1e-3));
        assert_eq!(object_cell(std::iter::empty(), &opts), None);
    }
}
