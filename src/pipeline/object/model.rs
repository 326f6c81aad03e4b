//! What a whole-object fit takes and gives: its settings, its result and stage times, its
//! errors, and the limit surface it fits.

use super::layout::{LayoutOptions, LayoutReport};
use super::refine::{Fitted, RefineOptions, RefineRound};
use crate::fit::budget::{Budget, StepStats};
use crate::mesh::clean::{CleanOptions, CleanReport};
use crate::mesh::crease::CreaseOptions;
use crate::mesh::simplify::{Landing, SimplifyError, SimplifyOptions, SurfaceTopology};
use crate::mesh::topology::TopologyError;
use crate::surface::loop_limit::{LoopLimitError, LoopLimitSurface};
use crate::surface::SurfaceParam;
use crate::TriMesh;
use glam::DVec3;
use std::time::Instant;

/// Whole fits from scratch a stray escalation adds at most by default
/// (`ObjectOptions::stray_budget_steps`), each at twice the controls the one before spent
/// (so at most 8x). The stray repair splits faces around a fold and refits around them,
/// which does not undo a fold the coarse control mesh made across a thin part (a leg,
/// horns beside an ear: the surface webs across the gap), while a control mesh
/// simplified to a larger budget does not make it. Measured with `trispline fit` at 5 %
/// on the 62 meshes of CGAL's `data/meshes` that take the object path (never tuned on),
/// surfaces straying past the bound: 24 with two steps doubling the budget asked (the
/// rule before), 21 doubling the controls spent, 12 with three steps (small CAD parts
/// and low-poly models of 140-3,000 points need 4-8x: hand, b9_mesh, spool, rotor,
/// helmet, bones), at twice the time of those straying fits. The bound is a promise to
/// the user; the control budget gives way to it, as in the stray repair.
pub const STRAY_BUDGET_STEPS: usize = 3;

/// Refused rounds (each retried with four times the tangential share) before the rounds
/// of a fit, whole or local, stop.
pub(super) const MAX_REFUSALS: usize = 3;

/// Controls a hole's rim keeps at least (fewer pull the rim's limit curve inward: it is the
/// cubic B-spline of the loop, which for a triangle is a small rounded triangle).
const MIN_BOUNDARY_LOOP: usize = 6;

/// The control budget for `n` data points.
pub(super) fn control_target(n: usize, opts: &ObjectOptions) -> usize {
    opts.target_controls
        .unwrap_or((opts.target_controls_pct / 100.0 * n as f64).round() as usize)
        .max(4)
        .min(n)
}

/// Each data point's landing on a simplified mesh as its parameter on the control faces.
pub(super) fn landing_params(landing: &[Landing]) -> Vec<SurfaceParam> {
    landing
        .iter()
        .map(|l| SurfaceParam {
            face: l.face,
            u: l.u,
            v: l.v,
        })
        .collect()
}

