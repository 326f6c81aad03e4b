//! The surface a planar-domain fit starts from: a new domain, or the previous version's
//! domain and controls (`ScatteredWarm`, kept in `WarmStart::scattered`).
//!
//! Warm rules: the previous domain is reused whole while it still holds every new data
//! point (its controls are the start). A DMS domain the data outgrew is laid out again on
//! the previous grid spacing (the grid is anchored at the reused frame's origin, so the old
//! triangles reappear with the same vertices): their controls are copied, new triangles
//! start from the previous surface where it reaches and from the plane of the data beyond,
//! unless the old spacing over the new data would exceed the control budget by more than
//! `WARM_BUDGET_SLACK`. A B-patch whose triangle no longer holds the data, or a degree
//! change, starts cold.

use super::domain::{dms_domain, grid_triangulation, manifold_cover, GridTriangulation};
use super::error::ScatteredError;
use crate::pipeline::scan::domain::enclosing_triangle;
use crate::pipeline::worker::FitConfig;
use crate::pipeline::{PipelineError, SurfaceKind, SurfaceModel};
use crate::surface::bezier::lattice_len;
use crate::surface::bpatch::{BPatch, BPatchRecord};
use crate::surface::dms::record::DmsRecord;
use crate::surface::dms::{DmsSpline, KnotRule, PlanarSurface};
use crate::surface::TriSurface;
use glam::{DVec2, DVec3};
use rustc_hash::FxHashMap;
use std::sync::Arc;

/// What a B-patch or DMS fit leaves for the next version of its patch (the plane frame,
/// warp and data feet go into `WarmStart`'s own fields).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum ScatteredWarm {
    /// A DMS spline: its record (controls included) and the grid spacing of its domain.
    Dms {
        /// The fitted spline as surface.json holds it.
        record: DmsRecord,
        /// Grid spacing of the domain in the plane.
        spacing: f64,
    },
    /// A B-patch: its record (controls included).
    Bpatch {
        /// The fitted patch as surface.json holds it.
        record: BPatchRecord,
    },
}

impl ScatteredWarm {
    /// The warm state of a fitted planar model with `controls`.
    pub(crate) fn of(
        model: &SurfaceModel,
        controls: &[DVec3],
        spacing: Option<f64>,
    ) -> Option<Self> {
        match model {
            SurfaceModel::Dms(d) => Some(ScatteredWarm::Dms {
                record: DmsRecord::new(d, controls),
                spacing: spacing.unwrap_or(0.0),
            }),
            SurfaceModel::BPatch(b) => Some(ScatteredWarm::Bpatch {
                record: BPatchRecord::new(b, controls),
            }),
            _ => None,
        }
    }
}

/// A warm DMS grid may have this many times the controls the budget asks for before the
/// domain is laid out for the budget instead (as the scan path's warm grids).
const WARM_BUDGET_SLACK: f64 = 1.25;

/// Margin of the B-patch's triangle around the map, as a fraction of its size.
const ENCLOSING_MARGIN: f64 = 0.01;

/// The surface to fit and where its controls start.
pub(super) struct Built {
    pub(super) model: SurfaceModel,
    /// Per control, the start taken from the previous version (`None`: start from the
    /// plane of the data); `None` altogether: a cold start.
    pub(super) controls: Option<Vec<Option<DVec3>>>,
    /// Controls taken from the previous version.
    pub(super) reused: usize,
    /// DMS: the domain's grid spacing.
    pub(super) spacing: Option<f64>,
    /// Why a previous version given was not used.
    pub(super) cold_because: Option<String>,
}

/// The mapped patch: every vertex's plane point (data first, then hole centres) and its
/// triangles.
pub(super) struct MapView<'a> {
    /// Plane points of the data (the first vertices of `plane`).
    pub(super) data: &'a [DVec2],
    /// Plane points of every vertex of `triangles`.
    pub(super) plane: &'a [DVec2],
    /// The mapped patch's triangles.
    pub(super) triangles: &'a [[u32; 3]],
}

/// The surface of `kind` over the map, from `previous` where the rules above allow.
pub(super) fn build_surface(
    kind: SurfaceKind,
    cfg: &FitConfig,
    map: &MapView,
    previous: Option<&ScatteredWarm>,
) -> Result<Built, PipelineError> {
    match kind {
        SurfaceKind::Dms => build_dms(cfg, map, previous),
        SurfaceKind::Bpatch => build_bpatch(cfg, map, previous),
        other => Err(ScatteredError::NotPlanarKind(other.name()).into()),
    }
}

fn covers(surface: &dyn PlanarSurface, plane: &[DVec2]) -> bool {
    plane.iter().all(|x| surface.locate(*x).is_some())
}

