//! Scans without subdivision connectivity: clean, keep the largest component, close holes
//! with virtual fans, map the patch to the plane (`remesh::planar`), build the domain
//! (`domain`), resample and inverse-subdivide for the initial net, then fit the ORIGINAL
//! scan points with a fairness term and a few rounds of parameter correction.

use super::components::cleaned_components;
use super::domain::{
    barycentric, bezier_initial_net, covered_cells, enclosing_triangle, grid_for_target,
    grid_initial_net, plane_extent, GridFrame, InitialNet,
};
use super::edge_band::near_edges;
use super::holes::{plan_holes, HolePlan};
use super::scan_solve::{assembled_fit, foot_points, rms, run_fit, DistanceRound, GridStencils};
pub use super::scan_warm::WarmFeet;
use super::scan_warm::{net_from_warm, params_from_previous};
use super::{FitOptions, PatchFit, PipelineError, SurfaceKind};
use crate::fit::engine::umbrella_laplacian;
use crate::fit::{Collocation, FitOutcome, FitStatus, Method, StepStats};
use crate::mesh::clean::{clean, CleanOptions};
use crate::remesh::fill_holes;
use crate::remesh::planar::{evened_out, planar_map, projection_warp, MapMethod, PlaneFrame};
use crate::remesh::warp::PlaneWarp;
use crate::surface::bezier::{lattice_triangles, BezierTriangle};
use crate::surface::grid_spline::GridSpline;
use crate::surface::loop_limit::LoopLimitSurface;
use crate::surface::{SurfaceParam, TriSurface};
use crate::TriMesh;
use glam::{DVec2, DVec3};
use std::sync::Arc;
use std::time::Instant;

/// Width of the band along the data's edges where distance rounds keep the larger
/// tangential share, in control spacings. On chin with the default rounds (the test
/// `the_edge_band_lowers_the_rms_without_raising_the_maximum`): 71.9 um RMS with the band
/// against 75.9 um with the edge share everywhere, and a 0.74 mm largest error against
/// 1.45 mm with the interior share everywhere. Three rings of samples (about this width on
/// the Stanford scans) did as well; six rings (a whole spacing) ended chin 0.6 um higher.
const EDGE_BAND_SPACINGS: f64 = 0.5;

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

/// What `bezier` means on a scan.
#[derive(
    Clone,
    Copy,
    Debug,
    Default,
    PartialEq,
    Eq,
    serde::Serialize,
    serde::Deserialize,
    clap::ValueEnum,
)]
#[serde(rename_all = "lowercase")]
pub enum BezierLayout {
    /// One quartic triangular Bezier patch per cell of the grid domain, C2 across cells:
    /// the Bezier form of the grid fit (a single patch cannot follow a scan: degree 16 left
    /// ~1 mm RMS on the Stanford scans, and 5 % control points would need degree ~60).
    #[default]
    Patches,
    /// One triangular Bezier patch of degree `lattice` over the whole map.
    Single,
}

#[derive(Clone, Debug)]
pub struct ScanOptions {
    /// Bezier, `Single` layout: the degree (control-net segments per side).
    pub lattice: usize,
    pub bezier_layout: BezierLayout,
    /// Loop: grid cells across the longer side of the patch; when absent the spacing is
    /// chosen for `target_controls_pct`.
    pub grid_segments: Option<usize>,
    /// Loop: control points as a percentage of the data points.
    pub target_controls_pct: f64,
    /// Fairness weight relative to the data: s = smoothing * data points / control points.
    pub smoothing: f64,
    /// Rounds of correction after the first fit (data parameters moved to their foot points).
    pub correction_rounds: usize,
    pub correction: Correction,
    /// Rounds stop once one lowers the geometric RMS by less than this fraction.
    pub correction_min_gain: f64,
    /// Share of the point-to-point term beside the point-to-plane one in distance rounds,
    /// inside the data: smaller lets the surface slide more freely, so rounds converge
    /// faster and further (lower RMS).
    pub correction_tangential: f64,
    /// The same share within half a control spacing of the data's edges (outer rim and
    /// holes): sliding there pulls the surface past the last points (higher maximum
    /// errors), so it stays stiffer.
    pub correction_tangential_edge: f64,
    /// The largest component must have at least this many vertices.
    pub min_component_vertices: usize,
    /// Holes (and data triangles) with a bridging radius above this many median edge
    /// lengths are trimmed out; narrower ones are bridged by the surface (`holes`).
    pub hole_bridge_edges: f64,
}

