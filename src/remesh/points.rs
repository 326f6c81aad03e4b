//! From a point cloud to a triangle mesh the scan path can map to the plane. The points are
//! projected onto a plane (their principal plane first, then the plane that folds the
//! fewest triangles of that first triangulation, as for range scans), triangulated by
//! 2D Delaunay (`delaunator`), and two kinds of triangles are removed: those that bridge
//! gaps (an edge longer than `max_edge_factor` times the local point spacing, the mean
//! distance to the `neighbours` nearest points in space, found with an `rstar` R-tree) and
//! the slivers Delaunay leaves along concave rims (a rim edge whose opposite angle is
//! obtuse beyond `max_rim_angle_deg`), peeled from the outside in.
//!
//! The mesh's vertices are the points themselves, in input order: the scan path fits every
//! point, never a resampling of the triangulation. Points that end up in no triangle (their
//! every edge bridged a gap: strays) are left out and counted.
//!
//! Why `delaunator`: it triangulates the points as given and returns triangles as indices
//! into the input slice (no vertex handles to map back, the input order is kept), its
//! orientation tests are robust, and its half-edge array gives the neighbours the rim
//! peeling walks. `spade` would do too, at the price of a vertex type and a handle map.
//!
//! Closed objects are no height field over any plane: projected, their sheets interleave,
//! and what survives the removals is scattered triangles, not one piece holding most
//! points; such clouds are refused here (`NotHeightField`): they need surface
//! reconstruction, which the worker then does (`pipeline::merge::reconstruct_cloud`).

use super::planar::PlaneFrame;
use crate::mesh::stats::UnionFind;
use crate::mesh::TriMesh;
use glam::DVec3;
use rayon::prelude::*;

/// How a point cloud is triangulated.
#[derive(Clone, Copy, Debug)]
pub struct PointCloudOptions {
    /// Neighbours whose mean distance is a point's local spacing.
    pub neighbours: usize,
    /// Edges longer than this multiple of the larger local spacing of their ends bridge a
    /// gap: their triangles are removed.
    pub max_edge_factor: f64,
    /// Rim triangles whose angle opposite the rim exceeds this (degrees) are slivers.
    pub max_rim_angle_deg: f64,
    /// Share of the points that must end up in sizeable pieces of triangles; below it the
    /// cloud is not a height field over any plane tried.
    pub min_covered_share: f64,
}

impl Default for PointCloudOptions {
    fn default() -> Self {
        Self {
            neighbours: 6,
            max_edge_factor: 3.0,
            max_rim_angle_deg: 120.0,
            min_covered_share: 0.8,
        }
    }
}

/// What triangulating a cloud did, for the report.
#[derive(Clone, Debug, serde::Serialize)]
pub struct PointCloudStats {
    /// Points of the cloud.
    pub points: usize,
    /// Points in at least one triangle: what the fit uses.
    pub triangulated_points: usize,
    /// Points in no triangle (strays beyond every gap), left out of the fit.
    pub left_out_points: usize,
    /// Points in edge-connected pieces of at least 1 % of the triangles: what tells a
    /// surface from scattered triangles (the scan path then fits the largest component by
    /// default, `--components all` every sizeable one).
    pub sizeable_piece_points: usize,
    /// Triangles of the Delaunay triangulation.
    pub delaunay_triangles: usize,
    /// Triangles removed for an edge bridging a gap.
    pub removed_bridging: usize,
    /// Rim slivers peeled.
    pub removed_slivers: usize,
    /// Triangles kept.
    pub triangles: usize,
    /// Median local spacing (mean distance to the nearest neighbours).
    pub median_spacing: f64,
    /// `principal` (the points' principal plane) or `least_folds` (the plane that folds
    /// the fewest triangles of the first triangulation).
    pub plane: &'static str,
    /// Angle between the projection plane's normal and the principal plane's, degrees.
    pub tilt_deg: f64,
}

/// A triangulated cloud: `mesh.positions` are the points, in order.
#[derive(Clone, Debug)]
pub struct PointTriangulation {
    /// The points and the triangles kept.
    pub mesh: TriMesh,
    /// What was done.
    pub stats: PointCloudStats,
}

