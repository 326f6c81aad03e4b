//! B-patches and DMS splines for inputs with Loop subdivision connectivity (the paper's
//! setting): inverse subdivision `fit.levels` deep gives the coarse net and every fine
//! vertex its exact place on it (coarse face, barycentric), so no scan preparation runs.
//!
//! - The coarse net's parameter triangulation: the net mapped to the plane by Floater's
//!   mean-value map with its outer boundary on a circle (convex: one-to-one; holes closed
//!   by fans around virtual centres, which stay in the domain without data), mirrored if
//!   the map turned the faces clockwise.
//! - DMS: that triangulation is the domain, triangle for triangle, so a fine vertex's
//!   parameter is its (coarse face, u, v) unchanged. Controls start on the coarse net
//!   (piecewise linear over the triangulation, read at each control's Greville site).
//! - B-patch: one triangle. When the coarse net is one triangular lattice of n segments
//!   (as the bezier kind needs), the patch has degree n over that lattice's triangle, its
//!   controls start as the coarse net read as a Bezier net (the same surface), and fine
//!   vertices keep their lattice coordinates. Otherwise the patch (degree `fit.bpatch.
//!   degree`) covers the smallest equilateral triangle around the mapped net and starts
//!   from the coarse net where its Greville sites fall on it, from the plane of the data
//!   elsewhere.
//!
//! Then the rounds of the scan path's planar kinds (`rounds`): the first fit at these
//! parameters, foot-point squared-distance rounds while they gain; and the region shown
//! (`shown_region`): where the fine mesh has triangles, so the input's holes stay open.

use super::error::ScatteredError;
use super::rounds::{first_fit_options, fit_rounds, start_net};
use crate::fit::Budget;
use crate::mesh::inverse::coarsen;
use crate::pipeline::coverage::Coverage;
use crate::pipeline::scan::domain::enclosing_triangle;
use crate::pipeline::scan::prepare::median_edge_length;
use crate::pipeline::subdivided::{hierarchy_of, lattice::lattice_coordinates};
use crate::pipeline::worker::{WarmStart, WorkerConfig};
use crate::pipeline::{NoSubdivision, PatchFit, PipelineError, SurfaceKind, SurfaceModel};
use crate::remesh::fill_holes;
use crate::remesh::param::mean_value_disk;
use crate::scattered_fit::InitialNet;
use crate::surface::bezier::lattice_points;
use crate::surface::bpatch::BPatch;
use crate::surface::dms::{DmsSpline, KnotRule, PlanarSurface};
use crate::surface::simplex_spline::det2;
use crate::surface::SurfaceParam;
use crate::TriMesh;
use glam::{DVec2, DVec3};
use std::sync::Arc;
use std::time::Instant;

/// Margin of the B-patch's triangle around the mapped net, as a fraction of its size.
const ENCLOSING_MARGIN: f64 = 0.01;

/// The coarse net and its parameter triangulation.
struct CoarseDomain {
    /// Plane point of every coarse vertex (then the virtual hole centres).
    plane: Vec<DVec2>,
    /// Positions of the same vertices (hole centres: their rims' centroids).
    positions: Vec<DVec3>,
    /// Coarse faces first (the fine parameters' face ids), then the hole fans; all
    /// counter-clockwise in `plane`.
    triangles: Vec<[u32; 3]>,
    /// The coarse net itself (vertex order and faces of inverse subdivision).
    net: TriMesh,
    /// Every fine vertex on the coarse net: (coarse face, u, v).
    fine: Vec<(u32, f64, f64)>,
}

