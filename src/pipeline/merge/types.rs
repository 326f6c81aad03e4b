//! What the merge's stages share: its options, a scan's samples, the merged mesh.

use crate::TriMesh;
use glam::DVec3;

/// A cell of the merge grid: cell (i, j, k) spans [i, i+1] x [j, j+1] x [k, k+1] cells;
/// corner (i, j, k) sits at (i, j, k) cells from the origin.
pub type CellKey = [i32; 3];

/// How scans are merged.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct MergeOptions {
    /// The merge grid's cell size in metres, fixed for the object; 0: from the scans
    /// (`cell_edges`).
    pub cell: f64,
    /// Cell size of the merge grid in median edge lengths of the object's coarsest scan
    /// (about one merged vertex per `cell_edges^2` scan points of one view).
    pub cell_edges: f64,
    /// Radius of the samples averaged at a point, in cells. The function is defined where
    /// a sample lies within it, and every corner of a cell the surface crosses must be: a
    /// corner lies up to sqrt(3) cells from the surface, plus the gap to the nearest sample
    /// (half the scan's spacing), so it is well over 1.73.
    pub radius_cells: f64,
    /// Gaussian width of their weights, in cells.
    pub sigma_cells: f64,
    /// Vertex rings over which a scan's weight ramps up from its rim.
    pub ramp_rings: usize,
    /// The weight of a scan's rim vertices (the ramp's start): where a view alone covers
    /// the object its rim still counts.
    pub rim_weight: f64,
    /// Samples inside a scan's triangles with an edge over this many median edges (a
    /// range grid's cell diagonal is 1.4: the triangles stretched where the view grazes
    /// the object), at most that far apart; 0: the scan's vertices only. At 2, every point
    /// of such a triangle lies within 1.15 edges of a sample, about `keep_cells` at
    /// `cell_edges`, so the merge keeps its vertices there.
    pub fill_spacing_edges: f64,
    /// Projections of each vertex onto the zero set.
    pub projections: usize,
    /// A merged vertex is kept only within this many cells of a sample: the surface stops
    /// where the data stops.
    pub keep_cells: f64,
    /// A merged vertex is dropped where it stands further than this many cells beyond the
    /// data: beyond the convex hull of the samples around it, in their tangent plane. At 0
    /// the surface stops up to a cell short of each view's rim, and where the sheet rule
    /// leaves out a crease's or a thin part's far side, vertices go there too (measured at
    /// 0.5 against 0 on six synthetic views of fertility: the model's RMS distance to the
    /// session's surface 0.121 -> 0.090; of CGAL's elephant 8.2e-4 -> 7.2e-4). Above 0, a
    /// vertex up to that far beyond is kept on the tangent plane of the local quadric at
    /// the rim point nearest to it (first-order past the data: on a 5 cm sphere in 1.9 mm
    /// cells a half-cell gap stands about 9 um off; the quadric itself, extrapolated,
    /// stood 340 um off at a grazing rim). (A rule on the samples' weighted centroid
    /// instead moved with the weights' ramp at a scan's rim and with the samples' spacing:
    /// it either stopped two vertex rings short of the bunny's rims or extrapolated on a
    /// sphere's steep ones.)
    pub rim_overhang_cells: f64,
    /// Close the holes the meshing leaves inside the data (holes whose centre lies within
    /// the samples' hull; wider ones, where no scan saw the object, stay open).
    pub close_holes: bool,
}

impl Default for MergeOptions {
    fn default() -> Self {
        Self {
            cell: 0.0,
            cell_edges: 1.5,
            radius_cells: 2.5,
            sigma_cells: 1.0,
            ramp_rings: 6,
            rim_weight: 0.05,
            fill_spacing_edges: 2.0,
            projections: 2,
            keep_cells: 0.75,
            rim_overhang_cells: 0.5,
            close_holes: true,
        }
    }
}

/// One scan's oriented samples in the object frame.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ScanSamples {
    /// The points (the scan's vertices that some triangle uses, then points inside its
    /// stretched triangles).
    pub points: Vec<DVec3>,
    /// Their unit normals (area-weighted face normals; the scan's orientation).
    pub normals: Vec<DVec3>,
    /// Their weights in (0, 1]: `rim_weight` on the rim, 1 from `ramp_rings` rings in.
    pub weights: Vec<f64>,
    /// The scan mesh's median edge length, its sampling spacing (0 without edges).
    pub spacing: f64,
}

/// The merged data: one vertex per crossed grid cell, triangulated by surface nets.
#[derive(Clone, Debug, Default)]
pub struct Merged {
    /// The vertices and triangles (oriented as the scans' normals; a few non-manifold
    /// configurations of surface nets are left for cleaning).
    pub mesh: TriMesh,
    /// Each vertex's unit normal (of the implicit function).
    pub normals: Vec<DVec3>,
    /// Each vertex's grid cell: vertices of two merges with the same cell are the same
    /// place of the object.
    pub cells: Vec<CellKey>,
    /// The cell size used.
    pub cell: f64,
    /// Grid corners at which the implicit function was evaluated in this update.
    pub corners_evaluated: usize,
    /// Candidate cells whose vertex was computed in this update (all of them in a merge
    /// from scratch, those around the changed scans' samples in a `MergeField` update).
    pub recomputed_cells: usize,
    /// Crossed cells whose vertex was dropped past the data's rim (no sample within
    /// `keep_cells`, beyond the samples' hull, or too few for the quadric).
    pub dropped_vertices: usize,
    /// Holes inside the data closed (see `MergeOptions::close_holes`).
    pub closed_holes: usize,
}
