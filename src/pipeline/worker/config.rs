//! What the worker is told. `FitConfig` mirrors the daemon's `[fit]` table and its
//! sub-tables (`[fit.budget]`, `[fit.scan]`, `[fit.correction]`, `[fit.components]`,
//! `[fit.dms]`, `[fit.bpatch]`); the
//! CLI's flags map onto the same structs. Sections are grouped by what they shape: the
//! solver's stopping rule, the scan's layout, the rounds after the first fit, and which
//! pieces of an input get a surface.

use crate::fit::{Budget, Method};
use crate::mesh::inverse::InverseMethod;
use crate::pipeline::scan::components::ComponentMode;
use crate::pipeline::scan::{CorrectionConfig, ScanConfig};
use crate::pipeline::scattered::{BPatchConfig, DmsConfig};
use crate::pipeline::SurfaceKind;
use crate::TriMesh;

/// `fit.domain`: which path fits an input without subdivision connectivity.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Domain {
    /// Disk-like scans on a grid over their planar map; closed, higher-genus and nearly
    /// closed inputs (the disk map cannot take them) on a control mesh.
    #[default]
    Auto,
    /// Always the grid over the planar map (what every scan took before whole objects).
    Grid,
    /// Always a control mesh simplified from the data: any input, subdivided or not.
    Mesh,
}

crate::pipeline::names::named!(Domain {
    Auto => "auto",
    Grid => "grid",
    Mesh => "mesh",
});

/// Everything the worker needs: the fit, and the one output setting it applies itself.
#[derive(Clone, Debug, serde::Serialize)]
pub struct WorkerConfig {
    /// The `[fit]` table.
    pub fit: FitConfig,
    /// `[output] tessellation`: segments per side of the shown surface in the GLB (it does
    /// not change the fit).
    pub tessellation: usize,
}

/// The default tessellation of the shown surface.
pub const DEFAULT_TESSELLATION: usize = 128;

impl Default for WorkerConfig {
    fn default() -> Self {
        Self {
            fit: FitConfig::default(),
            tessellation: DEFAULT_TESSELLATION,
        }
    }
}

/// `[fit]`: everything that shapes a fit.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FitConfig {
    /// The kind of surface fitted.
    pub surface: SurfaceKind,
    /// Which path fits inputs without subdivision connectivity (`mesh`: every input).
    #[serde(default)]
    pub domain: Domain,
    /// Levels of inverse subdivision.
    pub levels: usize,
    /// Inputs with subdivision connectivity: when the budget is not met, refit with one
    /// level of inverse subdivision less (4x control points), down to this floor.
    #[serde(default = "default_min_levels")]
    pub min_levels: usize,
    /// The solver.
    pub method: Method,
    /// How inverse subdivision finds the coarse net.
    pub inverse: InverseMethod,
    /// `[fit.budget]`: when the solver stops.
    #[serde(default)]
    pub budget: BudgetConfig,
    /// `[fit.scan]`: layout and weights of scans without subdivision connectivity.
    #[serde(default)]
    pub scan: ScanConfig,
    /// `[fit.correction]`: the scans' foot-point correction rounds.
    #[serde(default)]
    pub correction: CorrectionConfig,
    /// `[fit.components]`: which pieces of a scan get a surface.
    #[serde(default)]
    pub components: ComponentsConfig,
    /// `[fit.dms]`: `surface = "dms"`: degree and knot clouds.
    #[serde(default)]
    pub dms: DmsConfig,
    /// `[fit.bpatch]`: `surface = "bpatch"`: degree and knots.
    #[serde(default)]
    pub bpatch: BPatchConfig,
    /// Whole objects: data edges whose faces meet at more than this angle (degrees between
    /// their normals) become crease edges of the surface; 0 turns creases off.
    #[serde(default = "default_crease_angle_deg")]
    pub crease_angle_deg: f64,
    /// Whole objects: a shallower data edge (over 15 degrees) is a crease too where it turns
    /// this many times as much as the edges beside it, in a feature line of its own
    /// (`mesh::crease`); 0 turns this rule off.
    #[serde(default = "default_crease_relative_ratio")]
    pub crease_relative_ratio: f64,
    /// Whole objects with sharp edges: also fit the faceted surface (every control edge a
    /// crease, so the surface is the control mesh) at the same control count, and keep it
    /// where it is nearer the data (`pipeline::object::faceted`); false keeps the smooth
    /// surface always.
    #[serde(default = "default_faceted")]
    pub faceted: bool,
}

