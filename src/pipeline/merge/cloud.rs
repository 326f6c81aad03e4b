//! A whole-object point cloud (one that is no height field over any plane) made a mesh
//! by the same merge that joins registered scans: the points, with normals estimated and
//! oriented (`remesh::oriented`), are one view's oriented samples; the merge's
//! moving-least-squares zero set, meshed by surface nets, is the mesh the whole-object
//! path then fits. Each merged vertex is a weighted local average of the points around it
//! (so scanner noise is averaged, not interpolated), and the surface stops where the
//! points stop.

use super::field::MergeField;
use super::types::{MergeOptions, ScanSamples};
use crate::remesh::oriented::{oriented_normals, NORMAL_NEIGHBOURS};
use crate::TriMesh;
use glam::DVec3;

/// A reconstructed cloud: the mesh and how it was made.
#[derive(Clone, Debug)]
pub struct CloudMesh {
    /// The merged mesh (surface nets; cleaning comes with the fit).
    pub mesh: TriMesh,
    /// What the reconstruction did (report.json's `point_cloud`).
    pub stats: CloudReconstruction,
}

/// report.json's account of a cloud's reconstruction.
#[derive(Clone, Debug, serde::Serialize)]
pub struct CloudReconstruction {
    /// `"reconstruction"`: normals estimated and oriented, samples merged.
    pub route: &'static str,
    /// Points of the cloud.
    pub points: usize,
    /// Points that got a normal (their neighbours span a plane): the merge's samples.
    pub oriented_points: usize,
    /// Connected pieces of the neighbour graph (each oriented from its own top).
    pub pieces: usize,
    /// Orientation steps across normals over 60 degrees apart (sharp edges, thin parts).
    pub sharp_crossings: usize,
    /// Median local spacing of the points.
    pub median_spacing: f64,
    /// Their 90th percentile, which the cell covers.
    pub sparse_spacing: f64,
    /// Median RMS distance of a point's neighbourhood to its plane (the noise).
    pub noise: f64,
    /// Neighbours each normal was fitted to.
    pub normal_neighbours: usize,
    /// The merge's cell size (its Gaussian width): 1.5 sparse spacings on clean data, wider
    /// where the noise needs a wider average (`remesh::oriented::OrientedNormals::width`).
    pub cell: f64,
    /// Vertices of the merged mesh.
    pub merged_vertices: usize,
    /// Triangles of the merged mesh.
    pub merged_triangles: usize,
    /// Holes inside the points that the merge closed.
    pub closed_holes: usize,
}

/// Why a cloud gives no mesh.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum CloudError {
    /// Too few points with a normal for a surface, or no spacing between them.
    #[error("a point cloud of {points} points of which {oriented} have a normal: too few to reconstruct a surface from (at least {} needed)", MIN_ORIENTED_POINTS)]
    TooSparse {
        /// Points given.
        points: usize,
        /// Points whose neighbours span a plane.
        oriented: usize,
    },
    /// The merge found no surface (the points are scattered, or on a curve, not on a
    /// surface: a glTF POINTS outline of a square gave this).
    #[error("the {points} points gave no surface: they do not sample one (scattered, or along a curve; {merged} merged triangles)")]
    NoSurface {
        /// Points given.
        points: usize,
        /// Triangles the merge made.
        merged: usize,
    },
}

/// Fewest points with a normal a surface is reconstructed from: one point's neighbourhood.
const MIN_ORIENTED_POINTS: usize = NORMAL_NEIGHBOURS + 1;

/// Merged vertices a cloud is reconstructed with, about, at most: a cloud of millions of
/// points is merged on a coarser cell (by the square root of its excess) rather than
/// handing the fit millions of vertices, whose memory grows with them.
pub const MAX_MERGED_VERTICES: usize = 500_000;

/// Fewest merged triangles taken for a surface.
const MIN_MERGED_TRIANGLES: usize = 8;

