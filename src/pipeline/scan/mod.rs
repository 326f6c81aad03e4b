//! Scans without subdivision connectivity, in six stages: clean, keep the largest component,
//! close holes and map the patch to the plane (`prepare`); build the domain and its initial
//! net (`resample`); put in what the previous version left (`seed`); fit the ORIGINAL scan
//! points with a fairness term (`rounds::first_fit`), then a few rounds of foot-point
//! correction (`rounds::correct`); and trim the surface to the data (`trims`).
//!
//! The helpers the stages use: `components`, `holes`, `edge_band` (preparation and rims),
//! `domain` and `grid_inverse` (domains and initial nets), `solve` (the solves and foot
//! points), `warm` and `feet` (what a previous version leaves). Shared types live in `types`.

mod cold_start;
pub mod components;
pub mod domain;
mod edge_band;
mod feet;
mod grid_inverse;
pub mod holes;
pub(crate) mod prepare;
mod resample;
mod rounds;
mod seed;
mod solve;
mod trims;
mod types;
mod warm;
mod warm_guard;

pub use cold_start::ColdStart;
pub use feet::WarmFeet;
pub use types::{
    BezierLayout, Correction, CorrectionConfig, Domain, Dropped, Mapping, Preparation, ScanConfig,
    ScanFit, ScanTimings, Trims,
};
pub(crate) use types::{ScanOptions, ScanWarm};
pub(crate) use warm::warm_feet;

use crate::fit::engine::umbrella_laplacian;
use crate::fit::Collocation;
use crate::pipeline::{FitOptions, PatchFit, PipelineError, SurfaceKind, SurfaceModel};
use crate::TriMesh;
use glam::DVec2;
use rounds::{EdgeBand, LazyStencils, Problem};
use std::time::Instant;

/// Fits a disk-like scan: the stages above, in order, each taking what the ones before left.
pub(crate) fn fit_scan(
    mesh: &TriMesh,
    opts: &FitOptions,
    scan: &ScanOptions,
    warm: Option<&ScanWarm>,
) -> Result<ScanFit, PipelineError> {
    let t0 = Instant::now();
    let prepared = prepare::prepare(mesh, scan, warm)?;
    // A previous version too different from this one is not used at all (its plane, grid,
    // controls and feet would each mislead).
    let warm = warm.filter(|_| prepared.cold_start.is_none());
    let parameterization_ms = t0.elapsed().as_secs_f64() * 1e3;

    let t1 = Instant::now();
    let (hole_plan, resampled) = resample::resample(&prepared, opts, scan, warm)?;
    let warm = warm.filter(|_| resampled.cold_start.is_none());
    let cold_start = prepared.cold_start.or(resampled.cold_start);
    let resample_ms = t1.elapsed().as_secs_f64() * 1e3;

    let seed::Seed {
        start,
        reused,
        mut params,
        previous_feet,
    } = seed::seed(&prepared, &resampled, warm);
    let data = &prepared.part.positions;
    let control_count = resampled.model.as_surface().control_count();
    let fairness = Collocation::new(umbrella_laplacian(
        control_count,
        &resampled.fairness_triangles,
    ));
    let smoothing = scan.config.smoothing * data.len() as f64 / control_count.max(1) as f64;
    let prepare_ms = t0.elapsed().as_secs_f64() * 1e3;

    let t2 = Instant::now();
    let real = prepared.patch.real_vertices;
    let problem = Problem {
        opts,
        scan,
        model: &resampled.model,
        data,
        fairness: &fairness,
        smoothing,
    };
    let stencils = LazyStencils::new(&problem);
    let band = EdgeBand {
        part: &prepared.part,
        patch: &prepared.patch,
        plane: &prepared.map.plane[..real],
        domain: &resampled.domain,
    };
    let first = rounds::first_fit(
        &problem,
        &stencils,
        &band,
        start,
        reused,
        previous_feet,
        &mut params,
    )?;
    let corrected = rounds::correct(&problem, &stencils, &band, first, &mut params, t2)?;
    let fit_ms = t2.elapsed().as_secs_f64() * 1e3;
    drop(stencils);

    let trims = trims::trims(&prepared, &resampled.domain, &params, hole_plan);
    let resample::Resampled {
        model,
        domain,
        initial,
        ..
    } = resampled;
    let prepare::Prepared {
        part,
        components,
        dropped,
        patch,
        frame,
        map,
        ..
    } = prepared;
    let mapped_params = map
        .plane
        .iter()
        .map(|p| {
            let (u, v) = domain.param(*p);
            DVec2::new(u, v)
        })
        .collect();
    let degree = match &model {
        SurfaceModel::Bezier(b) => b.degree,
        SurfaceModel::Grid(_) if opts.surface == SurfaceKind::Bezier => 4,
        SurfaceModel::BPatch(b) => b.degree(),
        SurfaceModel::Dms(d) => d.degree(),
        SurfaceModel::Grid(_) | SurfaceModel::Mesh(_) => 0,
    };
    let outcome = corrected.outcome;
    Ok(ScanFit {
        fit: PatchFit {
            surface: opts.surface,
            degree,
            model,
            controls: outcome.controls.clone(),
            data: part.positions,
            params,
            outcome,
            geometric_errors: corrected.errors,
            warm_start: reused > 0,
            prepare_ms,
            fit_ms,
        },
        preparation: Preparation {
            components,
            kept_vertices: real,
            holes: patch.holes,
            dropped,
        },
        mapping: Mapping {
            frame,
            warp: map.warp,
            folds_warped: map.folds_warped,
            method: map.method,
            folds_projected: map.folds_projected,
            filled: map.mesh,
            mapped_params,
            near_fold: map.near_fold,
        },
        domain,
        initial,
        trims,
        correction_rms: corrected.correction_rms,
        reused_controls: reused,
        cold_start,
        timings: ScanTimings {
            parameterization_ms,
            resample_ms,
        },
    })
}
