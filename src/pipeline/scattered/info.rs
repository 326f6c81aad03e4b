//! What a planar-domain fit leaves beside the fit itself (for the outputs, the report and
//! the next version), and the planar view of its model.

use crate::pipeline::output::Coverage;
use crate::pipeline::scan::Preparation;
use crate::pipeline::SurfaceModel;
use crate::remesh::planar::{MapMethod, PlaneFrame};
use crate::remesh::warp::PlaneWarp;
use crate::surface::dms::PlanarSurface;
use glam::DVec2;
use std::time::Instant;

/// What a planar-domain fit leaves for its outputs, report and next version beside the fit.
pub struct ScatteredInfo {
    /// What cleaning and hole filling found.
    pub preparation: Preparation,
    /// The plane of the map.
    pub frame: PlaneFrame,
    /// Its warp, if the map is a warped projection.
    pub warp: Option<PlaneWarp>,
    /// How the map was made.
    pub method: MapMethod,
    /// The scanned region in domain coordinates (data at their final domain points).
    pub coverage: Coverage,
    /// The outer rim of the data in domain coordinates...
    pub outer: Vec<DVec2>,
    /// ... and the rims of trimmed holes and wide data triangles.
    pub holes: Vec<Vec<DVec2>>,
    /// Geometric RMS after each round.
    pub correction_rms: Vec<f64>,
    /// DMS: the grid spacing of the domain.
    pub spacing: Option<f64>,
    /// Controls taken from the previous version.
    pub reused_controls: usize,
    /// Given a previous version, why it (or its domain) was not used.
    pub cold_start: Option<String>,
    /// Where the fit's time went.
    pub stages: PlanarStages,
}

/// Wall and process CPU time of one stage of a planar fit, summed over its calls. Process
/// CPU counts every thread of the process, other jobs' included: a figure for benchmarks
/// that run one fit at a time.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct StageTime {
    /// Wall-clock milliseconds.
    pub wall_ms: f64,
    /// Process CPU milliseconds (user + system, all threads).
    pub cpu_ms: f64,
    /// Calls summed.
    pub calls: usize,
}

impl StageTime {
    /// Runs `f`, adding its time to this stage.
    pub(crate) fn time<R>(&mut self, f: impl FnOnce() -> R) -> R {
        let (wall, cpu) = (Instant::now(), process_cpu_ms());
        let result = f();
        self.wall_ms += wall.elapsed().as_secs_f64() * 1e3;
        self.cpu_ms += process_cpu_ms() - cpu;
        self.calls += 1;
        result
    }
}

/// The stages of a planar fit after its domain is built and its data located.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PlanarStages {
    /// The first fit at the mapped parameters (collocation rows and the solve).
    pub first_fit: StageTime,
    /// Foot points of the data, after the first fit and after every round.
    pub feet: StageTime,
    /// The rounds' collocation rows at the foot points.
    pub rows: StageTime,
    /// The rounds' normal-matrix assembly and solve.
    pub solves: StageTime,
}

/// CPU time of the process so far, in ms (0 where the clock is not available).
pub fn process_cpu_ms() -> f64 {
    let mut t = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: `t` is a valid, writable timespec; the call only writes it.
    let ok = unsafe { libc::clock_gettime(libc::CLOCK_PROCESS_CPUTIME_ID, &mut t) } == 0;
    if ok {
        t.tv_sec as f64 * 1e3 + t.tv_nsec as f64 * 1e-6
    } else {
        0.0
    }
}

/// The model of a fit as a planar surface (B-patch and DMS models only).
pub(crate) fn planar_surface(model: &SurfaceModel) -> Option<&dyn PlanarSurface> {
    match model {
        SurfaceModel::BPatch(b) => Some(b.as_ref() as &dyn PlanarSurface),
        SurfaceModel::Dms(d) => Some(d.as_ref() as &dyn PlanarSurface),
        _ => None,
    }
}
