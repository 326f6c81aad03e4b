//! Point clouds into the worker. A mesh without triangles is triangulated over the plane it
//! is a height field over (`remesh::points`) and goes through the scan path, which fits its
//! points (the triangulation only gives them neighbours and a planar map). A cloud that is
//! no height field over any plane (a whole object), or any cloud under `fit.domain =
//! "mesh"`, is reconstructed instead (`merge::reconstruct_cloud`: oriented normals, the
//! scans' merge) and the merged mesh takes the path a mesh would; its report then also
//! measures the cloud's own points against the fitted surface.

use super::{Domain, WorkerConfig};
use crate::pipeline::merge::{reconstruct_cloud, CloudReconstruction, MergeOptions};
use crate::pipeline::PipelineError;
use crate::remesh::oriented::CLEAN_WIDTH_SPACINGS;
use crate::remesh::points::{
    triangulate_points, PointCloudError, PointCloudOptions, PointCloudStats,
};
use crate::TriMesh;
use glam::DVec3;
use std::borrow::Cow;

/// How a point cloud became a mesh.
pub(super) enum CloudRoute {
    /// Triangulated over a plane: the mesh's vertices are the points.
    HeightField(PointCloudStats),
    /// Reconstructed: the mesh is the merge of the points, which are measured against the
    /// fitted surface afterwards.
    Reconstructed(CloudReconstruction),
}

/// The input with triangles: a mesh as given, or a point cloud triangulated or
/// reconstructed, with what that did and the configuration to fit it with.
pub(super) struct WithFaces<'a> {
    pub(super) mesh: Cow<'a, TriMesh>,
    pub(super) cloud: Option<CloudRoute>,
    pub(super) cfg: Cow<'a, WorkerConfig>,
    /// Time the triangulation or reconstruction took.
    pub(super) triangulation_ms: f64,
    /// The cloud's points when the fitted mesh is not made of them (a reconstruction).
    pub(super) measured_points: Option<&'a [DVec3]>,
}

impl WithFaces<'_> {
    /// report.json's `point_cloud` (none for meshes).
    pub(super) fn report(&self) -> Option<serde_json::Value> {
        let mut v = match self.cloud.as_ref()? {
            CloudRoute::HeightField(stats) => {
                let mut v = serde_json::to_value(stats).ok()?;
                v["route"] = serde_json::json!("height_field");
                v
            }
            CloudRoute::Reconstructed(stats) => serde_json::to_value(stats).ok()?,
        };
        v["triangulation_ms"] = serde_json::json!(self.triangulation_ms);
        Some(v)
    }
}

/// A mesh passes as it is; a point cloud is triangulated and fitted through the scan path,
/// or, when it is no height field or `fit.domain` is `mesh`, reconstructed and fitted as a
/// mesh would be (see the module docs).
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
            measured_points: None,
        });
    }
    let start = std::time::Instant::now();
    if cfg.fit.domain == Domain::Mesh {
        return reconstructed(mesh, cfg, start);
    }
    let t = match triangulate_points(&mesh.positions, &PointCloudOptions::default()) {
        Ok(t) => t,
        Err(PointCloudError::NotHeightField { covered, .. }) => {
            tracing::info!(
                points = mesh.positions.len(),
                covered_pct = format!("{:.1}", 100.0 * covered),
                "the cloud is no height field over any plane (a whole object): reconstructing a mesh from it"
            );
            return reconstructed(mesh, cfg, start);
        }
        Err(e) => return Err(e.into()),
    };
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
        cloud: Some(CloudRoute::HeightField(t.stats)),
        cfg: Cow::Owned(scan_cfg),
        triangulation_ms,
        measured_points: None,
    })
}

/// The cloud reconstructed (`merge::reconstruct_cloud` with the merge's defaults), its
/// mesh fitted under `cfg` as any mesh, with the control budget a share of the cloud's
/// points rather than of the merged vertices (each stands for about two points; an
/// object session's budget is scaled the same way). On noisy clouds, whose merge is
/// coarser than their spacing, a merged vertex stands for more points but the budget
/// grows no further than on clean ones: the extra points carry noise, not detail (on
/// CGAL's `sphere_20k.xyz`, 7 points a vertex, the full share fitted the noise with 1051
/// controls).
fn reconstructed<'a>(
    cloud: &'a TriMesh,
    cfg: &'a WorkerConfig,
    start: std::time::Instant,
) -> Result<WithFaces<'a>, PipelineError> {
    let made = reconstruct_cloud(&cloud.positions, &MergeOptions::default())?;
    let mut merged_cfg = cfg.clone();
    let points_per_vertex = (made.stats.oriented_points as f64
        / made.stats.merged_vertices.max(1) as f64)
        .clamp(1.0, CLEAN_WIDTH_SPACINGS * CLEAN_WIDTH_SPACINGS);
    let scan = &mut merged_cfg.fit.scan;
    scan.target_controls_pct = (scan.target_controls_pct * points_per_vertex).min(100.0);
    Ok(WithFaces {
        mesh: Cow::Owned(made.mesh),
        cloud: Some(CloudRoute::Reconstructed(made.stats)),
        cfg: Cow::Owned(merged_cfg),
        triangulation_ms: start.elapsed().as_secs_f64() * 1e3,
        measured_points: Some(&cloud.positions),
    })
}