/// Budget, cleaning, simplification and fitting settings of [`fit_object`].
#[derive(Clone, Debug)]
pub struct ObjectOptions {
    /// Control points as a percentage of the data points (when `target_controls` is unset).
    pub target_controls_pct: f64,
    /// Control points wanted, overriding the percentage (clamped to 4..=data points).
    pub target_controls: Option<usize>,
    /// Cleaning applied before the largest component is kept.
    pub clean: CleanOptions,
    /// Guards of the simplification; its `target_vertices` is set from the targets above.
    pub simplify: SimplifyOptions,
    /// Which data edges become crease edges of the control mesh (`angle_deg` 0: none).
    pub crease: CreaseOptions,
    /// Fairness weight relative to the data: s = smoothing * data points / control points.
    pub smoothing: f64,
    /// Foot-point rounds after the first fit (at most).
    pub rounds: usize,
    /// Rounds stop once one lowers the RMS by less than this fraction.
    pub min_gain: f64,
    /// Share of the point-to-point term beside the point-to-plane one in the first round.
    pub tangential: f64,
    /// The share each taken round halves down to (Levenberg-Marquardt: a round that
    /// lowers the RMS trusts the next with less damping). The point-to-point term holds
    /// the feet while they are far from their final places; once rounds succeed, a small
    /// share lets the surface slide along the data and converge further. Where the data is
    /// too sparse to hold a surface that slides freely, a fit that strays past the bound is
    /// fitted again at the steady `tangential` (`fit_object_input`). Measured against a
    /// share held at 0.005 (5 % controls): bun_zipper 63.7 -> 60.1 um; on CGAL's 74 meshes
    /// of the object path the RMS fell to 0.88x (geometric mean; 0.98x on the 43 fitted
    /// at the same control count), none left past the stray bound. A share held small
    /// from the first round instead: 0.0005 gave bun_zipper 60.7 um but CGAL's anchor 29x
    /// its RMS; 5e-5 was unstable on bun_zipper.
    pub tangential_floor: f64,
    /// Squared-distance minimisation (`geometric::curvature_term`) in the whole fit's
    /// rounds: the share of the point-to-point term away from the data's edges, beside the
    /// curvature's term, in place of `tangential` (which stays the Levenberg-Marquardt
    /// base the shares scale from). `None`: a constant `tangential` share.
    pub curvature_floor: Option<f64>,
    /// The same share for data points within `edge_rings` rings of the data's boundary:
    /// there the residual runs past the surface's edge, along it, where the point-to-plane
    /// term does not pull.
    pub tangential_edge: f64,
    /// Width, in vertex rings from the data's boundary, of the band using `tangential_edge`.
    pub edge_rings: usize,
    /// CG steps where a sparse factorisation fails.
    pub max_iterations: usize,
    /// Start the first fit from the data's foot points on the limit surface of the initial
    /// control mesh instead of their projections onto the control faces.
    pub limit_start: bool,
    /// Flips and relaxation of the simplified control mesh before fitting.
    pub layout: LayoutOptions,
    /// Adaptive refinement after the first fit.
    pub refine: RefineOptions,
    /// Times the simplified base mesh is split 1-to-4 before fitting (the paper's mesh
    /// adjustment to subdivision connectivity over a base domain; the simplification then
    /// keeps a 4^levels-th of the controls). 0: the simplified mesh is the control mesh.
    /// 0 by default: one split measured worse on every shared model (ratio to QEM at 5 %:
    /// bun_zipper 0.456 -> 0.485, fertility 0.250 -> 0.382, camelhead 0.243 -> 0.310),
    /// the uniform split spending controls where the simplification had found none needed.
    pub domain_levels: usize,
    /// Pull sample points of control faces with few foot points to the data (the
    /// surface-to-data term; without it such patches are held only by the fairness term).
    pub surface_samples: bool,
    /// When the rounds and the refinement stop before they converge or run out.
    pub stop: RoundStop,
    /// The farthest the surface may stray from the data, as a share of its bounding-box
    /// diagonal: beyond it, faces are split where it strays and the controls around them
    /// refitted, past the control budget if need be (`None`: no repair).
    pub max_stray_share: Option<f64>,
    /// Whole fits from scratch at twice the controls the fit before spent, at most, where
    /// the repair leaves the surface straying past `max_stray_share` and the budget cannot
    /// hold the shape (`fit_object_input`; the least straying fit is kept); 0: none.
    pub stray_budget_steps: usize,
    /// On data with sharp edges, and where the smooth fit strays past the bound, also fit
    /// the faceted candidate (every control edge a crease: the limit surface is the
    /// control mesh) at the kept fit's control count, and keep it where it fits the data
    /// better (`faceted`).
    pub faceted_candidate: bool,
}

/// The tangential share of the rounds' squared-distance term where the curvature gives
/// none (flat directions, and where the surface bends towards the point) when
/// `curvature_floor` asks for the curvature term: it keeps the surface from sliding
/// unheld there. Measured against the constant share (0.005 everywhere) at 1e-4, 3e-4
/// and 1e-3 on the 9 models of `object_table` and on 18 of CGAL's meshes used to choose
/// nothing before. The shared models' RMS fell at all three (fertility and camelhead by
/// 7-16 %); the unseen ones' by 1.6-1.8 % (geometric mean) at the two lower floors, with
/// 5-7 of the 18 worse by over 1 %, and not at 1e-3. The strays moved both ways at every
/// floor; at 1e-4 models within the bound before went near or past it (fandisk 0.17 ->
/// 0.49 % of the diagonal), at 3e-4 none did.
///
/// Not the default: on exact data the curvature term is below the floor nearly
/// everywhere, so what acts is a share 16 times smaller than the constant one. The
/// surface then slides more freely: on the object session's sphere views (no noise) the
/// whole fits' RMS fell 6-11 % but the final surface's largest distance from the sphere
/// doubled (5.8e-5 -> 1.23e-4), and a local refit of a changed view ended 28 % farther
/// from its data.
pub const CURVATURE_FLOOR: f64 = 3e-4;

/// The share of the data's bounding-box diagonal a whole fit's surface is held to from
/// the data (no bulge over holes): the stray repair's bound, the report's and the warm
/// results' guard.
pub const STRAY_LIMIT_SHARE: f64 = 0.005;