/// Why a point cloud gets no triangulation.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum PointCloudError {
    /// Fewer than three distinct points.
    #[error("a point cloud of {points} points: at least 3 are needed for a surface")]
    TooFewPoints {
        /// Points given.
        points: usize,
    },
    /// All points on one line (or one point).
    #[error("the {points} points lie on a line: no surface to fit")]
    Collinear {
        /// Points given.
        points: usize,
    },
    /// Too few points form one surface over the best plane: a closed or overhanging cloud.
    #[error("only {:.1} % of the {points} points form sizeable pieces of surface over the best plane found (at least {:.0} % needed): the cloud is not a height field over any plane (a whole object?): it needs surface reconstruction (the worker reconstructs such clouds, `pipeline::merge::reconstruct_cloud`)", 100.0 * covered, 100.0 * min)]
    NotHeightField {
        /// Points given.
        points: usize,
        /// Share of them in a triangle.
        covered: f64,
        /// The share required.
        min: f64,
    },
}

impl PointCloudError {
    /// A stable snake_case name of the refusal; a cloud that needs surface reconstruction
    /// is `unsupported` here (valid, but no triangulation takes it: the worker reconstructs
    /// it instead, an object session refuses it as a scan).
    pub fn kind(&self) -> &'static str {
        match self {
            Self::TooFewPoints { .. } => "too_few_points",
            Self::Collinear { .. } => "degenerate_point_cloud",
            Self::NotHeightField { .. } => "unsupported",
        }
    }
}

/// Triangulates a point cloud over the plane it is a height field over (see the module
/// docs); refuses clouds that are none.
pub fn triangulate_points(
    points: &[DVec3],
    opts: &PointCloudOptions,
) -> Result<PointTriangulation, PointCloudError> {
    let n = points.len();
    if n < 3 {
        return Err(PointCloudError::TooFewPoints { points: n });
    }
    let principal = principal_frame(points).ok_or(PointCloudError::Collinear { points: n })?;
    let spacing = local_spacing(points, opts.neighbours);
    let first = triangulate_over(points, &spacing, &principal, opts);
    if first.delaunay == 0 {
        return Err(PointCloudError::Collinear { points: n });
    }
    let mut best = (first, "principal", 0.0);
    // Range scans are height fields along the line of sight, which can be tens of degrees
    // off the principal plane's normal: the plane folding the fewest triangles of the first
    // triangulation is tried too, and the one covering more points kept.
    if best.0.sizeable < n {
        if let Some(frame) = PlaneFrame::fit_least_folds(&best.0.mesh) {
            let tilt = frame
                .normal()
                .dot(principal.normal())
                .abs()
                .clamp(0.0, 1.0)
                .acos()
                .to_degrees();
            if tilt > 1.0 {
                let second = triangulate_over(points, &spacing, &frame, opts);
                if second.sizeable > best.0.sizeable {
                    best = (second, "least_folds", tilt);
                }
            }
        }
    }
    let (t, plane, tilt_deg) = best;
    let covered = t.sizeable as f64 / n as f64;
    if covered < opts.min_covered_share {
        return Err(PointCloudError::NotHeightField {
            points: n,
            covered,
            min: opts.min_covered_share,
        });
    }
    let mut sorted = spacing;
    let mid = sorted.len() / 2;
    let median_spacing = *sorted.select_nth_unstable_by(mid, f64::total_cmp).1;
    let stats = PointCloudStats {
        points: n,
        triangulated_points: t.covered,
        left_out_points: n - t.covered,
        sizeable_piece_points: t.sizeable,
        delaunay_triangles: t.delaunay,
        removed_bridging: t.bridging,
        removed_slivers: t.slivers,
        triangles: t.mesh.triangles.len(),
        median_spacing,
        plane,
        tilt_deg,
    };
    Ok(PointTriangulation {
        mesh: t.mesh,
        stats,
    })
}

/// The plane of the two largest principal axes through the centroid.
fn principal_frame(points: &[DVec3]) -> Option<PlaneFrame> {
    let n = points.len() as f64;
    let origin = points.iter().copied().sum::<DVec3>() / n;
    let (values, axes) = crate::numeric::principal_axes(origin, points.iter().copied());
    let (major, middle) = (values[0], values[1]);
    if major.is_nan() || major <= 0.0 || middle <= 1e-12 * major {
        return None;
    }
    let e1 = axes[0].try_normalize()?;
    let e2 = (axes[1] - e1 * axes[1].dot(e1)).try_normalize()?;
    Some(PlaneFrame { origin, e1, e2 })
}

/// Each point's mean distance to its `k` nearest other points.
fn local_spacing(points: &[DVec3], k: usize) -> Vec<f64> {
    let tree = rstar::RTree::bulk_load(points.iter().map(|p| p.to_array()).collect());
    let k = k.max(1);
    points
        .par_iter()
        .map(|p| {
            // The first hit is the point itself.
            let (sum, count) = tree
                .nearest_neighbor_iter_with_distance_2(&p.to_array())
                .skip(1)
                .take(k)
                .fold((0.0, 0usize), |(s, c), (_, d2)| (s + d2.sqrt(), c + 1));
            if count == 0 {
                0.0
            } else {
                sum / count as f64
            }
        })
        .collect()
}