fn default_faceted() -> bool {
    true
}

fn default_min_levels() -> usize {
    1
}

/// Machined edges are 90 degrees or more; on smooth scans noise tilts neighbouring faces by
/// up to about 50 degrees in places (see `mesh::crease` for the measurements), so 60.
pub const DEFAULT_CREASE_ANGLE_DEG: f64 = 60.0;

fn default_crease_angle_deg() -> f64 {
    DEFAULT_CREASE_ANGLE_DEG
}

/// See `mesh::crease` for why 6.
pub const DEFAULT_CREASE_RELATIVE_RATIO: f64 = 6.0;

fn default_crease_relative_ratio() -> f64 {
    DEFAULT_CREASE_RELATIVE_RATIO
}

impl Default for FitConfig {
    fn default() -> Self {
        Self {
            surface: SurfaceKind::Bezier,
            domain: Domain::Auto,
            levels: 2,
            min_levels: default_min_levels(),
            method: Method::Cg,
            inverse: InverseMethod::Exact,
            budget: BudgetConfig::default(),
            scan: ScanConfig::default(),
            correction: CorrectionConfig::default(),
            components: ComponentsConfig::default(),
            dms: DmsConfig::default(),
            bpatch: BPatchConfig::default(),
            crease_angle_deg: DEFAULT_CREASE_ANGLE_DEG,
            crease_relative_ratio: DEFAULT_CREASE_RELATIVE_RATIO,
            faceted: default_faceted(),
        }
    }
}

/// `[fit.budget]`: the error targets and caps of a fit. With no target set the fit aims at
/// max error <= tolerance.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct BudgetConfig {
    /// Fitting steps at most.
    pub max_iterations: usize,
    /// Absolute tolerance; when absent, `tolerance_rel` times the bounding-box diagonal.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub tolerance: Option<f64>,
    /// Tolerance as a fraction of the bounding-box diagonal.
    pub tolerance_rel: f64,
    /// Target: largest error.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub max_error: Option<f64>,
    /// Target: mean error.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub mean_error: Option<f64>,
    /// Target: percentage of points within the tolerance.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub within_tolerance_pct: Option<f64>,
    /// Cap on the fitting time.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub max_time_ms: Option<u64>,
}

impl Default for BudgetConfig {
    fn default() -> Self {
        Self {
            max_iterations: 100,
            tolerance: None,
            tolerance_rel: 1e-3,
            max_error: None,
            mean_error: None,
            within_tolerance_pct: None,
            max_time_ms: None,
        }
    }
}

impl BudgetConfig {
    /// The solver's budget with the tolerance resolved against the mesh's size; with no
    /// target set the fit aims at max error <= tolerance.
    pub(crate) fn resolve(&self, mesh: &TriMesh) -> Budget {
        let tolerance = self
            .tolerance
            .unwrap_or(self.tolerance_rel * mesh.bounds_diagonal());
        let mut budget = Budget {
            tolerance,
            max_error: self.max_error,
            mean_error: self.mean_error,
            within_tolerance_pct: self.within_tolerance_pct,
            max_iterations: self.max_iterations,
            max_time_ms: self.max_time_ms,
            ..Budget::default()
        };
        if !budget.has_targets() {
            budget.max_error = Some(tolerance);
        }
        budget
    }
}

/// `[fit.components]`: which components of a scan get a surface.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ComponentsConfig {
    /// The largest component, or every kept component as its own surface.
    pub mode: ComponentMode,
    /// Components with fewer vertices are not fitted (the largest too: the input is then
    /// refused).
    pub min_vertices: usize,
    /// `mode = "all"`: components with fewer vertices than this fraction of the largest are
    /// not fitted.
    pub min_fraction: f64,
}

impl Default for ComponentsConfig {
    fn default() -> Self {
        Self {
            mode: ComponentMode::Largest,
            min_vertices: 100,
            min_fraction: 0.05,
        }
    }
}
