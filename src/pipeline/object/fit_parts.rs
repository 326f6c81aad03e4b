//! The parts of one fit on a control mesh (`fit_from`): what it starts from, what every
//! round reads, and one squared-distance round.

use super::data_side::DataSide;
use super::model::{limit_surface, ObjectError, ObjectOptions};
use super::refine::{faces_beyond, Fitted, RefineRound, MIN_FACES_BEYOND_SHARE};
use super::rim::Rim;
use super::shares::shares_and_curvature;
use super::solve::{rms, two_sided_rms, DistanceRound, Feet, Samples};
use crate::fit::distance::CholeskyPattern;
use crate::fit::engine::umbrella_laplacian_with_creases;
use crate::fit::Collocation;
use crate::mesh::distance::MeshDistance;
use crate::mesh::simplify::SurfaceTopology;
use crate::mesh::topology::Topology;
use crate::surface::loop_limit::LoopLimitSurface;
use crate::surface::SurfaceParam;
use crate::TriMesh;
use glam::DVec3;
use std::cell::Cell;

/// What a fit starts from: the control mesh, its creases, the data points' parameters on
/// it, and maybe more.
pub(super) struct FitStart<'a> {
    pub control_mesh: TriMesh,
    pub crease_edges: &'a [[u32; 2]],
    /// One per data point, on the control faces.
    pub params: Vec<SurfaceParam>,
    /// Control positions to start the rounds from (one per control mesh vertex), the
    /// first point fit skipped.
    pub warm: Option<Vec<DVec3>>,
    /// The surface of an earlier control mesh whose unchanged patches are reused.
    pub previous: Option<&'a LoopLimitSurface>,
    /// Intermediate rounds that go on to all of them where refinement would not run.
    pub go_on: Option<&'a GoOn>,
}

/// A fit of intermediate rounds (`intermediate`) goes on in place to `rounds` rounds when
/// refinement after it would not run (`declined` with the budget `cap`); else
/// `finish_rounds` would run them from its result, building the same surface and feet
/// again (on a 139k-point closed scan about 65 ms of a 3 s fit).
pub(super) struct GoOn {
    pub rounds: usize,
    pub cap: usize,
    /// The fit as refinement declined it, when the fit went on (the refinement's first
    /// and only stage, as `refine_fit` records it).
    pub declined_at: Cell<Option<RefineRound>>,
}

impl<'a> FitStart<'a> {
    pub fn new(
        control_mesh: TriMesh,
        crease_edges: &'a [[u32; 2]],
        params: Vec<SurfaceParam>,
    ) -> Self {
        Self {
            control_mesh,
            crease_edges,
            params,
            warm: None,
            previous: None,
            go_on: None,
        }
    }
}

impl GoOn {
    /// The round limit past `limit` when the fit goes on (refinement would not run).
    pub fn raised(&self, limit: usize, fitted: &Fitted, opts: &ObjectOptions) -> Option<usize> {
        if self.rounds <= limit || !declined(fitted, self.cap, opts) {
            return None;
        }
        let d = fitted.distances;
        let max = d.iter().fold(0.0, |m: f64, &x| m.max(x));
        let at = RefineRound::of(fitted.controls.len(), rms(d), max, d, opts.refine.tolerance);
        self.declined_at.set(Some(at));
        Some(self.rounds)
    }
}

/// What every round of a fit reads besides the data: the limit surface of the control
/// mesh, its topology, the hold of the data's rim on its boundary curve and the fairness
/// term with its weight.
pub(super) struct Setup {
    pub surface: LoopLimitSurface,
    pub control_topology: SurfaceTopology,
    pub rim: Rim,
    pub fairness: Collocation,
    pub smoothing: f64,
}

