//! Whole objects (closed, holed, any genus): the exact Loop limit surface of a control mesh
//! found by simplifying the data (Hoppe et al. 1994; Marinov & Kobbelt 2005), fitted to
//! every data point.
//!
//! Stages: clean and keep the largest component; simplify it by quadric edge collapse to
//! the control budget (`mesh::simplify`: the topology is kept, so the control mesh has the
//! component's Euler characteristic and boundary loops, and every data vertex is carried
//! to a control face: its initial parameter); a point-to-point least-squares fit at those
//! parameters with a small umbrella fairness term; then rounds of foot points (Newton on
//! the limit surface, crossing faces) and squared-distance minimisation (point-to-plane
//! with a small tangential share) until a round gains less than `min_gain` of the RMS.

mod solve;

use crate::fit::engine::umbrella_laplacian;
use crate::fit::Collocation;
use crate::mesh::clean::{clean, CleanOptions};
use crate::mesh::simplify::{
    simplify, Simplified, SimplifyError, SimplifyOptions, SurfaceTopology,
};
use crate::mesh::topology::TopologyError;
use crate::surface::loop_limit::{LoopLimitError, LoopLimitSurface};
use crate::surface::SurfaceParam;
use crate::TriMesh;
use glam::DVec3;
use solve::{point_fit, rows_at, DistanceRound, Feet};
use std::time::Instant;

#[derive(Clone, Debug)]
pub struct ObjectOptions {
    /// Control points as a percentage of the data points (when `target_controls` is unset).
    pub target_controls_pct: f64,
    pub target_controls: Option<usize>,
    pub clean: CleanOptions,
    /// Guards of the simplification; its `target_vertices` is set from the targets above.
    pub simplify: SimplifyOptions,
    /// Fairness weight relative to the data: s = smoothing * data points / control points.
    pub smoothing: f64,
    /// Foot-point rounds after the first fit (at most).
    pub rounds: usize,
    /// Rounds stop once one lowers the RMS by less than this fraction.
    pub min_gain: f64,
    /// Share of the point-to-point term beside the point-to-plane one in the rounds.
    pub tangential: f64,
    /// CG steps where a sparse factorisation fails.
    pub max_iterations: usize,
}

impl Default for ObjectOptions {
    fn default() -> Self {
        Self {
            target_controls_pct: 5.0,
            target_controls: None,
            clean: CleanOptions::default(),
            simplify: SimplifyOptions::default(),
            smoothing: 1e-5,
            rounds: 8,
            min_gain: 0.02,
            tangential: 0.005,
            max_iterations: 400,
        }
    }
}