/// Lattice segments per control face edge on which the stray is measured for the repair
/// and the report: finer than the control faces' own corners, so a bulge between them
/// shows, as in the written tessellation.
pub const STRAY_LATTICE_SEGMENTS: usize = 6;

/// When a fit's foot-point rounds and refinement rounds stop besides their own
/// convergence: the targets of the fit's budget hold (the error the user asked for is
/// reached: further rounds would spend time and, for refinement, controls beyond it), or
/// its time is up. Checked before every round, never inside one.
#[derive(Clone, Debug, Default)]
pub struct RoundStop {
    /// Targets, and the tolerance behind `within_tolerance_pct`; `None`: no targets.
    pub budget: Option<Budget>,
    /// No round starts after this instant.
    pub deadline: Option<Instant>,
}

impl RoundStop {
    /// The stop of a fit started at `start` under `budget`: its targets, and its
    /// `max_time_ms` counted from `start`.
    pub fn of_budget(budget: &Budget, start: Instant) -> Self {
        Self {
            budget: Some(budget.clone()),
            deadline: budget
                .max_time_ms
                .map(|ms| start + std::time::Duration::from_millis(ms)),
        }
    }

    /// Whether the budget's targets hold for these distances (never without targets).
    pub(super) fn targets_hold(&self, distances: &[f64]) -> bool {
        self.budget
            .as_ref()
            .is_some_and(|b| b.met(&StepStats::from_distances(0, distances, b.tolerance, 0.0)))
    }

    /// Whether the deadline has passed.
    pub fn out_of_time(&self) -> bool {
        self.deadline.is_some_and(|d| Instant::now() >= d)
    }

    /// Whether no further round should start.
    pub(super) fn reached(&self, distances: &[f64]) -> bool {
        self.out_of_time() || self.targets_hold(distances)
    }
}

impl ObjectOptions {
    /// The least tangential share the rounds halve down to (never above the first).
    pub(crate) fn share_floor(&self) -> f64 {
        self.tangential_floor.min(self.tangential)
    }

    /// The stray bound for `data` (`max_stray_share` of its bounding-box diagonal), which
    /// the stray repair, the budget's growth and the faceted surfaces all hold the fit
    /// to; `None` when the fit is not held to one.
    pub(super) fn stray_limit(&self, data: &TriMesh) -> Option<f64> {
        self.max_stray_share.map(|s| s * data.bounds_diagonal())
    }
}

impl Default for ObjectOptions {
    fn default() -> Self {
        Self {
            target_controls_pct: 5.0,
            target_controls: None,
            clean: CleanOptions::default(),
            crease: CreaseOptions::default(),
            simplify: SimplifyOptions {
                isotropy: 1e-3,
                min_boundary_loop: MIN_BOUNDARY_LOOP,
                ..Default::default()
            },
            smoothing: 1e-5,
            // The rounds were stopped while still gaining: on bun_zipper (5 % controls)
            // the last fit's rounds gained 2.9 % then 1.9 % and stopped at 63.8 um; run on
            // to a 0.2 % gain they reach 57.9 um (20 rounds), to 0.5 % 59.3 um (13 rounds,
            // +20 % fit CPU). The daemon's worker caps the rounds at
            // `fit.correction.rounds` instead of this library default.
            rounds: 16,
            min_gain: 0.005,
            tangential: 0.005,
            tangential_floor: 0.001,
            curvature_floor: None,
            tangential_edge: 0.05,
            edge_rings: 3,
            max_iterations: 400,
            limit_start: true,
            layout: LayoutOptions::default(),
            refine: RefineOptions::default(),
            domain_levels: 0,
            surface_samples: true,
            stop: RoundStop::default(),
            max_stray_share: Some(STRAY_LIMIT_SHARE),
            stray_budget_steps: STRAY_BUDGET_STEPS,
            faceted_candidate: true,
        }
    }
}