impl Setup {
    pub fn new(
        side: &DataSide,
        control_mesh: &TriMesh,
        crease_edges: &[[u32; 2]],
        previous: Option<&LoopLimitSurface>,
        opts: &ObjectOptions,
    ) -> Result<Self, ObjectError> {
        let control_topo = Topology::from_mesh(control_mesh).map_err(ObjectError::NotManifold)?;
        let control_topology = SurfaceTopology::of_built(control_mesh, &control_topo);
        let surface = limit_surface(control_mesh, crease_edges, previous)?;
        let m = control_mesh.positions.len();
        let fairness = Collocation::new(umbrella_laplacian_with_creases(
            m,
            &control_mesh.triangles,
            surface.crease_edges(),
        ));
        let n = side.mesh.positions.len();
        Ok(Self {
            rim: Rim::new(&control_mesh.triangles, &control_topo.twin, &side.on_rim),
            surface,
            control_topology,
            fairness,
            smoothing: opts.smoothing * n as f64 / m.max(1) as f64,
        })
    }
}

/// Whether refinement rounds would not run after a fit: the budget `cap` is spent, the
/// rounds' stop holds, or too few control faces hold points beyond the tolerance.
pub(super) fn declined(fit: &Fitted, cap: usize, opts: &ObjectOptions) -> bool {
    fit.controls.len() >= cap
        || opts.stop.reached(fit.distances)
        || faces_beyond(fit, opts.refine.tolerance) * MIN_FACES_BEYOND_SHARE < fit.controls.len()
}

/// What a fit's rounds read that stays the same from round to round.
pub(super) struct RoundContext<'a> {
    pub surface: &'a LoopLimitSurface,
    pub data: &'a [DVec3],
    pub component: &'a TriMesh,
    pub rim: &'a Rim,
    pub fairness: &'a Collocation,
    pub smoothing: f64,
    /// Per data point: near the data's boundary ...
    pub near_edge: &'a [bool],
    /// ... and held on the rim.
    pub on_rim: &'a [bool],
    /// The data mesh's closest points, for the surface-to-data samples (`None`: none).
    pub nearest: Option<&'a MeshDistance<'a>>,
    pub opts: &'a ObjectOptions,
}

/// A round tried: its result when taken, and what it was judged against.
pub(super) struct Tried {
    /// The new feet, controls and two-sided RMS, when the round lowered the RMS.
    pub next: Option<(Feet, Vec<DVec3>, f64)>,
    /// The two-sided RMS before it.
    pub before: f64,
    /// Control faces it sampled.
    pub sampled_faces: usize,
}

impl RoundContext<'_> {
    /// One squared-distance round from `controls` and their `feet`, with the tangential
    /// share `share` (the Levenberg-Marquardt factor of `fit_from`).
    pub fn round(
        &self,
        controls: &[DVec3],
        feet: &Feet,
        share: f64,
        pattern: &mut CholeskyPattern,
    ) -> Tried {
        let opts = self.opts;
        let samples = self.nearest.map_or_else(Samples::none, |nearest| {
            Samples::find(
                self.surface,
                controls,
                &feet.params,
                self.rim,
                self.component,
                nearest,
                None,
            )
        });
        let edge_factor = opts.tangential_edge / opts.tangential.max(f64::MIN_POSITIVE);
        let (tangential, curvature) = shares_and_curvature(
            (self.near_edge, self.on_rim),
            feet,
            (share, edge_factor),
            opts,
        );
        let round = DistanceRound {
            surface: self.surface,
            data: self.data,
            fairness: self.fairness,
            smoothing: self.smoothing,
            tangential: &tangential,
            curvature: curvature.as_deref(),
            max_iterations: opts.max_iterations,
            samples: &samples,
            sample_tangential: share,
        };
        // A round is taken when it lowers the two-sided RMS it minimises: judged by the
        // data's distances alone, a round that pulls a bulge over a hole back onto the data
        // was refused (bun_zipper_res4 at 40 % controls kept a first fit straying 17.7 %
        // of the diagonal).
        let before = two_sided_rms(&feet.distances, &samples.distances);
        let next = round
            .solve(feet, controls.to_vec(), pattern)
            .and_then(|next| round.judge(next, &feet.params, self.rim, self.nearest, before));
        Tried {
            next,
            before,
            sampled_faces: samples.faces,
        }
    }
}
