//! The planar-domain kinds in the product: `surface = "bpatch"` (Seidel's B-patch over one
//! triangle around the scan's planar map) and `surface = "dms"` (a DMS triangular B-spline
//! over a triangulation of the map: the grid path's cells at a coarser spacing).
//!
//! Inputs with subdivision connectivity `fit.levels` deep are fitted over their coarse net's
//! parameter triangulation (`subdivided`). Any other input goes through the scan's
//! preparation (clean, largest component, holes, planar map: `scan::prepare`). Then: the domain (`domain`), every data point
//! located in it, a first fit by `scattered_fit::fit_scattered`, then rounds at the foot
//! points (`rounds`: squared-distance minimisation like the scan path's, or point-to-point
//! again with `fit.correction.kind = "parameters"`) while a round gains
//! `fit.correction.min_gain`, and the covered region in the plane for the trimmed
//! tessellation (`output`). A previous version of the same kind (`warm`) gives its frame and
//! warp, and its domain and controls where they still cover the new data.

mod config;
mod domain;
mod error;
mod info;
pub mod kinds;
mod output;
mod rounds;
mod subdivided;
mod warm;

pub use config::{BPatchConfig, DmsConfig, BPATCH_DEGREES, DMS_DEGREES};
pub use error::ScatteredError;
use info::planar_surface;
pub use info::{process_cpu_ms, PlanarStages, ScatteredInfo, StageTime};
pub(crate) use output::add_outputs;
pub use output::tessellate_planar;
pub(crate) use subdivided::fit_planar_subdivided;
pub use warm::ScatteredWarm;

use super::output::Coverage;
use super::scan::holes::plan_holes;
use super::scan::prepare::{prepare, Prepared};
use super::scan::{Preparation, ScanOptions, ScanWarm};
use super::worker::{WarmStart, WorkerConfig};
use super::{PatchFit, PipelineError, SurfaceKind, SurfaceModel};
use crate::fit::Budget;
use crate::surface::dms::PlanarSurface;
use crate::surface::SurfaceParam;
use glam::DVec2;
use rayon::prelude::*;
use std::time::Instant;

/// Fits `mesh` with the planar-domain kind `cfg.fit.surface`, warm from `previous` when it
/// is a fit of the same kind.
pub(crate) fn fit_planar(
    mesh: &crate::TriMesh,
    previous: Option<&WarmStart>,
    cfg: &WorkerConfig,
    budget: &Budget,
) -> Result<(PatchFit, ScatteredInfo), PipelineError> {
    let t0 = Instant::now();
    let fit_cfg = &cfg.fit;
    let kind = fit_cfg.surface;
    if !matches!(kind, SurfaceKind::Bpatch | SurfaceKind::Dms) {
        return Err(ScatteredError::NotPlanarKind(kind.name()).into());
    }
    let scan = ScanOptions {
        config: fit_cfg.scan,
        correction: fit_cfg.correction,
        min_component_vertices: fit_cfg.components.min_vertices,
        refuse_distorted: false,
    };
    let previous = previous.filter(|w| w.surface == kind && w.scattered.is_some());
    let scan_warm = previous.map(|w| ScanWarm {
        frame: w.frame,
        warp: w.warp.as_ref(),
        feet: w.feet.as_ref(),
        ..ScanWarm::default()
    });
    let prepared = prepare(mesh, &scan, scan_warm.as_ref())?;
    let mut cold_start = prepared.cold_start.map(|c| c.to_string());
    let previous = previous.filter(|_| cold_start.is_none());
    let real = prepared.patch.real_vertices;
    let plane = &prepared.map.plane[..real];
    let data = &prepared.part.positions;
    let map = warm::MapView {
        data: plane,
        plane: &prepared.map.plane,
        triangles: &prepared.map.mesh.triangles,
    };
    let built = warm::build_surface(
        kind,
        fit_cfg,
        &map,
        previous.and_then(|w| w.scattered.as_ref()),
    )?;
    if built.cold_because.is_some() {
        cold_start = built.cold_because.clone();
    }
    let surface = planar_surface(&built.model).ok_or(ScatteredError::NotPlanarKind(kind.name()))?;
    let params = locate_all(surface, plane)?;
    let prepare_ms = t0.elapsed().as_secs_f64() * 1e3;

    let t1 = Instant::now();
    let initial = rounds::start_net(surface, &params, data, built.controls.clone());
    let options = rounds::first_fit_options(fit_cfg, budget, surface, data.len(), initial);
    let rounds = rounds::fit_rounds(surface, params, data, options, &fit_cfg.correction)?;
    let fit_ms = t1.elapsed().as_secs_f64() * 1e3;

    let domain_points: Vec<DVec2> = rounds
        .params
        .iter()
        .map(|p| surface.domain_point(*p))
        .collect();
    let info = planar_info(
        &prepared,
        &fit_cfg.scan,
        &domain_points,
        &rounds,
        built.spacing,
        built.reused,
        cold_start,
    );
    let degree = match &built.model {
        SurfaceModel::BPatch(b) => b.degree(),
        SurfaceModel::Dms(d) => d.degree(),
        _ => 0,
    };
    let fit = PatchFit {
        surface: kind,
        degree,
        model: built.model.clone(),
        controls: rounds.outcome.controls.clone(),
        data: data.clone(),
        params: rounds.params,
        outcome: rounds.outcome,
        geometric_errors: rounds.errors,
        warm_start: built.reused > 0,
        prepare_ms,
        fit_ms,
    };
    Ok((fit, info))
}

