//! Point clouds into the worker: a mesh without triangles is triangulated over the plane it
//! is a height field over (`remesh::points`) and goes through the scan path, which fits its
//! points (the triangulation only gives them neighbours and a planar map).

use super::{Domain, WorkerConfig};
use crate::pipeline::PipelineError;
use crate::remesh::points::{triangulate_points, PointCloudOptions, PointCloudStats};
use crate::TriMesh;
use std::borrow::Cow;

/// The input with triangles: a mesh as given, or a point cloud triangulated, with what
/// the triangulation did and the configuration to fit it with.
pub(super) struct WithFaces<'a> {
    pub(super) mesh: Cow<'a, TriMesh>,
    pub(super) cloud: Option<PointCloudStats>,
    pub(super) cfg: Cow<'a, WorkerConfig>,
    /// Time the triangulation took.
    pub(super) triangulation_ms: f64,
}

impl WithFaces<'_> {
    /// report.json's `point_cloud` (none for meshes).
    pub(super) fn report(&self) -> Option<serde_json::Value> {
        let mut v = serde_json::to_value(self.cloud.as_ref()?).ok()?;
        v["triangulation_ms"] = serde_json::json!(self.triangulation_ms);
        Some(v)
    }
}

/// A mesh passes as it is; a point cloud is triangulated, and fitted through the scan path
/// whatever `fit.domain` says but `mesh`, which is refused (the object path simplifies a
/// mesh; a cloud that is no height field, a whole object, is refused by the triangulation).
pub(super) fn with_faces<'a>(
    mesh: &'a TriMesh,
    cfg: &'a WorkerConfig,
) -> Result<WithFaces<'a>, PipelineError> {
    if !mesh.triangles.is_empty() {
        return Ok(WithFaces {
            mesh: Cow::Borrowed(mesh),
            cloud: None,
            cfg: Cow::Borrowed(cfg),
            triangulation_ms: 0.0,
        });
    }
    if cfg.fit.domain == Domain::Mesh {
        return Err(PipelineError::PointCloudAsObject);
    }
    let start = std::time::Instant::now();
    let t = triangulate_points(&mesh.positions, &PointCloudOptions::default())?;
    let triangulation_ms = start.elapsed().as_secs_f64() * 1e3;
    let s = &t.stats;
    if s.left_out_points > 0 {
        // Said where it happens, as dropped components are: points the fit does not see.
        tracing::warn!(
            points = s.points,
            left_out = s.left_out_points,
            "{} of {} points are in no triangle (strays beyond gaps wider than {} local spacings) and are not fitted",
            s.left_out_points,
            s.points,
            PointCloudOptions::default().max_edge_factor
        );
    }
    let mut scan_cfg = cfg.clone();
    scan_cfg.fit.domain = Domain::Grid;
    Ok(WithFaces {
        mesh: Cow::Owned(t.mesh),
        cloud: Some(t.stats),
        cfg: Cow::Owned(scan_cfg),
        triangulation_ms,
    })
}