/// What a correction round refits after moving the parameters to the foot points.
#[derive(
    Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize, clap::ValueEnum,
)]
#[serde(rename_all = "lowercase")]
pub enum Correction {
    /// Point-to-point least squares again (classic parameter correction).
    Parameters,
    /// Squared-distance minimisation (point-to-plane with a tangential share).
    Distance,
}

/// The surface model a fit lives on; `PatchFit` carries it for evaluation downstream.
#[derive(Clone, Debug)]
pub enum SurfaceModel {
    Bezier(BezierTriangle),
    Grid(GridSpline),
    /// The exact Loop limit surface of an input's own coarse net (subdivided inputs).
    Mesh(Arc<LoopLimitSurface>),
}

impl SurfaceModel {
    pub fn as_surface(&self) -> &dyn TriSurface {
        match self {
            SurfaceModel::Bezier(b) => b,
            SurfaceModel::Grid(g) => g,
            SurfaceModel::Mesh(m) => m.as_ref(),
        }
    }
}

/// Where the parameters live, kept for warm starts and written to surface.json.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum Domain {
    /// Barycentric coordinates of the plane triangle `corners` (corner 0 carries u,
    /// corner 1 carries v).
    Triangle { corners: [DVec2; 3] },
    /// Grid coordinates of the grid of this spacing anchored at the frame's origin.
    Grid { spacing: f64 },
}

impl Domain {
    pub fn param(&self, p: DVec2) -> (f64, f64) {
        match self {
            Domain::Triangle { corners } => barycentric(corners, p),
            Domain::Grid { spacing } => GridFrame { spacing: *spacing }.to_grid(p),
        }
    }
}

#[derive(Clone, Debug)]
pub struct ScanFit {
    pub fit: PatchFit,
    pub components: usize,
    pub kept_vertices: usize,
    pub holes: usize,
    pub frame: PlaneFrame,
    /// The warp of the projection plane, if the map is a warped projection, and the
    /// triangles it folded (left out of `filled` with the projection's folds).
    pub warp: Option<PlaneWarp>,
    pub folds_warped: usize,
    pub domain: Domain,
    pub map_method: MapMethod,
    pub folds_projected: usize,
    /// The patch as mapped: real triangles (folds left out) and the hole fills...
    pub filled: TriMesh,
    /// ... and its vertices' parameters on the plain map (before correction)...
    pub mapped_params: Vec<DVec2>,
    /// ... and which of them belong to folded triangles of the map.
    pub near_fold: Vec<bool>,
    pub initial: InitialNet,
    /// Outer boundary of the data in parameter coordinates, ordered: the trim.
    pub trim: Vec<(f64, f64)>,
    /// Which holes are bridged and which trimmed, and the triangles of `filled` that make
    /// the covered region (all but the fills of trimmed holes).
    pub hole_plan: HolePlan,
    /// Rims of the trimmed holes and wide data triangles in parameter coordinates, ordered
    /// like `trim`: what lies inside any of them is not part of the surface.
    pub hole_trims: Vec<Vec<(f64, f64)>>,
    /// Geometric RMS after the first fit and after each correction round.
    pub correction_rms: Vec<f64>,
    pub parameterization_ms: f64,
    pub resample_ms: f64,
    /// Control points reused from the previous version (warm start).
    pub reused_controls: usize,
}

/// What a previous version of the same patch leaves for this one.
#[derive(Clone, Debug, Default)]
pub struct ScanWarm<'a> {
    pub frame: Option<PlaneFrame>,
    pub warp: Option<&'a PlaneWarp>,
    pub domain: Option<&'a Domain>,
    pub controls: &'a [DVec3],
    /// Grid coordinates of `controls` (Loop grid).
    pub coords: &'a [(i64, i64)],
    /// The previous version's data points and where their foot points ended.
    pub feet: Option<&'a WarmFeet>,
}