/// One triangulation over one plane.
struct Attempt {
    mesh: TriMesh,
    delaunay: usize,
    bridging: usize,
    slivers: usize,
    /// Points in a kept triangle.
    covered: usize,
    /// Points in sizeable pieces.
    sizeable: usize,
}

/// Delaunay over `frame`, then the two removals of the module docs.
fn triangulate_over(
    points: &[DVec3],
    spacing: &[f64],
    frame: &PlaneFrame,
    opts: &PointCloudOptions,
) -> Attempt {
    let projected: Vec<delaunator::Point> = points
        .iter()
        .map(|p| {
            let q = frame.project(*p);
            delaunator::Point { x: q.x, y: q.y }
        })
        .collect();
    let dt = delaunator::triangulate(&projected);
    // Delaunator's order: half-edge `3 t + j` runs from corner j to corner j + 1.
    let triangles: Vec<[usize; 3]> = dt
        .triangles
        .chunks_exact(3)
        .map(|t| [t[0], t[1], t[2]])
        .collect();
    // Counter-clockwise in the frame, so that normals agree with the plane's.
    let oriented = |t: &[usize; 3]| {
        let (a, b, c) = (&projected[t[0]], &projected[t[1]], &projected[t[2]]);
        let cross = (b.x - a.x) * (c.y - a.y) - (b.y - a.y) * (c.x - a.x);
        let t = t.map(|v| v as u32);
        if cross >= 0.0 {
            t
        } else {
            [t[0], t[2], t[1]]
        }
    };
    let bridges = |a: usize, b: usize| {
        points[a].distance(points[b]) > opts.max_edge_factor * spacing[a].max(spacing[b])
    };
    let mut kept: Vec<bool> = triangles
        .iter()
        .map(|&[a, b, c]| !(bridges(a, b) || bridges(b, c) || bridges(c, a)))
        .collect();
    let bridging = kept.iter().filter(|k| !**k).count();
    let slivers = peel_rim_slivers(points, &triangles, &dt.halfedges, &mut kept, opts);
    let sizeable = sizeable_piece_points(points.len(), &triangles, &dt.halfedges, &kept);
    let mut in_triangle = vec![false; points.len()];
    let kept_triangles: Vec<[u32; 3]> = triangles
        .iter()
        .zip(&kept)
        .filter(|(_, k)| **k)
        .map(|(t, _)| {
            for &v in t {
                in_triangle[v] = true;
            }
            oriented(t)
        })
        .collect();
    Attempt {
        mesh: TriMesh::new(points.to_vec(), kept_triangles),
        delaunay: triangles.len(),
        bridging,
        slivers,
        covered: in_triangle.iter().filter(|c| **c).count(),
        sizeable,
    }
}

/// The triangle across edge j of triangle t (Delaunator's half-edges), if any.
fn across(halfedges: &[usize], t: usize, j: usize) -> Option<usize> {
    let e = *halfedges.get(3 * t + j)?;
    (e != delaunator::EMPTY).then_some(e / 3)
}

/// Smallest piece of triangles that counts as surface: 1 % of the kept triangles, and at
/// least this many.
const MIN_PIECE_TRIANGLES: usize = 64;

/// Points of the edge-connected pieces of kept triangles that are sizeable (see
/// `MIN_PIECE_TRIANGLES`). A height field gives a few pieces holding nearly every point; a
/// cloud projected across itself (a closed object) keeps scattered triangles whose
/// neighbours mix the sheets, in pieces of a few triangles.
fn sizeable_piece_points(
    points: usize,
    triangles: &[[usize; 3]],
    halfedges: &[usize],
    kept: &[bool],
) -> usize {
    let mut pieces = UnionFind::new(triangles.len());
    let live = || (0..triangles.len()).filter(|&t| kept[t]);
    for t in live() {
        for j in 0..3 {
            if let Some(o) = across(halfedges, t, j).filter(|&o| kept.get(o) == Some(&true)) {
                pieces.union(t, o);
            }
        }
    }
    let mut size = vec![0usize; triangles.len()];
    for t in live() {
        size[pieces.find(t)] += 1;
    }
    let min = MIN_PIECE_TRIANGLES.max(live().count() / 100);
    let mut counted = vec![false; points];
    for t in live() {
        if size[pieces.find(t)] >= min {
            for &v in &triangles[t] {
                counted[v] = true;
            }
        }
    }
    counted.iter().filter(|c| **c).count()
}