/// Every data point's parameter from its plane point; the domains are built to cover the
/// map, so a point outside is refused rather than fitted somewhere else.
fn locate_all(
    surface: &dyn PlanarSurface,
    plane: &[DVec2],
) -> Result<Vec<SurfaceParam>, PipelineError> {
    let located: Vec<Option<SurfaceParam>> = plane.par_iter().map(|x| surface.locate(*x)).collect();
    let outside = located.iter().filter(|p| p.is_none()).count();
    if outside > 0 {
        return Err(ScatteredError::OutsideDomain { points: outside }.into());
    }
    Ok(located.into_iter().flatten().collect())
}

/// The covered region (with the footprint of the fitted points the rounds left) and trims in
/// domain coordinates.
fn planar_info(
    prepared: &Prepared,
    scan: &crate::pipeline::scan::ScanConfig,
    domain_points: &[DVec2],
    rounds: &rounds::Rounds,
    spacing: Option<f64>,
    reused_controls: usize,
    cold_start: Option<String>,
) -> ScatteredInfo {
    let real = prepared.patch.real_vertices;
    let map = &prepared.map;
    let plan = plan_holes(
        &map.mesh,
        real,
        &prepared.patch.hole_loops,
        &prepared.part.triangles,
        scan.hole_bridge_edges * prepared.edge_length,
    );
    // Data vertices at their final domain points, hole centres where the map put them.
    let at = |v: u32| {
        domain_points
            .get(v as usize)
            .copied()
            .unwrap_or(map.plane[v as usize])
    };
    let outer = prepared.patch.outer.iter().map(|&v| at(v)).collect();
    let holes = prepared
        .patch
        .hole_loops
        .iter()
        .zip(&plan.bridged)
        .filter(|(_, bridged)| !**bridged)
        .map(|(rim, _)| rim.iter().map(|&v| at(v)).collect())
        .chain(
            plan.wide_triangles
                .iter()
                .map(|&k| map.mesh.triangles[k].iter().map(|&v| at(v)).collect()),
        )
        .collect();
    let corrected: Vec<SurfaceParam> = domain_points
        .iter()
        .map(|x| SurfaceParam {
            face: 0,
            u: x.x,
            v: x.y,
        })
        .collect();
    // The footprint as the other kinds': the fitted points the surface passes within the
    // bridging distance of, at their final domain points.
    let coverage = Coverage::new(&plan.covered, &corrected, &map.plane, &map.near_fold)
        .with_footprint(
            &corrected,
            &prepared.part.positions,
            &rounds.errors,
            plan.max_bridge,
        );
    ScatteredInfo {
        preparation: Preparation {
            components: prepared.components,
            kept_vertices: real,
            holes: prepared.patch.holes,
            dropped: prepared.dropped,
        },
        frame: prepared.frame,
        warp: map.warp.clone(),
        method: map.method,
        coverage,
        outer,
        holes,
        correction_rms: rounds.rms.clone(),
        stages: rounds.stages,
        spacing,
        reused_controls,
        cold_start,
    }
}