pub fn fit_scan(
    mesh: &TriMesh,
    opts: &FitOptions,
    scan: &ScanOptions,
    warm: Option<&ScanWarm>,
) -> Result<ScanFit, PipelineError> {
    let t0 = Instant::now();
    let cleaned = clean(mesh, &CleanOptions::default());
    let parts = cleaned_components(&cleaned);
    let components = parts.len();
    let part = parts.into_iter().next().unwrap_or_default();
    if part.triangles.is_empty() {
        return Err(PipelineError::Unsupported(
            "no faces left after cleaning".into(),
        ));
    }
    let unsupported = |e: crate::remesh::RemeshError| PipelineError::Unsupported(e.to_string());
    let previous_warp = warm.and_then(|w| w.warp);
    // The plane's frame and warp read only the data triangles: found beside the filling of
    // the holes (a warp from the previous version is reused instead, when it covers).
    let frame_and_warp = || -> Result<_, PipelineError> {
        let frame = match warm.and_then(|w| w.frame) {
            Some(f) => f,
            None => PlaneFrame::fit_least_folds(&part).ok_or_else(|| {
                PipelineError::Unsupported("degenerate patch: no mean normal".into())
            })?,
        };
        let warp = match previous_warp {
            Some(_) => None,
            None => projection_warp(&part, &frame),
        };
        Ok((frame, warp))
    };
    let (filled, framed) = rayon::join(|| fill_holes(&part), frame_and_warp);
    let patch = filled.map_err(unsupported)?;
    // After the topology checks, whose reasons (closed, not disk-like) say more.
    if part.positions.len() < scan.min_component_vertices {
        return Err(PipelineError::Unsupported(format!(
            "the largest component has {} vertices, fewer than min_component_vertices = {}",
            part.positions.len(),
            scan.min_component_vertices
        )));
    }
    let (frame, early_warp) = framed?;
    let map = evened_out(
        planar_map(&patch, &frame).map_err(unsupported)?,
        &patch,
        previous_warp.or(early_warp.as_ref()),
    );
    let plane = &map.plane;
    let edge_length = median_edge_length(&part);
    let parameterization_ms = t0.elapsed().as_secs_f64() * 1e3;

    let t1 = Instant::now();
    let real = patch.real_vertices;
    let data = &part.positions;
    let single_bezier =
        opts.surface == SurfaceKind::Bezier && scan.bezier_layout == BezierLayout::Single;
    // The hole plan decides only what is trimmed afterwards: it runs beside the resampling.
    let plan_hole_trims = || {
        plan_holes(
            &map.mesh,
            patch.real_vertices,
            &patch.hole_loops,
            &part.triangles,
            scan.hole_bridge_edges * edge_length,
        )
    };
    let (hole_plan, resampled) = rayon::join(plan_hole_trims, || -> Result<_, PipelineError> {
        Ok(match single_bezier {
            true => {
                let n0 = scan.lattice.max(1);
                let segments = (n0 as f64) * 2f64.powi(opts.levels.min(60) as i32);
                if n0 > MAX_BEZIER_DEGREE || (segments + 1.0) * (segments + 2.0) / 2.0 > 1e8 {
                    return Err(PipelineError::Unsupported(format!(
                    "Bezier degree {n0} with {} levels: the degree must be at most {MAX_BEZIER_DEGREE} and the resampled lattice ({segments} segments) at most 1e8 points",
                    opts.levels
                )));
                }
                let corners = match warm.and_then(|w| w.domain) {
                    Some(Domain::Triangle { corners })
                        if plane.iter().all(|p| {
                            let (u, v) = barycentric(corners, *p);
                            u >= 0.0 && v >= 0.0 && u + v <= 1.0
                        }) =>
                    {
                        *corners
                    }
                    _ => enclosing_triangle(plane, 0.01),
                };
                let initial =
                    bezier_initial_net(&map.mesh, plane, &corners, n0, opts.levels, opts.inverse);
                (
                    SurfaceModel::Bezier(BezierTriangle::new(n0)),
                    Domain::Triangle { corners },
                    initial,
                    lattice_triangles(n0),
                )
            }
            false => {
                let (spacing, cells) = match (warm.and_then(|w| w.domain), scan.grid_segments) {
                    (_, Some(n)) => (
                        plane_extent(plane).max_element().max(1e-300) / n.max(1) as f64,
                        None,
                    ),
                    (Some(Domain::Grid { spacing }), None) => (*spacing, None),
                    _ => {
                        let target = (scan.target_controls_pct / 100.0 * real as f64).round();
                        let (h, cells) =
                            grid_for_target(plane, &map.mesh.triangles, target as usize);
                        (h, Some(cells))
                    }
                };
                let gf = GridFrame { spacing };
                check_grid_size(plane, spacing, opts.levels)?;
                let cells = cells.unwrap_or_else(|| covered_cells(&gf, plane, &map.mesh.triangles));
                let grid = GridSpline::new(cells);
                let same_domain = warm.filter(|w| w.domain == Some(&Domain::Grid { spacing }));
                let initial = match same_domain.and_then(|w| net_from_warm(&grid, w)) {
                    Some(net) => net,
                    None => {
                        grid_initial_net(&map.mesh, plane, &gf, &grid, opts.levels, opts.inverse)
                    }
                };
                let tris = grid.net_triangles();
                (
                    SurfaceModel::Grid(grid),
                    Domain::Grid { spacing },
                    initial,
                    tris,
                )
            }
        })
    });
    let (model, domain, initial, fairness_tris) = resampled?;
    let resample_ms = t1.elapsed().as_secs_f64() * 1e3;
    let surface = model.as_surface();

    // Warm start: the previous control at the same place of the same domain.
    let mut start = initial.controls.clone();
    let mut reused = 0;
    if let Some(w) = warm.filter(|w| w.domain == Some(&domain)) {
        match &model {
            SurfaceModel::Bezier(_) if w.controls.len() == start.len() => {
                start = w.controls.to_vec();
                reused = start.len();
            }
            SurfaceModel::Grid(grid) if w.coords.len() == w.controls.len() => {
                for (&(i, j), &p) in w.coords.iter().zip(w.controls) {
                    if let Some(k) = grid.control_at(i, j) {
                        start[k as usize] = p;
                        reused += 1;
                    }
                }
            }
            _ => {}
        }
    }

    let mut params: Vec<SurfaceParam> = plane[..real]
        .iter()
        .map(|p| {
            let (u, v) = domain.param(*p);
            SurfaceParam { face: 0, u, v }
        })
        .collect();
    let previous_feet = warm
        .filter(|w| w.domain == Some(&domain))
        .and_then(|w| w.feet);
    if let (Some(feet), SurfaceModel::Grid(grid)) = (previous_feet, &model) {
        params_from_previous(feet, &frame, data, 2.0 * edge_length, &mut params);
        // A parameter the grid does not cover (the previous grid was larger) goes back.
        for (p, mapped) in params.iter_mut().zip(&plane[..real]) {
            if !grid.covers(p.u, p.v) {
                let (u, v) = domain.param(*mapped);
                *p = SurfaceParam { face: 0, u, v };
            }
        }
    }
    let fairness = Collocation::new(umbrella_laplacian(surface.control_count(), &fairness_tris));
    let smoothing = scan.smoothing * data.len() as f64 / surface.control_count().max(1) as f64;
    let prepare_ms = t0.elapsed().as_secs_f64() * 1e3;

    let t2 = Instant::now();
    // Built on first use: a warm start the previous surface already fits needs no solve.
    let stencils = std::cell::OnceCell::new();
    let grid_stencils = || {
        stencils
            .get_or_init(|| match &model {
                SurfaceModel::Grid(grid) => Some(GridStencils::new(grid, &fairness, smoothing)),
                _ => None,
            })
            .as_ref()
    };
    // Per data point, the tangential share of the distance rounds: stiffer near the data's
    // edges (outer rim and holes).
    let edge_shares = || -> Vec<f64> {
        let rims: Vec<&[u32]> = std::iter::once(patch.outer.as_slice())
            .chain(patch.hole_loops.iter().map(|h| h.as_slice()))
            .collect();
        let radius = EDGE_BAND_SPACINGS * control_spacing(&domain, scan.lattice);
        near_edges(&part, &plane[..real], &rims, radius)
            .iter()
            .map(|&near| match near {
                true => scan.correction_tangential_edge,
                false => scan.correction_tangential,
            })
            .collect()
    };
    let mut early_band = None;
    // A warm start that covers the domain already sits near the fit: its foot points are
    // better parameters than the projection, so it goes straight to the correction rounds.
    let warm_enough = scan.correction_rounds > 0
        && scan.correction == Correction::Distance
        && reused as f64 >= 0.9 * start.len() as f64;
    let mut warm_fits_already = false;
    let (mut outcome, mut feet) = if warm_enough {
        let feet = foot_points(surface, None, &start, data, &mut params);
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
        let share = (start.len() as f64 / data.len().max(1) as f64).min(0.5);
        let fresh_noise = ((1.0 + share) / (1.0 - share)).sqrt();
        warm_fits_already = previous_rms > 0.0
            && rms(&feet.distances())
                <= (1.0 + scan.correction_min_gain) * fresh_noise * previous_rms;
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
        (outcome, feet)
    } else {
        // The assembly plan and the first fit's rows are built side by side, and the
        // rounds' edge band beside the first fit: none of them needs another.
        let first_rows = match (&model, opts.method) {
            (SurfaceModel::Grid(grid), Method::Cg | Method::Direct) => {
                let (built, rows) = GridStencils::with_rows(grid, &fairness, smoothing, &params);
                let _ = stencils.set(Some(built));
                rows
            }
            _ => None,
        };
        let plan = grid_stencils();
        let params = &mut params;
        let (first, band) = rayon::join(
            || -> Result<_, PipelineError> {
                let outcome = match opts.method {
                    Method::Cg | Method::Direct => assembled_fit(
                        surface, plan, params, data, &fairness, smoothing, start, opts, first_rows,
                    ),
                    Method::Pia | Method::Lspia => {
                        run_fit(surface, params, data, &fairness, smoothing, start, opts)?
                    }
                };
                let feet = foot_points(surface, plan, &outcome.controls, data, params);
                Ok((outcome, feet))
            },
            || (scan.correction_rounds > 0).then(edge_shares),
        );
        early_band = band;
        first?
    };
    let mut steps = outcome.steps.clone();
    let mut errors = feet.distances();
    let mut correction_rms = vec![rms(&errors)];
    // Foot-point distances never exceed the distances at the parameters, so a budget met by
    // the first fit holds geometrically too: no correction needed.
    let rounds = if outcome.status == FitStatus::Met || warm_fits_already {
        0
    } else {
        scan.correction_rounds
    };
    let tangential: Vec<f64> = match rounds {
        0 => Vec::new(),
        _ => early_band.unwrap_or_else(edge_shares),
    };
    let round = DistanceRound {
        surface,
        stencils: if rounds > 0 { grid_stencils() } else { None },
        data,
        fairness: &fairness,
        smoothing,
        tangential: &tangential,
        max_iterations: opts.budget.max_iterations,
    };
    for _ in 0..rounds {
        let (controls, cg_steps) = match scan.correction {
            Correction::Parameters => {
                let next = run_fit(
                    surface,
                    &params,
                    data,
                    &fairness,
                    smoothing,
                    outcome.controls.clone(),
                    opts,
                )?;
                let n = next.steps.len().saturating_sub(1);
                (next.controls, n)
            }
            Correction::Distance => round.solve(
                &params,
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
            t2.elapsed().as_secs_f64() * 1e3,
        );
        let met = opts.budget.met(&stats);
        if let Some(hook) = opts.on_step {
            hook(&stats);
        }
        steps.push(stats);
        outcome.controls = controls;
        params = trial;
        feet = trial_feet;
        errors = e;
        correction_rms.push(rms(&errors));
        if met {
            outcome.status = FitStatus::Met;
            break;
        }
        // The budget's time cap holds for the rounds as for the steps of a fit.
        let elapsed_ms = t2.elapsed().as_secs_f64() * 1e3;
        if opts
            .budget
            .max_time_ms
            .is_some_and(|m| elapsed_ms >= m as f64)
        {
            outcome.status = FitStatus::Capped;
            break;
        }
        // Rounds converge: once one gains under 2 % the next would gain less (a warm start
        // from the previous version's surface usually stops here after one round).
        if after > (1.0 - scan.correction_min_gain) * before {
            outcome.status = FitStatus::Stalled;
            break;
        }
    }
    outcome.steps = steps;
    outcome.iterations = outcome.steps.len().saturating_sub(1);
    let fit_ms = t2.elapsed().as_secs_f64() * 1e3;

    let loop_params = |rim: &[u32]| -> Vec<(f64, f64)> {
        rim.iter()
            .map(|&v| {
                params
                    .get(v as usize)
                    .map_or_else(|| domain.param(plane[v as usize]), |q| (q.u, q.v))
            })
            .collect()
    };
    let trim = loop_params(&patch.outer);
    let hole_trims = patch
        .hole_loops
        .iter()
        .zip(&hole_plan.bridged)
        .filter(|(_, bridged)| !**bridged)
        .map(|(rim, _)| loop_params(rim))
        .chain(
            hole_plan
                .wide_triangles
                .iter()
                .map(|&k| loop_params(&map.mesh.triangles[k])),
        )
        .collect();
    let mapped_params = plane
        .iter()
        .map(|p| {
            let (u, v) = domain.param(*p);
            DVec2::new(u, v)
        })
        .collect();
    let degree = match &model {
        SurfaceModel::Bezier(b) => b.degree,
        SurfaceModel::Grid(_) if opts.surface == SurfaceKind::Bezier => 4,
        SurfaceModel::Grid(_) | SurfaceModel::Mesh(_) => 0,
    };
    Ok(ScanFit {
        fit: PatchFit {
            surface: opts.surface,
            degree,
            model,
            controls: outcome.controls.clone(),
            data: data.clone(),
            params,
            outcome,
            geometric_errors: errors,
            warm_start: reused > 0,
            prepare_ms,
            fit_ms,
        },
        components,
        kept_vertices: real,
        holes: patch.holes,
        frame,
        domain,
        map_method: map.method,
        folds_projected: map.folds_projected,
        warp: map.warp.clone(),
        folds_warped: map.folds_warped,
        filled: map.mesh,
        mapped_params,
        near_fold: map.near_fold,
        initial,
        trim,
        hole_plan,
        hole_trims,
        correction_rms,
        parameterization_ms,
        resample_ms,
        reused_controls: reused,
    })
}

/// Median edge length of a mesh, from at most ~30k edges spread over it: the data's
/// sample spacing, the unit in which hole widths are judged.
fn median_edge_length(mesh: &TriMesh) -> f64 {
    let stride = (mesh.triangles.len() / 10_000).max(1);
    let mut lengths: Vec<f64> = mesh
        .triangles
        .iter()
        .step_by(stride)
        .flat_map(|t| {
            let p = t.map(|v| mesh.positions[v as usize]);
            [
                (p[1] - p[0]).length(),
                (p[2] - p[1]).length(),
                (p[0] - p[2]).length(),
            ]
        })
        .filter(|l| l.is_finite())
        .collect();
    if lengths.is_empty() {
        return 0.0;
    }
    let mid = lengths.len() / 2;
    *lengths.select_nth_unstable_by(mid, f64::total_cmp).1
}

/// Cells of the grid's bounding box times the 4^levels resampling triangles of each: a
/// bound on the memory the grid path takes, checked before anything is allocated (a tiny
/// spacing from a degenerate patch or a huge `--lattice` would otherwise exhaust memory).
const MAX_RESAMPLED_TRIANGLES: f64 = 2e8;

/// Beyond this the single patch is neither a sensible model of a scan nor cheap to evaluate.
const MAX_BEZIER_DEGREE: usize = 96;

fn check_grid_size(plane: &[DVec2], spacing: f64, levels: usize) -> Result<(), PipelineError> {
    let extent = plane_extent(plane);
    let cells = 2.0 * (extent.x / spacing + 3.0) * (extent.y / (0.866 * spacing) + 3.0);
    let triangles = cells * 4f64.powi(levels.min(30) as i32);
    if !(spacing > 0.0 && triangles.is_finite() && triangles <= MAX_RESAMPLED_TRIANGLES) {
        return Err(PipelineError::Unsupported(format!(
            "grid too fine for this patch: spacing {spacing:e} over a {:e} x {:e} map with {levels} levels (about {triangles:.1e} resampling triangles, limit {MAX_RESAMPLED_TRIANGLES:e})",
            extent.x, extent.y
        )));
    }
    Ok(())
}
