//! The scan path's options and results: shared by its stages and by the warm start, so
//! that none of them imports another for a type.

use super::cold_start::ColdStart;
use super::domain::{barycentric, GridFrame, InitialNet};
use super::feet::WarmFeet;
use super::holes::HolePlan;
use crate::pipeline::names::named;
use crate::pipeline::PatchFit;
use crate::remesh::planar::{MapMethod, PlaneFrame};
use crate::remesh::warp::PlaneWarp;
use crate::TriMesh;
use glam::{DVec2, DVec3};

/// What `bezier` means on a scan.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
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

named!(BezierLayout {
    Patches => "patches",
    Single => "single",
});

/// What a correction round refits after moving the parameters to the foot points.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Correction {
    /// Point-to-point least squares again (classic parameter correction).
    Parameters,
    /// Squared-distance minimisation (point-to-plane with a tangential share).
    #[default]
    Distance,
}

named!(Correction {
    Parameters => "parameters",
    Distance => "distance",
});

/// `[fit.scan]`: how a scan without subdivision connectivity is laid out and weighted.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ScanConfig {
    /// Loop grids: control points as a percentage of the data points.
    pub target_controls_pct: f64,
    /// Loop grids: cells across the patch's longer side; when absent the spacing follows
    /// `target_controls_pct`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub grid_segments: Option<usize>,
    /// `bezier`: one quartic patch per grid cell, or one patch of degree `lattice`.
    pub bezier_layout: BezierLayout,
    /// `bezier` with the `single` layout: the degree (control-net segments per side).
    pub lattice: usize,
    /// Fairness weight relative to the data: s = smoothing * data points / control points.
    pub smoothing: f64,
    /// Holes whose bridging radius (largest distance from the hole's flat fill to its rim)
    /// exceeds this many median edge lengths of the data are trimmed out of the surface,
    /// narrower ones bridged; data triangles wider than that are trimmed too.
    pub hole_bridge_edges: f64,
    /// Whole objects: where the surface strays past 0.5 % of the diagonal after its
    /// repair and a decimation of as many vertices strays too, the object is fitted again
    /// at twice the controls the fit before spent, at most this many times, and the least
    /// straying fit kept (0: the budget holds). Object
    /// sessions never do (their updates are refitted view by view).
    pub stray_budget_steps: usize,
}

impl Default for ScanConfig {
    fn default() -> Self {
        Self {
            target_controls_pct: 5.0,
            grid_segments: None,
            bezier_layout: BezierLayout::Patches,
            lattice: 16,
            smoothing: 1e-5,
            hole_bridge_edges: 1.5,
            stray_budget_steps: crate::pipeline::object::STRAY_BUDGET_STEPS,
        }
    }
}

/// `[fit.correction]`: the foot-point correction rounds after a scan's first fit.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CorrectionConfig {
    /// Rounds after the first fit (at most; see `min_gain`).
    pub rounds: usize,
    /// What a round refits.
    pub kind: Correction,
    /// Rounds stop once one lowers the geometric RMS by less than this fraction.
    pub min_gain: f64,
    /// Share of the point-to-point term beside the point-to-plane one in distance rounds,
    /// inside the data: smaller lets the surface slide more freely, so rounds converge
    /// faster and further (lower RMS).
    pub tangential: f64,
    /// The same share within half a control spacing of the data's edges (outer rim and
    /// holes): sliding there pulls the surface past the last points (higher maximum
    /// errors), so it stays stiffer.
    pub tangential_edge: f64,
    /// Whole objects: above 0, the rounds minimise the squared distance with its curvature
    /// term (SDM) and this tangential share where the curvature gives none, in place of
    /// `tangential` (`pipeline::object::CURVATURE_FLOOR` says what it measured); 0: off.
    pub curvature_floor: f64,
}

impl CorrectionConfig {
    /// `curvature_floor` as the whole-object fit takes it (`None`: off).
    pub fn curvature_floor(&self) -> Option<f64> {
        (self.curvature_floor > 0.0).then_some(self.curvature_floor)
    }
}

impl Default for CorrectionConfig {
    fn default() -> Self {
        Self {
            rounds: 8,
            kind: Correction::Distance,
            min_gain: 0.04,
            tangential: 0.005,
            tangential_edge: 0.02,
            curvature_floor: 0.0,
        }
    }
}

/// Everything the scan path is told besides the shared `FitOptions`.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct ScanOptions {
    /// Layout and weights.
    pub config: ScanConfig,
    /// The correction rounds.
    pub correction: CorrectionConfig,
    /// The largest component must have at least this many vertices.
    pub min_component_vertices: usize,
    /// Refuse a disk map that squeezes much of the surface (`RemeshError::Distorted`),
    /// for a caller that has a better path for it.
    pub refuse_distorted: bool,
}

/// Where the parameters live, kept for warm starts and written to surface.json.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum Domain {
    /// Barycentric coordinates of the plane triangle `corners` (corner 0 carries u,
    /// corner 1 carries v).
    Triangle {
        /// The triangle's corners in the plane of the map.
        corners: [DVec2; 3],
    },
    /// Grid coordinates of the grid of this spacing anchored at the frame's origin.
    Grid {
        /// Distance between neighbouring grid vertices in the plane of the map.
        spacing: f64,
    },
}

