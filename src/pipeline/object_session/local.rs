//! Local refits of an object's control mesh when a scan changes ground the control mesh
//! already covers (a new version of a scan, a corrected registration): the session's side
//! of `pipeline::object`'s local refit.
//!
//! The data points are the vertices of the merge's cleaned largest part (`LocalData`), one
//! per grid cell, so the previous fit's points are matched to the new merge by cell: a
//! kept cell keeps its point's foot point as the start, a cell that appeared starts from a
//! neighbouring cell's foot point, a cell that went loses its point. A point whose
//! position changed or appeared is a changed point of the refit.
//!
//! A local refit keeps the control mesh, so it is judged before it is kept: the data's
//! topology (no handle made or lost, no hole of `HOLE_EDGES` edges or more opened), every
//! point on the previous fit's ground, and the result (RMS, largest error and stray from
//! the data against the previous fit); otherwise the whole fit runs.

use crate::fit::{Budget, FitOutcome, FitStatus, StepStats};
use crate::mesh::clean::CleanOptions;
use crate::mesh::simplify::SurfaceTopology;
use crate::mesh::topology::Topology;
use crate::pipeline::merge::{CellKey, Merged};
use crate::pipeline::object::{
    fitted_component, free_controls, refit_around, LayoutReport, LocalFeet, LocalFit, LocalOptions,
    ObjectTimes, RoundReport,
};
use crate::pipeline::worker::{
    stray_refusal, FittedPatch, ObjectInfo, WarmDecision, MAX_STRAY_GROWTH, MAX_STRAY_SHARE,
};
use crate::pipeline::{PatchFit, SurfaceModel};
use crate::remesh::boundary_loops;
use crate::surface::loop_limit::LoopLimitSurface;
use crate::surface::{SurfaceParam, TriSurface};
use crate::TriMesh;
use glam::DVec3;
use rustc_hash::FxHashMap;
use std::sync::Arc;

/// The previous fit a local refit starts from.
pub(super) struct Previous<'a> {
    pub surface: &'a LoopLimitSurface,
    pub controls: &'a [DVec3],
    pub data: &'a [DVec3],
    pub params: &'a [SurfaceParam],
    pub errors: &'a [f64],
    /// Each previous data point's merge cell.
    pub cells: &'a [CellKey],
    /// The topology of the data the control mesh was built or last refitted for ...
    pub topology: &'a SurfaceTopology,
    /// ... and its holes (`holes_of`).
    pub holes: usize,
}