/// Fits `mesh` as `cfg.fit.surface` (bpatch or dms) over its coarse net when it has
/// subdivision connectivity `cfg.fit.levels` (>= 1) deep, with the region to show (in
/// domain points); `Ok(None)` when it has not (the caller maps it as a scan).
pub(crate) fn fit_planar_subdivided(
    mesh: &TriMesh,
    previous: Option<&WarmStart>,
    cfg: &WorkerConfig,
    budget: &Budget,
) -> Result<Option<(PatchFit, Coverage)>, PipelineError> {
    let t0 = Instant::now();
    let fit_cfg = &cfg.fit;
    let kind = fit_cfg.surface;
    if fit_cfg.levels == 0 {
        return Ok(None);
    }
    let Some(domain) = coarse_domain(mesh, fit_cfg.levels, fit_cfg.inverse)? else {
        return Ok(None);
    };
    let (model, params, start, degree) = match kind {
        SurfaceKind::Dms => dms_on_net(&domain, cfg)?,
        SurfaceKind::Bpatch => bpatch_on_net(&domain, cfg)?,
        other => return Err(ScatteredError::NotPlanarKind(other.name()).into()),
    };
    let surface: &dyn PlanarSurface = match &model {
        SurfaceModel::Dms(d) => d.as_ref(),
        SurfaceModel::BPatch(b) => b.as_ref(),
        _ => return Err(ScatteredError::NotPlanarKind(kind.name()).into()),
    };
    let data = &mesh.positions;
    let warm = previous
        .filter(|w| w.surface == kind && w.controls.len() == surface.control_count())
        .map(|w| w.controls.clone());
    let warm_start = warm.is_some();
    let initial = match warm {
        Some(controls) => InitialNet::Given(controls),
        None => start_net(surface, &params, data, Some(start)),
    };
    let prepare_ms = t0.elapsed().as_secs_f64() * 1e3;
    let t1 = Instant::now();
    let options = first_fit_options(fit_cfg, budget, surface, data.len(), initial);
    let mapped: Vec<DVec2> = params.iter().map(|p| surface.domain_point(*p)).collect();
    let rounds = fit_rounds(surface, params, data, options, &fit_cfg.correction)?;
    let fit_ms = t1.elapsed().as_secs_f64() * 1e3;
    let reach = fit_cfg.scan.hole_bridge_edges * median_edge_length(mesh);
    let shown = shown_region(
        surface,
        mesh,
        &mapped,
        &rounds.params,
        &rounds.errors,
        reach,
    );
    let fit = PatchFit {
        surface: kind,
        degree,
        controls: rounds.outcome.controls.clone(),
        model,
        data: data.clone(),
        params: rounds.params,
        outcome: rounds.outcome,
        geometric_errors: rounds.errors,
        warm_start,
        prepare_ms,
        fit_ms,
    };
    Ok(Some((fit, shown)))
}

/// What of a subdivided fit is shown, by `pipeline::coverage`'s rule in domain points: the
/// fine triangles with their vertices at their final domain points (a hole of the input has
/// none, so the fans that close it in the domain stay hidden) and the footprint of the
/// fitted points the surface passes within `reach` of (the scan path's hole-bridging
/// distance in fine edges).
fn shown_region(
    surface: &dyn PlanarSurface,
    mesh: &TriMesh,
    mapped: &[DVec2],
    feet: &[SurfaceParam],
    errors: &[f64],
    reach: f64,
) -> Coverage {
    let corrected: Vec<SurfaceParam> = feet
        .iter()
        .map(|p| {
            let x = surface.domain_point(*p);
            SurfaceParam {
                face: 0,
                u: x.x,
                v: x.y,
            }
        })
        .collect();
    Coverage::new(&mesh.triangles, &corrected, mapped, &[]).with_footprint(
        &corrected,
        &mesh.positions,
        errors,
        reach,
    )
}

/// The coarse net `levels` deep and its parameter triangulation (module docs); `None`
/// without subdivision connectivity that deep.
fn coarse_domain(
    mesh: &TriMesh,
    levels: usize,
    inverse: crate::mesh::inverse::InverseMethod,
) -> Result<Option<CoarseDomain>, PipelineError> {
    let (topo, hierarchy) = match hierarchy_of(mesh, levels) {
        Ok(h) => h,
        Err(PipelineError::NoSubdivision(_)) => return Ok(None),
        Err(e) => return Err(e),
    };
    let net = coarsen(mesh, levels, inverse)
        .map_err(NoSubdivision::Inverse)?
        .mesh;
    let fine = hierarchy.fine_vertex_params(&topo);
    let patch = fill_holes(&net).map_err(|e| ScatteredError::CoarseNet(e.to_string()))?;
    let mut plane =
        mean_value_disk(&patch).map_err(|e| ScatteredError::CoarseNet(e.to_string()))?;
    let triangles = patch.mesh.triangles.clone();
    let signed: Vec<f64> = triangles
        .iter()
        .map(|t| {
            let [a, b, c] = t.map(|v| plane[v as usize]);
            det2(a, b, c)
        })
        .collect();
    let clockwise = signed.iter().filter(|&&d| d < 0.0).count();
    if clockwise * 2 > triangles.len() {
        plane.iter_mut().for_each(|p| p.x = -p.x);
    }
    let folded = if clockwise * 2 > triangles.len() {
        triangles.len() - clockwise
    } else {
        clockwise
    } + signed.iter().filter(|&&d| d == 0.0 || d.is_nan()).count();
    if folded > 0 {
        return Err(ScatteredError::CoarseNetFolded { triangles: folded }.into());
    }
    Ok(Some(CoarseDomain {
        plane,
        positions: patch.mesh.positions.clone(),
        triangles,
        net,
        fine,
    }))
}

