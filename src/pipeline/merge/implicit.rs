//! The merged scans' implicit function: a bucket grid over every scan's samples and the
//! weighted signed distance along the samples' normals (see the module docs of `merge`).

use super::types::ScanSamples;
use crate::mesh::bucket_grid::BucketGrid;
use glam::{DVec2, DVec3};
use nalgebra::{Matrix6, Vector6};

/// Samples of the sheet nearest a query count only if their normal is within this cosine
/// of the nearest sample's (about 70 degrees): the far side of a thin part faces away.
const SAME_SHEET_COS: f64 = 0.35;

/// A bucket grid over the samples of several scans (`BucketGrid`). Each bucket's samples
/// are copied side by side in scan and sample order: a query reads every sample of 27
/// buckets, and through (scan, sample) indices each was a jump into another scan's arrays
/// (`Implicit::at` is the merge's largest cost; side by side, the bunny session's merges
/// took 10-16 % less CPU). The positions, which every query's distance test reads, lie in
/// an array of their own; the normals and weights, read only for the samples within the
/// radius, in another.
pub(super) struct PointIndex {
    grid: Option<BucketGrid>,
    points: Vec<DVec3>,
    samples: Vec<IndexedSample>,
}

/// What a sample brings besides its position.
#[derive(Clone, Copy)]
pub(super) struct IndexedSample {
    pub normal: DVec3,
    pub weight: f64,
}

impl PointIndex {
    /// Buckets of size `cell` (the largest query radius, so a query reads 27 buckets).
    pub(super) fn build(scans: &[&ScanSamples], cell: f64) -> Self {
        let points: Vec<DVec3> = scans
            .iter()
            .flat_map(|s| s.points.iter().copied())
            .collect();
        let grid = BucketGrid::new(&points, cell);
        // Where each scan's samples start in `points`.
        let offsets: Vec<usize> = scans
            .iter()
            .scan(0, |at, s| {
                let from = *at;
                *at += s.points.len();
                Some(from)
            })
            .collect();
        let order: Vec<usize> = grid
            .iter()
            .flat_map(|g| g.members())
            .map(|&i| i as usize)
            .collect();
        let samples = order
            .iter()
            .map(|&i| {
                let s = offsets.partition_point(|&o| o <= i) - 1;
                let (scan, k) = (scans[s], i - offsets[s]);
                IndexedSample {
                    normal: scan.normals[k],
                    weight: scan.weights[k],
                }
            })
            .collect();
        let points = order.iter().map(|&i| points[i]).collect();
        Self {
            grid,
            points,
            samples,
        }
    }

    /// Calls `visit` with the offset from `x`, its squared length and the sample of every
    /// sample within `radius` of `x` in the 27 buckets around it, bucket by bucket in
    /// (z, y, x) order.
    fn within<'s>(
        &'s self,
        x: DVec3,
        radius: f64,
        mut visit: impl FnMut(DVec3, f64, &'s IndexedSample),
    ) {
        let Some(grid) = &self.grid else {
            return;
        };
        let r2 = radius * radius;
        grid.around(x, |run| {
            let start = run.start;
            for (k, p) in self.points[run].iter().enumerate() {
                let d = *p - x;
                let d2 = d.length_squared();
                if d2 <= r2 {
                    visit(d, d2, &self.samples[start + k]);
                }
            }
        });
    }
}

/// The implicit function at a point.
#[derive(Clone, Copy, Debug)]
pub(super) struct Sample {
    /// Signed distance to the merged surface (positive where the normals point).
    pub value: f64,
    /// Unit normal (the weighted mean of the samples' normals).
    pub normal: DVec3,
    /// Distance to the nearest sample.
    pub nearest: f64,
}

/// The weighted signed distance of the samples within `radius`.
pub(super) struct Implicit<'a> {
    pub index: &'a PointIndex,
    pub radius: f64,
    pub sigma: f64,
}

/// Fewest samples a local quadric is fitted to (it has six coefficients).
const MIN_QUADRIC_SAMPLES: usize = 6;
/// Least spread of the samples across their narrowest tangent direction (variance in
/// Gaussian widths squared; a full disk has 0.5, a half disk at a straight rim 0.18): a
/// row of samples holds no quadric across it. A spread, not a count, so that two views of
/// the same ground (twice the samples, the same spread) decide alike.
const MIN_TANGENTIAL_SPREAD: f64 = 0.02;
/// Ridge on the quadric's coefficients (relative to the total weight): keeps the fit
/// defined where the samples lie along a line (a scan's rim), leaving the offset free.
const QUADRIC_RIDGE: f64 = 1e-6;