impl Domain {
    /// The surface parameter of a plane point.
    pub fn param(&self, p: DVec2) -> (f64, f64) {
        match self {
            Domain::Triangle { corners } => barycentric(corners, p),
            Domain::Grid { spacing } => GridFrame { spacing: *spacing }.to_grid(p),
        }
    }
}

/// What a previous version of the same patch leaves for this one.
#[derive(Clone, Debug, Default)]
pub(crate) struct ScanWarm<'a> {
    /// The plane the previous version was mapped to.
    pub frame: Option<PlaneFrame>,
    /// The previous version's warp of that plane.
    pub warp: Option<&'a PlaneWarp>,
    /// The previous version's domain.
    pub domain: Option<&'a Domain>,
    /// The previous version's controls.
    pub controls: &'a [DVec3],
    /// Grid coordinates of `controls` (Loop grid).
    pub coords: &'a [(i64, i64)],
    /// The previous version's data points and where their foot points ended.
    pub feet: Option<&'a WarmFeet>,
}

/// A scan fit: the fit and everything the preparation and the domain left for the
/// outputs, the report and the next version.
#[derive(Clone, Debug)]
pub struct ScanFit {
    /// The fitted patch.
    pub fit: PatchFit,
    /// What cleaning and hole filling found.
    pub preparation: Preparation,
    /// The map to the plane.
    pub mapping: Mapping,
    /// Where the parameters live.
    pub domain: Domain,
    /// How the initial net came about.
    pub initial: InitialNet,
    /// What of the parameter domain is not part of the surface.
    pub trims: Trims,
    /// Geometric RMS after the first fit and after each correction round.
    pub correction_rms: Vec<f64>,
    /// Control points reused from the previous version (warm start).
    pub reused_controls: usize,
    /// Given a previous version, why it was not used (`None`: used, or none given).
    pub cold_start: Option<ColdStart>,
    /// Stage times.
    pub timings: ScanTimings,
}

/// What cleaning and hole filling found.
#[derive(Clone, Copy, Debug)]
pub struct Preparation {
    /// Components of the cleaned input.
    pub components: usize,
    /// Vertices of the component fitted.
    pub kept_vertices: usize,
    /// Holes filled.
    pub holes: usize,
    /// The components not fitted: what a user loses unless told.
    pub dropped: Dropped,
}

/// The pieces of an input left out of its surface (every component but the one fitted).
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct Dropped {
    /// Components left out.
    pub pieces: usize,
    /// Their vertices.
    pub vertices: usize,
    /// `vertices` as a share of all the cleaned input's vertices (0..=1).
    pub share: f64,
    /// Vertices of the largest piece left out.
    pub largest: usize,
}

impl Dropped {
    /// The summary of `sizes` (vertex counts of the pieces left out) out of `total` vertices.
    pub fn of(sizes: &[usize], total: usize) -> Self {
        let vertices: usize = sizes.iter().sum();
        Self {
            pieces: sizes.len(),
            vertices,
            share: vertices as f64 / total.max(1) as f64,
            largest: sizes.iter().copied().max().unwrap_or(0),
        }
    }

    /// Logs the pieces left out, if any, of `components` in all and `total` vertices: said
    /// where it happens, on every path (a piece of a third of a scan, or one of two
    /// interlinked knots, left out without a word looks like a fit of the whole).
    pub fn warn(&self, components: usize, total: usize) {
        if self.pieces == 0 {
            return;
        }
        tracing::warn!(
            pieces = self.pieces,
            vertices = self.vertices,
            share_pct = format!("{:.1}", 100.0 * self.share),
            largest_piece = self.largest,
            "{} of {} components not fitted: {} of {} vertices ({:.1} %), the largest piece left out has {}; `--components all` fits every sizeable piece",
            self.pieces,
            components,
            self.vertices,
            total,
            100.0 * self.share,
            self.largest,
        );
    }
}

/// The patch's map to the plane.
#[derive(Clone, Debug)]
pub struct Mapping {
    /// The plane.
    pub frame: PlaneFrame,
    /// The warp of the projection plane, if the map is a warped projection...
    pub warp: Option<PlaneWarp>,
    /// ... and the triangles it folded (left out of `filled` with the projection's folds).
    pub folds_warped: usize,
    /// How the map was made.
    pub method: MapMethod,
    /// Folded triangles of the projection.
    pub folds_projected: usize,
    /// The patch as mapped: real triangles (folds left out) and the hole fills...
    pub filled: TriMesh,
    /// ... and its vertices' parameters on the plain map (before correction)...
    pub mapped_params: Vec<DVec2>,
    /// ... and which of them belong to folded triangles of the map.
    pub near_fold: Vec<bool>,
}

/// The parts of the parameter domain that are not part of the surface.
#[derive(Clone, Debug)]
pub struct Trims {
    /// Outer boundary of the data in parameter coordinates, ordered.
    pub outer: Vec<(f64, f64)>,
    /// Rims of the trimmed holes and wide data triangles in parameter coordinates, ordered
    /// like `outer`: what lies inside any of them is not part of the surface.
    pub holes: Vec<Vec<(f64, f64)>>,
    /// Which holes are bridged and which trimmed, and the triangles of the filled patch
    /// that make the covered region (all but the fills of trimmed holes).
    pub plan: HolePlan,
}

/// Stage times of a scan fit, in milliseconds.
#[derive(Clone, Copy, Debug)]
pub struct ScanTimings {
    /// Cleaning, hole filling and the map to the plane.
    pub parameterization_ms: f64,
    /// The domain and the initial net.
    pub resample_ms: f64,
}