type OnNet = (SurfaceModel, Vec<SurfaceParam>, Vec<Option<DVec3>>, usize);

/// The coarse net at domain point x (piecewise linear over the triangulation), if x lies on
/// it (brute force: the B-patch has few controls).
fn net_at(d: &CoarseDomain, x: DVec2) -> Option<DVec3> {
    d.triangles.iter().find_map(|t| {
        let [a, b, c] = t.map(|v| d.plane[v as usize]);
        let det = det2(a, b, c);
        let (u, v) = (det2(x, b, c) / det, det2(a, x, c) / det);
        let w = 1.0 - u - v;
        (u.min(v).min(w) >= -1e-12).then(|| {
            let [pa, pb, pc] = t.map(|k| d.positions[k as usize]);
            pa * u + pb * v + pc * w
        })
    })
}

fn dms_on_net(d: &CoarseDomain, cfg: &WorkerConfig) -> Result<OnNet, PipelineError> {
    let spline = DmsSpline::new(
        d.plane.clone(),
        d.triangles.clone(),
        cfg.fit.dms.degree,
        KnotRule::Perturbed {
            spread: cfg.fit.dms.knot_spread,
        },
    )
    .map_err(ScatteredError::Dms)?;
    let params = d
        .fine
        .iter()
        .map(|&(face, u, v)| SurfaceParam { face, u, v })
        .collect();
    let start = spline
        .greville_sites()
        .into_iter()
        .map(|s| {
            spline.locate(s).map(|p| {
                let [a, b, c] = d.triangles[p.face as usize].map(|k| d.positions[k as usize]);
                a * p.u + b * p.v + c * (1.0 - p.u - p.v)
            })
        })
        .collect();
    let degree = spline.degree();
    Ok((SurfaceModel::Dms(Arc::new(spline)), params, start, degree))
}

fn bpatch_on_net(d: &CoarseDomain, cfg: &WorkerConfig) -> Result<OnNet, PipelineError> {
    let spread = cfg.fit.bpatch.knot_spread;
    if let Ok((n, index)) = lattice_coordinates(d.net.positions.len(), &d.net.triangles) {
        // The lattice's own triangle: corner (i, j) = (n, 0) is A, (0, n) is B, (0, 0) C.
        let domain = [
            DVec2::new(1.0, 0.0),
            DVec2::new(0.5, 3f64.sqrt() / 2.0),
            DVec2::ZERO,
        ];
        let patch = BPatch::outward(n, domain, spread).map_err(ScatteredError::BPatch)?;
        let coords = lattice_points(n);
        let mut bezier = vec![DVec3::ZERO; coords.len()];
        for (v, &idx) in index.iter().enumerate() {
            bezier[idx] = d.net.positions[v];
        }
        let params = d
            .fine
            .iter()
            .map(|&(f, u, v)| {
                let t = d.net.triangles.get(f as usize).copied().unwrap_or([0; 3]);
                let w = 1.0 - u - v;
                let c = |k: usize| coords[index[t[k] as usize]];
                let lattice = |pick: fn((usize, usize)) -> usize| {
                    (u * pick(c(0)) as f64 + v * pick(c(1)) as f64 + w * pick(c(2)) as f64)
                        / n as f64
                };
                SurfaceParam {
                    face: 0,
                    u: lattice(|p| p.0),
                    v: lattice(|p| p.1),
                }
            })
            .collect();
        let start = patch
            .controls_from_bezier(&bezier)
            .into_iter()
            .map(Some)
            .collect();
        return Ok((SurfaceModel::BPatch(Arc::new(patch)), params, start, n));
    }
    let corners = enclosing_triangle(&d.plane, ENCLOSING_MARGIN);
    let degree = cfg.fit.bpatch.degree;
    let patch = BPatch::outward(degree, corners, spread).map_err(ScatteredError::BPatch)?;
    let params = d
        .fine
        .iter()
        .map(|&(f, u, v)| {
            let t = d.triangles.get(f as usize).copied().unwrap_or([0; 3]);
            let [a, b, c] = t.map(|k| d.plane[k as usize]);
            patch.param_of(a * u + b * v + c * (1.0 - u - v))
        })
        .collect();
    let start = patch
        .greville_sites()
        .into_iter()
        .map(|s| net_at(d, s))
        .collect();
    Ok((SurfaceModel::BPatch(Arc::new(patch)), params, start, degree))
}