impl Implicit<'_> {
    /// The point of the merged surface under `x` along `normal`: a weighted least-squares
    /// quadric height field over the tangent plane at `x` (same weights and sheet rule as
    /// `at`), evaluated at `x`. A plane fit (what `at` is) stands off a curved surface by
    /// about sigma^2 times the curvature / 2 (35 um at a 2 mm sigma on a 5 cm sphere); a
    /// quadric follows it. `None` with too few samples.
    pub(super) fn refine(&self, x: DVec3, normal: DVec3) -> Option<DVec3> {
        let e1 = normal.any_orthonormal_vector();
        let e2 = normal.cross(e1);
        let inv = 1.0 / (self.sigma * self.sigma);
        let scale = 1.0 / self.sigma;
        let mut normal_matrix = Matrix6::<f64>::zeros();
        let mut rhs = Vector6::<f64>::zeros();
        let mut count = 0;
        let mut total = 0.0;
        self.same_sheet_around(x, normal, |d, weight| {
            let w = weight * (-d.length_squared() * inv).exp();
            let (u, v) = (d.dot(e1) * scale, d.dot(e2) * scale);
            let basis = Vector6::new(1.0, u, v, u * u, u * v, v * v);
            normal_matrix += w * basis * basis.transpose();
            rhs += w * d.dot(normal) * basis;
            count += 1;
            total += w;
        });
        if count < MIN_QUADRIC_SAMPLES
            || total <= 0.0
            || narrowest_spread(&normal_matrix) < MIN_TANGENTIAL_SPREAD
        {
            return None;
        }
        for k in 1..6 {
            normal_matrix[(k, k)] += QUADRIC_RIDGE * total;
        }
        let c = normal_matrix.cholesky()?.solve(&rhs);
        c[0].is_finite().then(|| x + c[0] * normal)
    }

    /// The point of the data's rim nearest to `x` in the tangent plane of `normal`, as an
    /// offset from `x` in that plane: the nearest point of the convex hull of the
    /// projections of the same-sheet samples within the radius (zero inside the data, and
    /// on its rim). Unlike their weighted centroid, the hull does not move with the
    /// weights (a scan's rim ramp) or with the samples' spacing (sparse at grazing
    /// angles). `None` with fewer than three samples off one line.
    pub(super) fn overhang(&self, x: DVec3, normal: DVec3) -> Option<DVec3> {
        let e1 = normal.any_orthonormal_vector();
        let e2 = normal.cross(e1);
        let mut projected: Vec<DVec2> = Vec::with_capacity(64);
        self.same_sheet_around(x, normal, |d, _| {
            projected.push(DVec2::new(d.dot(e1), d.dot(e2)));
        });
        let nearest = super::support::nearest_on_hull(&mut projected)?;
        Some(nearest.x * e1 + nearest.y * e2)
    }

    /// Calls `visit` with the offset from `x` and the weight of every sample within the
    /// radius whose normal is within `SAME_SHEET_COS` of `normal` (the sheet `x` is on).
    fn same_sheet_around(&self, x: DVec3, normal: DVec3, mut visit: impl FnMut(DVec3, f64)) {
        self.index.within(x, self.radius, |d, _, sample| {
            if sample.normal.dot(normal) >= SAME_SHEET_COS {
                visit(d, sample.weight);
            }
        });
    }

    /// The function at `x`; `None` where no sample lies within the radius (or their weights
    /// vanish).
    pub(super) fn at(&self, x: DVec3) -> Option<Sample> {
        let mut near: Vec<(f64, DVec3, &IndexedSample)> = Vec::with_capacity(64);
        let mut best = (f64::MAX, 0usize);
        self.index.within(x, self.radius, |d, d2, sample| {
            if d2 < best.0 {
                best = (d2, near.len());
            }
            near.push((d2, d, sample));
        });
        let sheet = near.get(best.1)?.2.normal;
        let inv = 1.0 / (self.sigma * self.sigma);
        let (mut sum_w, mut sum_f, mut sum_n) = (0.0, 0.0, DVec3::ZERO);
        for &(d2, d, sample) in &near {
            let n = sample.normal;
            if n.dot(sheet) < SAME_SHEET_COS {
                continue;
            }
            let w = sample.weight * (-d2 * inv).exp();
            sum_w += w;
            sum_f -= w * n.dot(d);
            sum_n += w * n;
        }
        let normal = sum_n.try_normalize()?;
        (sum_w > 0.0).then(|| Sample {
            value: sum_f / sum_w,
            normal,
            nearest: best.0.sqrt(),
        })
    }
}

/// The smallest eigenvalue of the weighted covariance of the samples' tangent coordinates,
/// read off the quadric's normal matrix (row 0 holds the weight and first moments, the
/// (u, v) block the second moments).
fn narrowest_spread(m: &Matrix6<f64>) -> f64 {
    let w = m[(0, 0)];
    let (mu, mv) = (m[(0, 1)] / w, m[(0, 2)] / w);
    let a = m[(1, 1)] / w - mu * mu;
    let b = m[(1, 2)] / w - mu * mv;
    let c = m[(2, 2)] / w - mv * mv;
    0.5 * (a + c) - (0.25 * (a - c) * (a - c) + b * b).sqrt()
}