/// Why an object fit failed.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ObjectError {
    /// Cleaning left no faces.
    #[error("the mesh has no faces left after cleaning")]
    Empty,
    /// The data component or the control mesh has no half-edge topology.
    #[error("the cleaned component is not a manifold")]
    NotManifold(#[source] TopologyError),
    /// The simplification to a control mesh refused the component.
    #[error("simplifying to a control mesh failed")]
    Simplify(#[source] SimplifyError),
    /// The control mesh does not define a Loop limit surface.
    #[error("the control mesh has no Loop limit surface")]
    Surface(#[source] LoopLimitError),
    /// [`fit_on_control_mesh`] was given a parameter count different from the data's.
    #[error("{params} initial parameters for {points} data points")]
    ParamCount {
        /// Initial parameters given.
        params: usize,
        /// Data points (component vertices).
        points: usize,
    },
    /// A least-squares solve produced no finite control points.
    #[error("the {stage} solve gave no finite control points")]
    Solve {
        /// Which solve failed (`"first"`: the initial point fit).
        stage: &'static str,
    },
}

/// Stage times in milliseconds.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct ObjectTimes {
    /// Cleaning and extracting the largest component.
    pub clean_ms: f64,
    /// Simplifying the component to the control mesh.
    pub simplify_ms: f64,
    /// Flips and relaxation of the control mesh.
    pub layout_ms: f64,
    /// Adaptive refinement: every refined control mesh and its whole fit (the surface,
    /// first fit and rounds times are those of the fit before refinement).
    pub refine_ms: f64,
    /// Topology counts, the limit surface and the fairness operator.
    pub surface_ms: f64,
    /// Initial parameters, the first point fit and its foot points.
    pub first_fit_ms: f64,
    /// All foot-point/distance rounds, refused ones included.
    pub rounds_ms: f64,
    /// The whole fit, end to end.
    pub total_ms: f64,
    /// The stray escalation beside the fit kept: its decimation checks and the whole fits
    /// it dropped (`ObjectFit::stray_budgets`); part of `total_ms`.
    pub stray_budget_ms: f64,
    /// The faceted candidate of a sharp-edged object, its decimation, fit and stray
    /// measurement (`ObjectFit::faceted`); part of `total_ms`. The other stages are the
    /// smooth fit's, whichever was kept.
    pub faceted_ms: f64,
}

/// RMS and max distance of the data to the surface after a stage.
#[derive(Clone, Copy, Debug, serde::Serialize)]
pub struct RoundReport {
    /// Root mean square distance, in the data's units.
    pub rms: f64,
    /// Largest distance, in the data's units.
    pub max: f64,
}

/// A fitted object: the surface, its controls, and how well it fits the data.
pub struct ObjectFit {
    /// The data points fitted: the vertices of the kept component.
    pub data: Vec<DVec3>,
    /// The component itself (data points and their triangles).
    pub component: TriMesh,
    /// The control mesh before the final fit: the simplification after the layout stage
    /// at its initial positions or, after refinement, the refined mesh at the previous
    /// fit's limit positions.
    pub simplified: TriMesh,
    /// The limit surface's structure (faces and evaluation), independent of positions.
    pub surface: LoopLimitSurface,
    /// Fitted control point positions, one per control mesh vertex.
    pub controls: Vec<DVec3>,
    /// Foot point of every data point on the final surface.
    pub params: Vec<SurfaceParam>,
    /// Distance of every data point to its foot point.
    pub distances: Vec<f64>,
    /// Root mean square of `distances`.
    pub rms: f64,
    /// Largest of `distances`.
    pub max: f64,
    /// After the first fit, then after each round.
    pub rounds: Vec<RoundReport>,
    /// Topology of the data component.
    pub data_topology: SurfaceTopology,
    /// Topology of the control mesh (equal to the data's when simplification kept it).
    pub control_topology: SurfaceTopology,
    /// Stage times.
    pub times: ObjectTimes,
    /// What the layout stage changed (all zero when it did not run).
    pub layout: LayoutReport,
    /// The fit before refinement, then after each refinement round (empty when refinement
    /// is off).
    pub refinement: Vec<RefineRound>,
    /// Control faces the last round sampled for the surface-to-data term inside (faces
    /// with a quarter no foot point lands on; boundary curve samples not counted).
    pub sampled_faces: usize,
    /// What a local refit of a new version touched (`None`: a whole fit).
    pub local: Option<LocalUpdate>,
    /// How far the surface strays from the data, when the fit measured it (the stray
    /// repair does, on a lattice of `STRAY_LATTICE_SEGMENTS` per control face edge).
    pub stray: Option<f64>,
    /// What cleaning changed in the input before the fit (its first pass; `None` where
    /// the fit was given data already cleaned, as the rounds and refits of a fit are).
    pub cleaning: Option<CleanReport>,
    /// The whole fits tried when the first strayed past the bound, that one first, each at
    /// a larger budget (empty when the first stayed within it or was not measured).
    pub stray_budgets: Vec<StrayBudget>,
    /// Which of the smooth and the faceted fit was kept, on data with sharp edges or a
    /// smooth fit past the stray bound (`None`: the faceted candidate was not tried).
    pub faceted: Option<FacetedChoice>,
}

/// Which fit of a sharp-edged or straying object was kept, and the figures it was chosen on
/// (`faceted::keep_nearer`).
#[derive(Clone, Copy, Debug, serde::Serialize)]
pub struct FacetedChoice {
    /// Control points of both fits.
    pub controls: usize,
    /// The smooth fit's RMS distance from the data ...
    pub smooth_rms: f64,
    /// ... its largest distance ...
    pub smooth_max: f64,
    /// ... and how far it strays from the data (`None`: not measured).
    pub smooth_stray: Option<f64>,
    /// The faceted fit's RMS distance from the data ...
    pub faceted_rms: f64,
    /// ... its largest distance ...
    pub faceted_max: f64,
    /// ... and how far it strays from the data.
    pub faceted_stray: f64,
    /// Whether the faceted fit was kept.
    pub kept_faceted: bool,
    /// Time the faceted fit and its measurement took.
    pub ms: f64,
}

/// One whole fit of a stray escalation (`ObjectFit::stray_budgets`).
#[derive(Clone, Copy, Debug, serde::Serialize)]
pub struct StrayBudget {
    /// The control budget it was asked for.
    pub target: usize,
    /// The controls it ended with (a stray repair may add a tenth).
    pub controls: usize,
    /// Its RMS distance.
    pub rms: f64,
    /// How far its surface strayed from the data.
    pub stray: f64,
    /// Whether it is the fit kept (the least straying).
    pub kept: bool,
    /// Whether it is a faceted fit, the escalation's last resort (`faceted::hold_bound`).
    pub faceted: bool,
}

impl StrayBudget {
    pub(super) fn of(target: usize, fit: &ObjectFit) -> Self {
        Self {
            target,
            controls: fit.controls.len(),
            rms: fit.rms,
            stray: fit.stray.unwrap_or(f64::INFINITY),
            kept: false,
            faceted: false,
        }
    }
}

impl ObjectFit {
    /// What refinement reads of the fit.
    pub(super) fn fitted(&self) -> Fitted<'_> {
        Fitted {
            component: &self.component,
            surface: &self.surface,
            controls: &self.controls,
            params: &self.params,
            distances: &self.distances,
        }
    }

    /// The control mesh at the fitted positions.
    pub fn control_mesh(&self) -> TriMesh {
        TriMesh::new(self.controls.clone(), self.surface.faces().to_vec())
    }
}