/// Removes kept triangles whose rim edge (one with no kept triangle across) faces an
/// obtuse angle beyond the limit, from the outside in, never leaving a point in no
/// triangle. `triangles` and `halfedges` are Delaunator's: half-edge `3 t + j` runs from
/// corner j of triangle t to corner j + 1, its twin is `halfedges[3 t + j]` (or `EMPTY` on
/// the hull). Returns how many were removed.
fn peel_rim_slivers(
    points: &[DVec3],
    triangles: &[[usize; 3]],
    halfedges: &[usize],
    kept: &mut [bool],
    opts: &PointCloudOptions,
) -> usize {
    let cos_limit = opts.max_rim_angle_deg.to_radians().cos();
    let mut uses = vec![0u32; points.len()];
    for (t, _) in triangles.iter().zip(kept.iter()).filter(|(_, k)| **k) {
        for &v in t {
            uses[v] += 1;
        }
    }
    // A kept neighbour across edge j of t.
    let kept_across = |kept: &[bool], t: usize, j: usize| {
        across(halfedges, t, j).filter(|&o| kept.get(o) == Some(&true))
    };
    let mut queue: Vec<usize> = (0..triangles.len()).filter(|&t| kept[t]).collect();
    let mut removed = 0;
    while let Some(t) = queue.pop() {
        if !kept[t] {
            continue;
        }
        let tri = triangles[t];
        let sliver = (0..3).any(|j| {
            if kept_across(kept, t, j).is_some() {
                return false;
            }
            let (a, b, c) = (
                points[tri[j]],
                points[tri[(j + 1) % 3]],
                points[tri[(j + 2) % 3]],
            );
            let (u, v) = (a - c, b - c);
            let denom = u.length() * v.length();
            denom > 0.0 && u.dot(v) / denom < cos_limit
        });
        if !sliver || tri.iter().any(|&v| uses[v] <= 1) {
            continue;
        }
        kept[t] = false;
        removed += 1;
        for &v in &tri {
            uses[v] -= 1;
        }
        queue.extend((0..3).filter_map(|j| kept_across(kept, t, j)));
    }
    removed
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A jittered grid over a bumpy height field, with a square hole in the middle.
    fn sheet(hole: bool) -> Vec<DVec3> {
        let mut pts = Vec::new();
        for i in 0..40 {
            for j in 0..30 {
                if hole && (15..22).contains(&i) && (10..18).contains(&j) {
                    continue;
                }
                let jitter = ((i * 7 + j * 13) % 11) as f64 * 0.02;
                let (x, y) = (i as f64 + jitter, j as f64 - jitter);
                pts.push(DVec3::new(x, y, 3.0 * (0.2 * x).sin() * (0.15 * y).cos()));
            }
        }
        pts
    }

    #[test]
    fn a_height_field_keeps_every_point_and_its_holes() {
        let pts = sheet(true);
        let t = triangulate_points(&pts, &PointCloudOptions::default()).expect("a sheet");
        assert_eq!(t.stats.left_out_points, 0);
        assert_eq!(t.mesh.positions, pts);
        // No kept edge crosses the hole (7 x 8 grid steps wide).
        let longest = t
            .mesh
            .triangles
            .iter()
            .flat_map(|tri| (0..3).map(move |k| (tri[k] as usize, tri[(k + 1) % 3] as usize)))
            .map(|(a, b)| pts[a].distance(pts[b]))
            .fold(0.0, f64::max);
        assert!(longest < 3.0, "an edge of {longest} bridges the hole");
        assert!(t.stats.removed_bridging > 0);
    }

    #[test]
    fn a_closed_cloud_is_refused_as_unsupported() {
        // A sphere: no plane sees it as a height field.
        let mut pts = Vec::new();
        let n = 2000;
        let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
        for i in 0..n {
            let y = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
            let r = (1.0 - y * y).sqrt();
            let phi = golden * i as f64;
            pts.push(DVec3::new(r * phi.cos(), y, r * phi.sin()));
        }
        let e = triangulate_points(&pts, &PointCloudOptions::default()).expect_err("closed");
        assert_eq!(e.kind(), "unsupported");
        assert!(e.to_string().contains("surface reconstruction"), "{e}");
        let line: Vec<DVec3> = (0..10).map(|i| DVec3::X * i as f64).collect();
        assert_eq!(
            triangulate_points(&line, &PointCloudOptions::default())
                .expect_err("a line")
                .kind(),
            "degenerate_point_cloud"
        );
    }
}