#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ObjectError {
    #[error("the mesh has no faces left after cleaning")]
    Empty,
    #[error("the cleaned component is not a manifold")]
    NotManifold(#[source] TopologyError),
    #[error("simplifying to a control mesh failed")]
    Simplify(#[source] SimplifyError),
    #[error("the control mesh has no Loop limit surface")]
    Surface(#[source] LoopLimitError),
    #[error("the {stage} solve gave no finite control points")]
    Solve { stage: &'static str },
}

/// Stage times in milliseconds.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct ObjectTimes {
    pub clean_ms: f64,
    pub simplify_ms: f64,
    pub surface_ms: f64,
    pub first_fit_ms: f64,
    pub rounds_ms: f64,
    pub total_ms: f64,
}

/// RMS and max distance of the data to the surface after a stage.
#[derive(Clone, Copy, Debug, serde::Serialize)]
pub struct RoundReport {
    pub rms: f64,
    pub max: f64,
}

pub struct ObjectFit {
    /// The data points fitted: the vertices of the kept component.
    pub data: Vec<DVec3>,
    /// The component itself (data points and their triangles).
    pub component: TriMesh,
    /// The simplification before fitting: the control faces at their initial positions
    /// (also the quadric-decimated mesh with as many vertices as there are controls).
    pub simplified: TriMesh,
    pub surface: LoopLimitSurface,
    pub controls: Vec<DVec3>,
    /// Foot point of every data point on the final surface.
    pub params: Vec<SurfaceParam>,
    /// Distance of every data point to its foot point.
    pub distances: Vec<f64>,
    pub rms: f64,
    pub max: f64,
    /// After the first fit, then after each round.
    pub rounds: Vec<RoundReport>,
    pub data_topology: SurfaceTopology,
    pub control_topology: SurfaceTopology,
    pub times: ObjectTimes,
}

impl ObjectFit {
    pub fn control_mesh(&self) -> TriMesh {
        TriMesh::new(self.controls.clone(), self.surface.faces().to_vec())
    }
}

/// Fits the exact Loop limit surface of a simplified control mesh to the largest
/// component of `mesh`.
pub fn fit_object(mesh: &TriMesh, opts: &ObjectOptions) -> Result<ObjectFit, ObjectError> {
    let start = Instant::now();
    let mut times = ObjectTimes::default();
    let component = largest_component(mesh, &opts.clean).ok_or(ObjectError::Empty)?;
    let data_topology = SurfaceTopology::of(&component).map_err(ObjectError::NotManifold)?;
    times.clean_ms = ms_since(start);

    let t = Instant::now();
    let n = component.positions.len();
    let target = opts
        .target_controls
        .unwrap_or((opts.target_controls_pct / 100.0 * n as f64).round() as usize)
        .max(4)
        .min(n);
    let simplify_opts = SimplifyOptions {
        target_vertices: target,
        ..opts.simplify.clone()
    };
    let simplified = simplify(&component, &simplify_opts).map_err(ObjectError::Simplify)?;
    times.simplify_ms = ms_since(t);

    let t = Instant::now();
    let Simplified {
        mesh: control_mesh,
        landing,
        ..
    } = simplified;
    let control_topology =
        SurfaceTopology::of(&control_mesh).map_err(ObjectError::NotManifold)?;
    let surface = LoopLimitSurface::new(control_mesh.positions.len(), &control_mesh.triangles)
        .map_err(ObjectError::Surface)?;
    let params: Vec<SurfaceParam> = landing
        .iter()
        .map(|l| SurfaceParam {
            face: l.face,
            u: l.u,
            v: l.v,
        })
        .collect();
    let m = control_mesh.positions.len();
    let fairness = Collocation::new(umbrella_laplacian(m, &control_mesh.triangles));
    let smoothing = opts.smoothing * n as f64 / m.max(1) as f64;
    times.surface_ms = ms_since(t);

    let t = Instant::now();
    let data = component.positions.clone();
    let rows = rows_at(&surface, &params);
    let mut controls = point_fit(
        &rows,
        &data,
        &fairness,
        smoothing,
        control_mesh.positions.clone(),
        opts.max_iterations,
    )
    .ok_or(ObjectError::Solve { stage: "first" })?;
    drop(rows);
    let mut feet = Feet::find(&surface, &controls, &data, &params);
    times.first_fit_ms = ms_since(t);

    let t = Instant::now();
    let mut rounds = vec![RoundReport {
        rms: feet.rms(),
        max: feet.max(),
    }];
    let tangential = vec![opts.tangential; n];
    let round = DistanceRound {
        surface: &surface,
        data: &data,
        fairness: &fairness,
        smoothing,
        tangential: &tangential,
        max_iterations: opts.max_iterations,
    };
    for _ in 0..opts.rounds {
        let Some(next) = round.solve(&feet, controls.clone()) else {
            break;
        };
        let next_feet = Feet::find(&surface, &next, &data, &feet.params);
        let (before, after) = (feet.rms(), next_feet.rms());
        if after.is_nan() || after >= before {
            break;
        }
        controls = next;
        feet = next_feet;
        rounds.push(RoundReport {
            rms: after,
            max: feet.max(),
        });
        if before - after < opts.min_gain * before {
            break;
        }
    }
    times.rounds_ms = ms_since(t);
    times.total_ms = ms_since(start);
    Ok(ObjectFit {
        data,
        component,
        simplified: control_mesh,
        rms: feet.rms(),
        max: feet.max(),
        surface,
        controls,
        params: feet.params,
        distances: feet.distances,
        rounds,
        data_topology,
        control_topology,
        times,
    })
}

fn ms_since(t: Instant) -> f64 {
    t.elapsed().as_secs_f64() * 1e3
}

/// The cleaned mesh's largest edge-connected component (most faces; the lowest label on a
/// tie), its vertices in cleaned order.
fn largest_component(mesh: &TriMesh, opts: &CleanOptions) -> Option<TriMesh> {
    let cleaned = clean(mesh, opts);
    let labels = &cleaned.face_component;
    let mut counts = vec![0usize; cleaned.mesh.triangles.len()];
    for &l in labels {
        counts[l as usize] += 1;
    }
    let (best, &size) = counts
        .iter()
        .enumerate()
        .max_by(|a, b| a.1.cmp(b.1).then(b.0.cmp(&a.0)))?;
    if size == 0 {
        return None;
    }
    let mut index = vec![u32::MAX; cleaned.mesh.positions.len()];
    let mut triangles = Vec::with_capacity(size);
    for (t, &l) in cleaned.mesh.triangles.iter().zip(labels) {
        if l as usize == best {
            for &v in t {
                index[v as usize] = 0;
            }
            triangles.push(*t);
        }
    }
    let mut positions = Vec::new();
    for (v, i) in index.iter_mut().enumerate() {
        if *i == 0 {
            *i = positions.len() as u32;
            positions.push(cleaned.mesh.positions[v]);
        }
    }
    for t in &mut triangles {
        *t = t.map(|v| index[v as usize]);
    }
    Some(TriMesh::new(positions, triangles))
}