/// Reconstructs a mesh from the points of a cloud (see the module docs). `opts` are the
/// merge's options; their `cell` is taken when set, the width the points' spacing and
/// noise call for otherwise (coarser on clouds of over `MAX_MERGED_VERTICES` points).
pub fn reconstruct_cloud(points: &[DVec3], opts: &MergeOptions) -> Result<CloudMesh, CloudError> {
    let oriented = oriented_normals(points);
    let mut samples = ScanSamples {
        spacing: oriented.spacing,
        ..ScanSamples::default()
    };
    for (p, n) in points.iter().zip(&oriented.normals) {
        if *n != DVec3::ZERO {
            samples.points.push(*p);
            samples.normals.push(*n);
            samples.weights.push(1.0);
        }
    }
    let too_sparse = CloudError::TooSparse {
        points: points.len(),
        oriented: samples.points.len(),
    };
    if samples.points.len() < MIN_ORIENTED_POINTS
        || oriented.width.is_nan()
        || oriented.width <= 0.0
    {
        return Err(too_sparse);
    }
    let cell = if opts.cell > 0.0 {
        opts.cell
    } else {
        let excess = samples.points.len() as f64 / MAX_MERGED_VERTICES as f64;
        oriented.width.max(oriented.spacing * excess.sqrt())
    };
    // The cloud has no triangles to fill and no rim to ramp from.
    let merge_opts = MergeOptions {
        fill_spacing_edges: 0.0,
        ramp_rings: 0,
        ..opts.clone()
    };
    let merged = MergeField::new(cell).update(&[&samples], &[&samples], &[], &merge_opts);
    if merged.mesh.triangles.len() < MIN_MERGED_TRIANGLES {
        return Err(CloudError::NoSurface {
            points: points.len(),
            merged: merged.mesh.triangles.len(),
        });
    }
    let stats = CloudReconstruction {
        route: "reconstruction",
        points: points.len(),
        oriented_points: samples.points.len(),
        pieces: oriented.pieces,
        sharp_crossings: oriented.sharp_crossings,
        median_spacing: oriented.spacing,
        sparse_spacing: oriented.sparse_spacing,
        noise: oriented.noise,
        normal_neighbours: oriented.neighbours,
        cell,
        merged_vertices: merged.mesh.positions.len(),
        merged_triangles: merged.mesh.triangles.len(),
        closed_holes: merged.closed_holes,
    };
    Ok(CloudMesh {
        mesh: merged.mesh,
        stats,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::stats::mesh_stats;

    /// `n` points of an ellipsoid with semi-axes `axes` (a Fibonacci lattice mapped onto
    /// it), each moved along the radius by a deterministic noise of amplitude `noise`.
    fn ellipsoid_cloud(n: usize, axes: DVec3, noise: f64) -> Vec<DVec3> {
        let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
        (0..n)
            .map(|i| {
                let y = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
                let rho = (1.0 - y * y).sqrt();
                let a = golden * i as f64;
                let d = DVec3::new(rho * a.cos(), y, rho * a.sin());
                let jitter = noise * (((i * 7919) % 1000) as f64 / 500.0 - 1.0);
                d * axes * (1.0 + jitter)
            })
            .collect()
    }

    /// Distance of `p` to the ellipsoid, to first order (exact on a sphere).
    fn off_ellipsoid(p: DVec3, axes: DVec3) -> f64 {
        let q = p / axes;
        let g = (q / axes).length() * 2.0;
        (q.length_squared() - 1.0).abs() / g.max(f64::MIN_POSITIVE)
    }

    /// RMS distance of `points` to the sphere of radius `r` about the origin.
    fn rms_off_sphere(points: &[DVec3], r: f64) -> f64 {
        let sum: f64 = points.iter().map(|p| (p.length() - r).powi(2)).sum();
        (sum / points.len() as f64).sqrt()
    }

    #[test]
    fn an_ellipsoid_cloud_becomes_a_closed_mesh_on_the_ellipsoid() {
        let axes = DVec3::new(0.05, 0.03, 0.02);
        let cloud = ellipsoid_cloud(20_000, axes, 0.0);
        let made = reconstruct_cloud(&cloud, &MergeOptions::default()).expect("a surface");
        let stats = mesh_stats(&made.mesh, 0);
        assert_eq!(stats.boundary_loops, 0, "{stats:?}");
        assert_eq!(made.stats.pieces, 1);
        let worst = made
            .mesh
            .positions
            .iter()
            .map(|p| off_ellipsoid(*p, axes))
            .fold(0.0, f64::max);
        // A tenth of the cloud's spacing (about 0.4 mm here).
        assert!(
            worst < 0.1 * made.stats.median_spacing,
            "{worst} against spacing {}",
            made.stats.median_spacing
        );
        // Outward: positive signed volume, near the ellipsoid's.
        let volume = made.mesh.signed_volume();
        let expected = 4.0 / 3.0 * std::f64::consts::PI * axes.x * axes.y * axes.z;
        assert!(
            (volume / expected - 1.0).abs() < 0.02,
            "{volume} vs {expected}"
        );
    }

    #[test]
    fn noise_is_averaged_not_interpolated() {
        let axes = DVec3::splat(0.05);
        let noise = 0.004;
        let cloud = ellipsoid_cloud(20_000, axes, noise);
        let made = reconstruct_cloud(&cloud, &MergeOptions::default()).expect("a surface");
        let (points, merged) = (
            rms_off_sphere(&cloud, 0.05),
            rms_off_sphere(&made.mesh.positions, 0.05),
        );
        assert!(
            merged < 0.5 * points,
            "merged {merged} against points {points}"
        );
    }

    /// Noise as large as the spacing: the width grows with it, so the surface is one
    /// piece around the sphere and the merge lies far nearer the sphere than the points.
    #[test]
    fn noise_as_large_as_the_spacing_widens_the_average() {
        let r = 0.05;
        let clean = reconstruct_cloud(
            &ellipsoid_cloud(20_000, DVec3::splat(r), 0.0),
            &MergeOptions::default(),
        )
        .expect("a surface");
        let spacing = clean.stats.median_spacing;
        // Uniform noise of half-width 1.7 spacings: sigma about one spacing.
        let noisy = ellipsoid_cloud(20_000, DVec3::splat(r), 1.7 * spacing / r);
        let made = reconstruct_cloud(&noisy, &MergeOptions::default()).expect("a surface");
        assert!(
            made.stats.cell > 1.3 * clean.stats.cell,
            "{:?} vs {:?}",
            made.stats,
            clean.stats
        );
        assert!(made.stats.normal_neighbours > clean.stats.normal_neighbours);
        let stats = mesh_stats(&made.mesh, 0);
        assert_eq!(stats.components, 1, "{stats:?}");
        assert_eq!(stats.boundary_loops, 0, "{stats:?}");
        assert_eq!(stats.genus, Some(0), "{stats:?}");
        let (points, merged) = (
            rms_off_sphere(&noisy, r),
            rms_off_sphere(&made.mesh.positions, r),
        );
        assert!(
            merged < 0.25 * points,
            "merged {merged} against points {points}"
        );
    }

    #[test]
    fn scattered_or_too_few_points_are_refused() {
        let line: Vec<DVec3> = (0..50).map(|i| DVec3::new(i as f64, 0.0, 0.0)).collect();
        assert!(matches!(
            reconstruct_cloud(&line, &MergeOptions::default()),
            Err(CloudError::TooSparse { .. })
        ));
        assert!(reconstruct_cloud(&[], &MergeOptions::default()).is_err());
    }
}