fn build_bpatch(
    cfg: &FitConfig,
    map: &MapView,
    previous: Option<&ScatteredWarm>,
) -> Result<Built, PipelineError> {
    let degree = cfg.bpatch.degree;
    let mut cold_because = None;
    if let Some(ScatteredWarm::Bpatch { record }) = previous {
        match record.surface() {
            Ok((patch, controls)) if patch.degree() == degree && covers(&patch, map.data) => {
                return Ok(Built {
                    reused: controls.len(),
                    controls: Some(controls.into_iter().map(Some).collect()),
                    model: SurfaceModel::BPatch(Arc::new(patch)),
                    spacing: None,
                    cold_because: None,
                });
            }
            Ok((patch, _)) if patch.degree() != degree => {
                cold_because = Some(format!("degree: {} before, {degree} now", patch.degree()));
            }
            Ok(_) => cold_because = Some("domain: the data left the previous triangle".into()),
            Err(e) => cold_because = Some(format!("previous patch refused: {e}")),
        }
    }
    let corners = enclosing_triangle(map.plane, ENCLOSING_MARGIN);
    let patch =
        BPatch::outward(degree, corners, cfg.bpatch.knot_spread).map_err(ScatteredError::BPatch)?;
    Ok(Built {
        model: SurfaceModel::BPatch(Arc::new(patch)),
        controls: None,
        reused: 0,
        spacing: None,
        cold_because,
    })
}

fn dms_spline(cfg: &FitConfig, tri: GridTriangulation) -> Result<DmsSpline, PipelineError> {
    DmsSpline::new(
        tri.vertices,
        tri.triangles,
        cfg.dms.degree,
        KnotRule::Perturbed {
            spread: cfg.dms.knot_spread,
        },
    )
    .map_err(|e| ScatteredError::Dms(e).into())
}

fn build_dms(
    cfg: &FitConfig,
    map: &MapView,
    previous: Option<&ScatteredWarm>,
) -> Result<Built, PipelineError> {
    let degree = cfg.dms.degree;
    let target = (cfg.scan.target_controls_pct / 100.0 * map.data.len() as f64).round() as usize;
    let mut cold_because = None;
    if let Some(ScatteredWarm::Dms { record, spacing }) = previous {
        match record.surface() {
            Ok((old, controls)) if old.degree() == degree => {
                if covers(&old, map.data) {
                    return Ok(Built {
                        reused: controls.len(),
                        controls: Some(controls.into_iter().map(Some).collect()),
                        model: SurfaceModel::Dms(Arc::new(old)),
                        spacing: Some(*spacing),
                        cold_because: None,
                    });
                }
                let cells = manifold_cover(*spacing, map.plane, map.triangles);
                let tri = grid_triangulation(*spacing, &cells)?;
                let limit = (WARM_BUDGET_SLACK * target as f64).ceil() as usize;
                let count = tri.triangles.len() * lattice_len(degree);
                if count <= limit {
                    let spacing = tri.spacing;
                    let spline = dms_spline(cfg, tri)?;
                    let start = transfer(&old, &controls, &spline);
                    return Ok(Built {
                        reused: start.iter().filter(|c| c.is_some()).count(),
                        controls: Some(start),
                        model: SurfaceModel::Dms(Arc::new(spline)),
                        spacing: Some(spacing),
                        cold_because: None,
                    });
                }
                cold_because = Some(format!(
                    "budget: the previous spacing gives {count} controls over the new data, at most {limit}"
                ));
            }
            Ok((old, _)) => {
                cold_because = Some(format!("degree: {} before, {degree} now", old.degree()));
            }
            Err(e) => cold_because = Some(format!("previous spline refused: {e}")),
        }
    }
    let tri = dms_domain(map.plane, map.triangles, degree, target)?;
    let spacing = tri.spacing;
    Ok(Built {
        model: SurfaceModel::Dms(Arc::new(dms_spline(cfg, tri)?)),
        controls: None,
        reused: 0,
        spacing: Some(spacing),
        cold_because,
    })
}

/// Exact bits of a triangle's corners: the same grid vertex computed by the same formula
/// from the same spacing gives the same key.
fn corner_key(corners: [DVec2; 3]) -> [u64; 6] {
    let c = corners.map(|p| [p.x.to_bits(), p.y.to_bits()]);
    [c[0][0], c[0][1], c[1][0], c[1][1], c[2][0], c[2][1]]
}

/// Controls of `new` from `old`: a triangle both have keeps its controls; any other control
/// takes the old surface at its Greville site where the old domain reaches (`None`
/// beyond: the caller starts those from the plane of the data).
fn transfer(old: &DmsSpline, controls: &[DVec3], new: &DmsSpline) -> Vec<Option<DVec3>> {
    let per = lattice_len(new.degree());
    let corners = |s: &DmsSpline, t: &[u32; 3]| t.map(|v| s.vertices()[v as usize]);
    let old_index: FxHashMap<[u64; 6], usize> = old
        .triangles()
        .iter()
        .enumerate()
        .map(|(k, t)| (corner_key(corners(old, t)), k))
        .collect();
    let sites = new.greville_sites();
    let eval = old.evaluator(controls);
    let mut start = Vec::with_capacity(new.control_count());
    for (k, t) in new.triangles().iter().enumerate() {
        match old_index.get(&corner_key(corners(new, t))) {
            Some(&o) => start.extend(controls[o * per..(o + 1) * per].iter().map(|c| Some(*c))),
            None => start.extend(
                sites[k * per..(k + 1) * per]
                    .iter()
                    .map(|s| old.locate(*s).map(|p| eval(p).position)),
            ),
        }
    }
    start
}
