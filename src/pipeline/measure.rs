//! How far points lie from a surface: a fine tessellation of the fit and point-to-mesh
//! distances (the tessellation's own chord error is a small share of scan noise).

use crate::mesh::distance::MeshDistance;
use crate::pipeline::output::{tessellate, tessellate_mesh_faces};
use crate::pipeline::{PatchFit, SurfaceModel};
use crate::TriMesh;
use glam::DVec3;
use rayon::prelude::*;

/// Segments per control-face side of a control-mesh surface's measuring tessellation.
const MEASURE_PER_FACE: usize = 8;
/// Segments in all of a grid or Bezier surface's measuring tessellation: a bunny-sized
/// scan's segments are then about 0.3 mm long, whose chord error on a 1 cm radius is about
/// 1 um (2048 made 8 million triangles, seconds per update for a daemon).
const MEASURE_SEGMENTS: usize = 512;

/// Statistics of the distances of a point set to a mesh.
#[derive(Clone, Copy, Debug, Default, serde::Serialize)]
pub struct DistanceStats {
    /// Points measured.
    pub points: usize,
    /// Root mean square distance.
    pub rms: f64,
    /// Median distance.
    pub median: f64,
    /// 95th percentile.
    pub p95: f64,
    /// Largest distance.
    pub max: f64,
}

/// The fitted surface as a fine triangle mesh (untrimmed).
pub fn surface_mesh(fit: &PatchFit) -> TriMesh {
    let tess = match &fit.model {
        SurfaceModel::Mesh(_) => tessellate_mesh_faces(fit, MEASURE_PER_FACE),
        _ => tessellate(fit, MEASURE_SEGMENTS, None),
    };
    TriMesh::new(tess.positions, tess.triangles)
}

/// The fitted surface at every data point's parameter: where the surface was fitted,
/// never where it only extrapolates (a grid's untrimmed cells).
pub fn surface_points_at_data(fit: &PatchFit) -> Vec<DVec3> {
    let evaluate = fit.model.as_surface().evaluator(&fit.controls);
    fit.params
        .par_iter()
        .map(|p| evaluate(*p).position)
        .collect()
}

/// Points farther than this many mean edge lengths from every vertex of the mesh are
/// measured to the nearest vertex: the bucket search's cost grows with the cube of the
/// distance (the parts of a scan no surface covers took minutes when it grew with the
/// fourth power), and that far out the nearest vertex is within one edge of the nearest
/// point.
const FAR_EDGES: f64 = 16.0;

/// Distances of `points` to `mesh` (points with no distance, e.g. non-finite, are left
/// out); points far from it (`FAR_EDGES`) measured to its nearest vertex.
pub fn distance_stats(points: &[DVec3], mesh: &TriMesh) -> DistanceStats {
    MeshMeasure::new(mesh).stats(points)
}

/// A mesh's distance queries, built once for many point sets (every scan of an object
/// against its surface: built per scan, the five bunny scans' measure took 1.05 s).
pub struct MeshMeasure<'a> {
    query: MeshDistance<'a>,
    vertices: rstar::RTree<[f64; 3]>,
    far: f64,
}

impl<'a> MeshMeasure<'a> {
    /// The queries of `mesh`: its triangles, and its vertices for points far off it.
    pub fn new(mesh: &'a TriMesh) -> Self {
        let query = MeshDistance::new(mesh);
        let far = FAR_EDGES * query.mean_edge();
        let vertices = mesh.positions.iter().map(|v| v.to_array()).collect();
        Self {
            query,
            vertices: rstar::RTree::bulk_load(vertices),
            far,
        }
    }

    /// [`distance_stats`] of `points` to this mesh.
    pub fn stats(&self, points: &[DVec3]) -> DistanceStats {
        let d: Vec<f64> = points
            .par_iter()
            .with_min_len(256)
            .filter(|q| q.is_finite())
            .filter_map(|q| {
                let nearest = self.vertices.nearest_neighbor(&q.to_array())?;
                let to_vertex = q.distance(DVec3::from_array(*nearest));
                match to_vertex > self.far {
                    true => Some(to_vertex),
                    false => self.query.distance(*q),
                }
            })
            .collect();
        summarise(d)
    }
}

/// Median, p95, RMS and largest of the distances `d`.
fn summarise(mut d: Vec<f64>) -> DistanceStats {
    if d.is_empty() {
        return DistanceStats::default();
    }
    d.sort_unstable_by(f64::total_cmp);
    let at = |q: f64| d[((d.len() - 1) as f64 * q).round() as usize];
    DistanceStats {
        points: d.len(),
        rms: (d.iter().map(|x| x * x).sum::<f64>() / d.len() as f64).sqrt(),
        median: at(0.5),
        p95: at(0.95),
        max: d[d.len() - 1],
    }
}