/// A previous fit a new version starts from (a local refit, an extension over new ground).
pub struct PreviousFit<'a> {
    /// Its control mesh at the fitted positions.
    pub control_mesh: &'a TriMesh,
    /// Its crease edges.
    pub crease_edges: &'a [[u32; 2]],
    /// Its RMS distance (to tell changed old points from noise).
    pub rms: f64,
    /// Its limit surface, when the caller kept it: the new surfaces take over its
    /// quadtrees of child nets (`LoopLimitSurface::with_creases_reusing`), which a fit of
    /// a coarse irregular control mesh otherwise spends much of its time building again.
    pub surface: Option<&'a LoopLimitSurface>,
}

/// The limit surface of `control_mesh`, taking over the unchanged patches of `previous`.
pub(super) fn limit_surface(
    control_mesh: &TriMesh,
    crease_edges: &[[u32; 2]],
    previous: Option<&LoopLimitSurface>,
) -> Result<LoopLimitSurface, ObjectError> {
    let (count, faces) = (control_mesh.positions.len(), &control_mesh.triangles);
    match previous {
        Some(previous) => {
            LoopLimitSurface::with_creases_reusing(count, faces, crease_edges, previous)
        }
        None => LoopLimitSurface::with_creases(count, faces, crease_edges),
    }
    .map_err(ObjectError::Surface)
}

pub(super) fn ms_since(t: Instant) -> f64 {
    t.elapsed().as_secs_f64() * 1e3
}

/// What a local refit of a new version touched (see `refit_where_changed`).
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct LocalUpdate {
    /// Data points farther from the previous surface than the previous data near them.
    pub changed_points: usize,
    /// Controls solved again, new ones included; every other control kept its position.
    pub free_controls: usize,
    /// Controls the local refinement added.
    pub added_controls: usize,
    /// Points over the patches the free controls move (their feet found again), summed
    /// over the refits.
    pub moving_points: usize,
    /// Squared-distance rounds taken, summed over the refits.
    pub rounds: usize,
    /// Data points on new ground the control mesh was extended over (0: the update kept
    /// the previous control mesh's extent).
    pub new_ground_points: usize,
}
