//! A scan as a view of the object: its samples in the object frame, the direction it
//! looks from and its spacing, and how far apart a session's views look.

use crate::mesh::rigid::RigidTransform;
use crate::pipeline::merge::{scan_samples, MergeOptions, ScanSamples};
use crate::TriMesh;
use glam::DVec3;

/// One scan of the object.
#[derive(Clone, Debug)]
pub struct SessionScan {
    /// Its transform into the object frame.
    pub transform: RigidTransform,
    /// Its samples in the object frame.
    pub samples: ScanSamples,
    /// Vertices of the scan as given.
    pub vertices: usize,
    /// Its viewing direction in the object frame (the weighted mean of its samples'
    /// normals); `None` when they cancel out (a closed scan looks from everywhere).
    pub direction: Option<DVec3>,
    /// Its median edge length (its sampling spacing), which the merge cell follows.
    pub spacing: f64,
}

impl SessionScan {
    /// `mesh` (in its own frame, `transform` into the object's) as a scan of the object;
    /// `None` when it has no samples to merge.
    pub(super) fn of(
        mesh: &TriMesh,
        transform: RigidTransform,
        opts: &MergeOptions,
    ) -> Option<Self> {
        let samples = scan_samples(mesh, &transform, opts);
        let spacing = samples.spacing;
        if samples.points.is_empty() || spacing <= 0.0 || !spacing.is_finite() {
            return None;
        }
        Some(SessionScan {
            transform,
            direction: view_direction(&samples),
            samples,
            vertices: mesh.positions.len(),
            spacing,
        })
    }
}

/// The weighted mean of a scan's sample normals, unit length (`None` if they cancel out).
fn view_direction(samples: &ScanSamples) -> Option<DVec3> {
    let sum: DVec3 = samples
        .normals
        .iter()
        .zip(&samples.weights)
        .map(|(n, w)| *n * *w)
        .sum();
    let total: f64 = samples.weights.iter().sum();
    // Normals that mostly cancel (a closed or wrapped scan) give no direction.
    (sum.length() > 0.2 * total)
        .then(|| sum.normalize())
        .filter(|d| d.is_finite())
}

/// The largest angle (degrees) between two scans' viewing directions; 180 when a scan has
/// none.
pub(super) fn view_spread_deg<'a>(scans: impl Iterator<Item = &'a SessionScan>) -> f64 {
    let directions: Vec<Option<DVec3>> = scans.map(|s| s.direction).collect();
    let mut widest = 0.0f64;
    for (k, a) in directions.iter().enumerate() {
        for b in &directions[k + 1..] {
            let angle = match (a, b) {
                (Some(a), Some(b)) => a.dot(*b).clamp(-1.0, 1.0).acos().to_degrees(),
                _ => 180.0,
            };
            widest = widest.max(angle);
        }
    }
    if directions.iter().any(Option::is_none) {
        widest = 180.0;
    }
    widest
}
