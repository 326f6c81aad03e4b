//! The worker's core: a mesh in, a fitted triangular surface out. Pure: no file IO; the CLI
//! and the daemon write what it returns.
//!
//! One input takes one of two paths:
//! - [`subdivided`]: the input has Loop subdivision connectivity, so inverse subdivision
//!   gives the control net and every vertex its exact parameter;
//! - [`scan`]: any disk-like scan: cleaned, mapped to the plane, fitted on a grid (or one
//!   Bezier patch) with foot-point correction.
//!
//! [`worker`] chooses the path, applies the configuration and the component policy;
//! [`output`] turns a fit into surface.json, a tessellation and GLB bytes. A third path for
//! whole (closed) objects belongs beside the two as `pipeline/object/`.

#![warn(missing_docs)]

mod collocation;
mod coverage;
mod error;
mod geometric;
pub mod measure;
pub mod merge;
mod names;
pub mod object;
pub mod object_session;
pub mod output;
pub mod scan;
pub mod scattered;
pub mod subdivided;
mod welded_lattice;
pub mod worker;

pub use collocation::collocation;
pub use error::{NoSubdivision, PipelineError};
pub use names::UnknownName;

use crate::fit::{Budget, FitOutcome, Method, StepHook};
use crate::mesh::inverse::InverseMethod;
use crate::surface::bezier::BezierTriangle;
use crate::surface::bpatch::BPatch;
use crate::surface::dms::DmsSpline;
use crate::surface::grid_spline::GridSpline;
use crate::surface::loop_limit::LoopLimitSurface;
use crate::surface::{SurfaceParam, TriSurface};
use glam::DVec3;
use std::sync::Arc;

/// The kind of surface fitted.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum SurfaceKind {
    /// Triangular Bezier: one patch of a lattice, or one quartic patch per grid cell.
    Bezier,
    /// Loop: the limit surface of a control net (a grid's box splines on scans).
    Loop,
    /// Seidel's B-patch: one polynomial over one domain triangle, knot sequences per corner.
    Bpatch,
    /// DMS triangular B-spline: simplex splines over a domain triangulation, a knot cloud
    /// per domain vertex.
    Dms,
}

names::named!(SurfaceKind {
    Bezier => "bezier",
    Loop => "loop",
    Bpatch => "bpatch",
    Dms => "dms",
});

/// What both paths share: the surface, the inverse subdivision and the solver's budget.
#[derive(Clone)]
pub struct FitOptions<'a> {
    /// The kind of surface fitted.
    pub surface: SurfaceKind,
    /// Levels of inverse subdivision.
    pub levels: usize,
    /// The solver.
    pub method: Method,
    /// How inverse subdivision finds the coarse net.
    pub inverse: InverseMethod,
    /// When the solver stops.
    pub budget: Budget,
    /// Called after every fitting step (and every correction round of a scan): progress
    /// display; `None` costs nothing.
    pub on_step: Option<StepHook<'a>>,
}

/// The surface model a fit lives on; `PatchFit` carries it for evaluation downstream.
#[derive(Clone, Debug)]
pub enum SurfaceModel {
    /// One triangular Bezier patch over the reference triangle.
    Bezier(BezierTriangle),
    /// A regular three-direction grid of box splines (Loop, or per-cell quartic Bezier).
    Grid(GridSpline),
    /// The exact Loop limit surface of an input's own coarse net (subdivided inputs).
    Mesh(Arc<LoopLimitSurface>),
    /// A B-patch over one domain triangle of the plane (parameters barycentric in it).
    BPatch(Arc<BPatch>),
    /// A DMS spline over a triangulation of the plane (parameter faces: its triangles).
    Dms(Arc<DmsSpline>),
}

impl SurfaceModel {
    /// The model as an evaluable surface.
    pub fn as_surface(&self) -> &dyn TriSurface {
        match self {
            SurfaceModel::Bezier(b) => b,
            SurfaceModel::Grid(g) => g,
            SurfaceModel::Mesh(m) => m.as_ref(),
            SurfaceModel::BPatch(b) => b.as_ref(),
            SurfaceModel::Dms(d) => d.as_ref(),
        }
    }
}

/// A fitted patch: the model, its controls, the data and their parameters, and how the fit
/// went.
#[derive(Clone, Debug)]
pub struct PatchFit {
    /// The kind of surface fitted.
    pub surface: SurfaceKind,
    /// Bezier degree (0 for a Loop grid).
    pub degree: usize,
    /// The surface model the controls belong to.
    pub model: SurfaceModel,
    /// Control points in the model's order (lattice order for Bezier).
    pub controls: Vec<DVec3>,
    /// The data points fitted.
    pub data: Vec<DVec3>,
    /// Each data point's final parameter.
    pub params: Vec<SurfaceParam>,
    /// The solver's outcome (steps, status).
    pub outcome: FitOutcome,
    /// Each data point's distance to its foot point on the surface.
    pub geometric_errors: Vec<f64>,
    /// Whether the fit started from a previous version's controls.
    pub warm_start: bool,
    /// Time before the solve, in milliseconds.
    pub prepare_ms: f64,
    /// Time of the solve (and correction rounds), in milliseconds.
    pub fit_ms: f64,
}

impl PatchFit {
    /// The largest geometric error.
    pub fn geometric_max(&self) -> f64 {
        self.geometric_errors.iter().cloned().fold(0.0, f64::max)
    }
    /// The RMS of the geometric errors.
    pub fn geometric_rms(&self) -> f64 {
        let n = self.geometric_errors.len().max(1) as f64;
        (self.geometric_errors.iter().map(|e| e * e).sum::<f64>() / n).sqrt()
    }
}