/// The new data matched to the previous fit by cell.
struct Matched {
    data: Vec<DVec3>,
    params: Vec<SurfaceParam>,
    /// The previous point each point was matched to, `None` for a changed one.
    same_as: Vec<Option<usize>>,
    /// Points with no previous point in or beside their cell: new ground.
    left_out: usize,
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
        left_out: 0,
    };
    for (c, p) in cells.iter().zip(positions) {
        let kept = old.get(c).copied();
        // A new cell with no previous neighbour lies off the ground the control mesh
        // covers: it is left out, and counted.
        let Some(k) = kept.or_else(|| neighbours(*c).find_map(|n| old.get(&n).copied())) else {
            m.left_out += 1;
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

/// The data a local refit fits: the merge's cleaned largest part, as the whole fit takes
/// it (the previous fit's points came from there), with each vertex's merge cell. The
/// bits cleaning drops (small parts, non-manifold spots of the surface nets) can lie
/// millimetres off the surface: matched by cell with the rest, they made the bunny's
/// re-registered bun045 (30 um) start its refit at 85 um RMS, max 3.9 mm (cleaned:
/// 36 um, 1.5 mm).
pub(super) struct LocalData {
    pub cells: Vec<CellKey>,
    pub mesh: TriMesh,
    pub topology: SurfaceTopology,
    /// Its boundary loops of at least `HOLE_EDGES` edges.
    pub holes: usize,
}

impl LocalData {
    /// `None` when cleaning leaves nothing, or no manifold surface.
    pub(super) fn of(merged: &Merged) -> Option<LocalData> {
        let mesh = fitted_component(&merged.mesh, &CleanOptions::default())?;
        let topo = Topology::from_mesh(&mesh).ok()?;
        let topology = SurfaceTopology::of_built(&mesh, &topo);
        let cells = cells_of(&mesh.positions, merged)?;
        Some(LocalData {
            cells,
            mesh,
            topology,
            holes: holes_of(&topo),
        })
    }
}

/// `LocalOptions::anchor` of an object session's refits. A point's point-to-point term
/// weighs each control of its row by the term's share times the squared basis weight, and
/// the squared Loop basis weights of a row sum to 0.27 on average (regular torus, uniform
/// parameters): per point a control stands for, 0.27 x the share. At the default share
/// of 0.005 (`[fit.correction] tangential`) that is 1.35e-3; an anchor of 1e-3 holds a
/// free control about as firmly, so it drifts along the surface no more freely than a
/// foot point does, and the data still move it.
/// Measured on the bunny's five scans at 3 % controls with bun045 re-registered 30 um
/// (the process test `daemon_objects`, at `rim_overhang_cells` 0.5): without it a free
/// control slid 3.4 mm and folded a face 2.9 mm off the data (the guard then fitted the
/// whole object again); with it the farthest face stood 0.68 mm off and the refit was
/// kept, at 4.99e-5 RMS against the whole fit's 5.03e-5.
pub(super) const SESSION_ANCHOR: f64 = 1e-3;

/// A boundary loop of fewer edges than this is a gap between a few merge cells, not a hole
/// a local refit must keep open: at a grazing rim such gaps open and close with a 30 um
/// shift of one view, and a whole fit keeps at least `MIN_BOUNDARY_LOOP` (6) controls on
/// any hole it keeps. A control mesh spanning one is bounded by the stray guard.
const HOLE_EDGES: usize = 6;

/// The boundary loops of `topo` of at least `HOLE_EDGES` edges.
fn holes_of(topo: &Topology) -> usize {
    boundary_loops(topo)
        .iter()
        .filter(|l| l.len() >= HOLE_EDGES)
        .count()
}

/// Each position's merge cell, read off the merge by position (cleaning keeps the
/// positions of what it keeps); `None` when one is not a merged vertex.
fn cells_of(positions: &[DVec3], merged: &Merged) -> Option<Vec<CellKey>> {
    let bits = |p: &DVec3| [p.x.to_bits(), p.y.to_bits(), p.z.to_bits()];
    let cell_at: FxHashMap<[u64; 3], CellKey> = merged
        .mesh
        .positions
        .iter()
        .zip(&merged.cells)
        .map(|(p, c)| (bits(p), *c))
        .collect();
    positions
        .iter()
        .map(|p| cell_at.get(&bits(p)).copied())
        .collect()
}

/// Why the data's topology now (`now`, with `holes` loops of `HOLE_EDGES` edges or more)
/// rules out a local refit of the control mesh built for `before`, if it does: a handle
/// made or lost, or a hole opened, which the kept control mesh would span. A hole the data
/// closed is no reason by itself (the bunny's small holes at grazing rims close and open
/// with a 30 um shift of one view): where the kept control mesh still has it, the data
/// there lies off the surface, and the refit's largest error says so
/// (`largest_error_refusal`). Nor is a gap of fewer edges opening (`HOLE_EDGES`).
fn topology_refusal(
    (before, holes_before): (&SurfaceTopology, usize),
    (now, holes): (&SurfaceTopology, usize),
) -> Option<String> {
    (now.genus != before.genus || holes > holes_before).then(|| {
        format!(
            "topology changed: genus {}, {} holes of {HOLE_EDGES} edges or more among {} \
             boundary loops (were {}, {holes_before} among {})",
            now.genus, holes, now.boundary_loops, before.genus, before.boundary_loops
        )
    })
}

/// Refits the controls around the data that changed (see the module docs) and returns the
/// matched data with the fit; why not when the data's topology rules the refit out or a
/// point lies off the previous fit's ground. A hole opened and another closed at once
/// pass the topology count: only the stray guard bounds the surface over the new one.
pub(super) fn refit(
    previous: &Previous,
    data: &LocalData,
    opts: &LocalOptions,
) -> Result<(Vec<DVec3>, LocalFit), String> {
    if let Some(why) = topology_refusal(
        (previous.topology, previous.holes),
        (&data.topology, data.holes),
    ) {
        return Err(why);
    }
    let matched = match_data(previous, &data.cells, &data.mesh.positions);
    if matched.left_out > 0 {
        return Err(format!(
            "{} points lie on new ground (no previous point within a merge cell)",
            matched.left_out
        ));
    }
    let n = matched.data.len();
    if n == 0 {
        return Err("no data".into());
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
        // Every matched point is a vertex of the data mesh (none was left out).
        Some(&data.mesh),
        feet,
        changed.len(),
        &free,
        opts,
    );
    Ok((matched.data, fit))
}

/// A local refit may fit its data at most this much worse (RMS) than the previous fit.
const MAX_LOCAL_RMS_RISE: f64 = 1.1;

/// The previous update's object fit, kept for the next local refit.
pub(super) struct LastFit {
    pub fit: PatchFit,
    /// Each data point's merge cell.
    pub cells: Vec<CellKey>,
    pub data_topology: SurfaceTopology,
    /// The data's holes (`holes_of`).
    pub holes: usize,
    pub control_topology: SurfaceTopology,
}

impl LastFit {
    /// The object fit of an update with its points' cells, read off the merge the fit's
    /// data came from, and `holes` (`holes_of`) of that data; `None` for a fit of another
    /// model or a point not from the merge.
    pub(super) fn of(fitted: &FittedPatch, merged: &Merged, holes: usize) -> Option<LastFit> {
        let info = fitted.object.as_ref()?;
        let SurfaceModel::Mesh(surface) = &fitted.fit.model else {
            return None;
        };
        let cells = cells_of(&fitted.fit.data, merged)?;
        // The same surface built afresh: a fitted one holds every quadtree leaf its fit and
        // tessellation evaluated (the bunny's: about 180 MB against 5 MB, rebuilt in 35
        // ms), and a kept session holds this until its next update.
        let fresh = LoopLimitSurface::with_creases(
            surface.control_count(),
            surface.faces(),
            surface.crease_edges(),
        )
        .ok()?;
        Some(LastFit {
            fit: PatchFit {
                model: SurfaceModel::Mesh(Arc::new(fresh)),
                ..fitted.fit.clone()
            },
            cells,
            data_topology: info.data_topology,
            holes,
            control_topology: info.control_topology,
        })
    }

    /// Why a local refit on `surface` (the previous fit's, or its refinement) to `data` is
    /// not kept, if it is not: it fits the data clearly worse than the previous fit did
    /// (`fits_worse`), leaves a point off the surface by more than the stray guard lets
    /// the surface leave the data (`largest_error_refusal`), or strays from the data
    /// farther than the previous surface there (`worker::stray_refusal`).
    pub(super) fn refusal(
        &self,
        surface: &LoopLimitSurface,
        local: &LocalFit,
        data: &TriMesh,
    ) -> Option<String> {
        let largest = |e: &[f64]| e.iter().copied().fold(0.0, f64::max);
        let previous = match &self.fit.model {
            SurfaceModel::Mesh(s) => Some(s.as_ref()),
            _ => None,
        };
        fits_worse(self.fit.geometric_rms(), rms_of_every_point(&local.errors))
            .or_else(|| {
                largest_error_refusal(
                    largest(&self.fit.geometric_errors),
                    largest(&local.errors),
                    data.bounds_diagonal(),
                )
            })
            .or_else(|| {
                stray_refusal(surface, &local.controls, data, &self.fit.controls, || {
                    previous
                })
            })
    }

    /// The largest distance from `data` to the surface a local refit may leave
    /// (`largest_error_refusal`'s bound).
    pub(super) fn largest_error_limit(&self, data: &TriMesh) -> f64 {
        let before = self
            .fit
            .geometric_errors
            .iter()
            .copied()
            .fold(0.0, f64::max);
        largest_allowed(before, data.bounds_diagonal())
    }

    /// The refit's result in the form the worker's outputs read.
    /// `refined`: the refined control mesh's surface when the refit refined it
    /// (`object::refine_where_far`), else the previous surface stays.
    pub(super) fn refitted(
        &self,
        (data, local): &(Vec<DVec3>, LocalFit),
        refined: Option<LoopLimitSurface>,
        data_topology: SurfaceTopology,
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
            model: match refined {
                Some(surface) => SurfaceModel::Mesh(Arc::new(surface)),
                None => self.fit.model.clone(),
            },
            ..self.fit.clone()
        };
        let info = ObjectInfo {
            reason: "local refit of the previous control mesh".into(),
            warm: WarmDecision::Used,
            data_topology,
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
            cleaning: None,
            stray_budgets: Vec::new(),
            faceted: None,
            // The merged data's components were counted by the whole fit this refit
            // started from; a local refit keeps its control mesh's.
            dropped: Default::default(),
        };
        FittedPatch {
            object: Some(info),
            ..FittedPatch::bare(fit, budget)
        }
    }
}

/// The RMS of a refit's errors at every data point (its moving points' and the others',
/// which kept their feet): what a whole fit's RMS measures, where the moving points alone,
/// gathered around the change, lie farther than the whole's average (a sphere's bumped cap
/// refitted: 1.37e-5 against 1.13e-5 over the whole before). Infinite without points.
fn rms_of_every_point(errors: &[f64]) -> f64 {
    if errors.is_empty() {
        return f64::INFINITY;
    }
    (errors.iter().map(|e| e * e).sum::<f64>() / errors.len() as f64).sqrt()
}

/// Why a local refit is not kept, if it is not: it fits the new data (RMS `after` over
/// every point, `rms_of_every_point`) over `MAX_LOCAL_RMS_RISE` times worse than the
/// previous fit fitted its own (RMS `before`). An update over the same ground (a scan
/// replaced, its registration corrected) fits about as well from scratch, so a refit left
/// well above it did not follow the change, and the whole fit runs. The moving points'
/// RMS was compared before: it caught the bunny's bun045 moved 30 um (40.8 um locally
/// against 35.2 um before, 35.0 um from scratch), and it refused refits that did follow
/// their change (a sphere's bumped cap) once the whole fits converged further; the
/// largest-error and stray guards still judge the refit's region alone.
fn fits_worse(before: f64, after: f64) -> Option<String> {
    // Written so that a NaN refuses the refit.
    let as_well = after <= MAX_LOCAL_RMS_RISE * before;
    (!as_well).then(|| {
        format!(
            "the local refit fits the data with RMS {after:.3e}, over {MAX_LOCAL_RMS_RISE} \
             times the previous fit's {before:.3e}"
        )
    })
}

/// Why a local refit whose largest error is `after` is not kept (the previous fit's was
/// `before`, the data's bounding-box diagonal is `diagonal`), if it is not: the stray
/// guard's rule the other way round, data to surface instead of surface to data (over
/// `MAX_STRAY_SHARE` of the diagonal and over `MAX_STRAY_GROWTH` times the previous).
/// Data covering a hole the kept control mesh still has (the data's topology may lose
/// holes, `topology_refusal`) lies off the surface by about the hole's radius.
fn largest_error_refusal(before: f64, after: f64, diagonal: f64) -> Option<String> {
    let allowed = largest_allowed(before, diagonal);
    // Written so that a NaN refuses the refit.
    let within = after <= allowed;
    (!within).then(|| {
        format!(
            "the local refit leaves a data point {after:.3e} off the surface (the previous \
             fit {before:.3e}; at most {allowed:.3e}, {MAX_STRAY_SHARE} of the bounding-box \
             diagonal or {MAX_STRAY_GROWTH} times the previous)"
        )
    })
}

/// The largest error a local refit may leave when the previous fit's was `before`.
fn largest_allowed(before: f64, diagonal: f64) -> f64 {
    (MAX_STRAY_GROWTH * before).max(MAX_STRAY_SHARE * diagonal)
}

#[cfg(test)]
mod tests {
    use super::{fits_worse, largest_error_refusal, topology_refusal, LocalData};
    use crate::mesh::simplify::SurfaceTopology;
    use crate::pipeline::merge::Merged;
    use crate::TriMesh;
    use glam::DVec3;

    #[test]
    fn a_local_refit_fitting_clearly_worse_than_before_is_not_kept() {
        let before = 3.5355339e-5;
        assert_eq!(fits_worse(before, 3.6e-5), None);
        assert_eq!(fits_worse(before, 2e-5), None);
        let why = fits_worse(before, 4.1e-5).expect("refused");
        assert!(
            why.contains("4.100e-5") && why.contains("3.536e-5"),
            "{why}"
        );
        assert!(fits_worse(before, f64::NAN).is_some());
        assert!(fits_worse(before, super::rms_of_every_point(&[])).is_some());
    }

    #[test]
    fn a_local_refit_leaving_a_point_far_off_is_not_kept() {
        let diagonal = 0.25;
        // Within 1.5 times the previous largest error, or within 0.5 % of the diagonal.
        assert_eq!(largest_error_refusal(5.6e-4, 8.3e-4, diagonal), None);
        assert_eq!(largest_error_refusal(1e-4, 1.2e-3, diagonal), None);
        // Beyond both: data over a hole the kept control mesh still has.
        let why = largest_error_refusal(5.6e-4, 2.4e-3, diagonal).expect("refused");
        assert!(why.contains("2.400e-3"), "{why}");
        assert!(largest_error_refusal(5.6e-4, f64::NAN, diagonal).is_some());
    }

    fn topology(loops: usize, genus: i64) -> SurfaceTopology {
        SurfaceTopology {
            euler: 2 - 2 * genus - loops as i64,
            boundary_loops: loops,
            components: 1,
            genus,
        }
    }

    #[test]
    fn a_local_refit_is_ruled_out_by_a_new_hole_or_handle_not_by_a_closed_hole() {
        let before = (&topology(32, 0), 20);
        // Small holes at grazing rims closed (the bunny's re-registered bun045: 32 -> 29).
        assert_eq!(topology_refusal(before, (&topology(29, 0), 18)), None);
        assert_eq!(topology_refusal(before, before), None);
        // A gap of a few edges opened: no hole to keep.
        assert_eq!(topology_refusal(before, (&topology(33, 0), 20)), None);
        // A hole opened: the kept control mesh would span it.
        let why = topology_refusal(before, (&topology(33, 0), 21)).expect("refused");
        assert!(why.contains("21 holes"), "{why}");
        // A handle made or lost.
        assert!(topology_refusal(before, (&topology(32, 1), 20)).is_some());
        assert!(topology_refusal((&topology(2, 1), 0), (&topology(2, 0), 0)).is_some());
    }

    /// A grid of `n` x `n` vertices in the plane z = 0 with spacing 1, its cells (x, y, 0).
    fn grid(n: u32) -> (Vec<DVec3>, Vec<[u32; 3]>, Vec<[i32; 3]>) {
        let mut positions = Vec::new();
        let mut cells = Vec::new();
        for j in 0..n {
            for i in 0..n {
                positions.push(DVec3::new(i as f64, j as f64, 0.0));
                cells.push([i as i32, j as i32, 0]);
            }
        }
        let mut triangles = Vec::new();
        for j in 0..n - 1 {
            for i in 0..n - 1 {
                let v = j * n + i;
                triangles.push([v, v + 1, v + n + 1]);
                triangles.push([v, v + n + 1, v + n]);
            }
        }
        (positions, triangles, cells)
    }

    /// A loose bit of the merge beside the object (a cell away) is not matched into a
    /// local refit: the whole fit's cleaning drops it, so the previous fit never had it.
    #[test]
    fn the_local_data_is_the_merges_cleaned_largest_part_with_its_cells() {
        let (mut positions, mut triangles, mut cells) = grid(6);
        let loose = positions.len() as u32;
        positions.extend([
            DVec3::new(6.0, 0.0, 1.0),
            DVec3::new(7.0, 0.0, 1.0),
            DVec3::new(6.0, 1.0, 1.0),
        ]);
        cells.extend([[6, 0, 1], [7, 0, 1], [6, 1, 1]]);
        triangles.push([loose, loose + 1, loose + 2]);
        let merged = Merged {
            mesh: TriMesh {
                positions,
                triangles,
            },
            cells,
            ..Default::default()
        };
        let data = LocalData::of(&merged).expect("a manifold part");
        assert_eq!(data.mesh.positions.len(), 36);
        assert_eq!(data.cells.len(), 36);
        assert_eq!(data.topology.boundary_loops, 1);
        for (p, c) in data.mesh.positions.iter().zip(&data.cells) {
            assert_eq!([p.x as i32, p.y as i32, 0], *c);
        }
    }

    /// `object::refine_where_far`, the refinement an update's local refit falls back on.
    mod refined_where_far {
        use crate::mesh::loop_subdiv::subdivide;
        use crate::pipeline::object::{
            fit_object, refine_where_far, LocalFit, LocalOptions, ObjectOptions, RefineOptions,
        };
        use crate::surface::TriSurface;
        use crate::testdata::icosahedron;
        use crate::TriMesh;
        use glam::DVec3;

        /// A unit sphere with a narrow bump of 0.3 around +z: a coarse control mesh leaves
        /// the bump's top far off.
        fn bumped_sphere() -> TriMesh {
            let (positions, triangles) = icosahedron();
            let fine = subdivide(&TriMesh::new(positions, triangles), 4).expect("manifold");
            let positions = fine
                .positions
                .iter()
                .map(|p| {
                    let n = p.normalize();
                    n * (1.0 + 0.3 * (-(n - DVec3::Z).length_squared() / 0.02).exp())
                })
                .collect();
            TriMesh::new(positions, fine.triangles)
        }

        #[test]
        fn a_local_refit_is_refined_where_it_leaves_points_far_and_nowhere_else() {
            let opts = ObjectOptions {
                target_controls: Some(150),
                refine: RefineOptions {
                    rounds: 0,
                    ..Default::default()
                },
                max_stray_share: None,
                ..Default::default()
            };
            let fit = fit_object(&bumped_sphere(), &opts).expect("fitted");
            // The whole fit as a local refit that freed nothing.
            let unrefined = || LocalFit {
                controls: fit.controls.clone(),
                params: fit.params.clone(),
                errors: fit.distances.clone(),
                free_controls: Vec::new(),
                changed_points: 0,
                moving_points: 0,
                rounds: vec![(fit.rms, fit.max)],
            };
            let local = unrefined();
            let limit = 0.5 * fit.max;
            let far = fit.distances.iter().filter(|&&d| d > limit).count();
            assert!(
                far > 0 && fit.max > 0.01,
                "the bump is left off: max {}",
                fit.max
            );
            let (surface, refined) = refine_where_far(
                &fit.surface,
                local,
                &fit.component,
                limit,
                &LocalOptions::of(&opts),
            )
            .expect("refined");
            let max = refined.errors.iter().copied().fold(0.0, f64::max);
            eprintln!(
                "{} -> {} controls, max {:.3e} -> {max:.3e}, {far} points beyond {limit:.3e}",
                fit.controls.len(),
                refined.controls.len(),
                fit.max
            );
            assert!(refined.controls.len() > fit.controls.len());
            assert_eq!(surface.control_count(), refined.controls.len());
            assert!(max < fit.max, "max {max} against {}", fit.max);
            // Every control the refit did not free is the previous one, bit for bit, and the
            // freed ones are around the bump.
            for (k, (a, b)) in fit.controls.iter().zip(&refined.controls).enumerate() {
                if refined.free_controls.binary_search(&(k as u32)).is_err() {
                    assert_eq!(a, b, "control {k}");
                }
            }
            assert!(!refined.free_controls.is_empty());
            assert!(refined.free_controls.len() < refined.controls.len() / 2);
            // Nothing to refine below the largest error.
            let local = unrefined();
            let none = refine_where_far(
                &fit.surface,
                local,
                &fit.component,
                fit.max,
                &LocalOptions::of(&opts),
            );
            assert!(none.is_none());
        }
    }
}
