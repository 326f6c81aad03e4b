//! Whether a previous version may warm-start this one. A warm start reuses the previous
//! plane, warp, grid spacing, controls and foot points: right for a rescan of the same
//! surface, ruinous for a version that covers other ground (the previous grid spacing over
//! a map that no longer fits it gave one fragmented rescan 37,869 controls for 5,808
//! points). Such a version starts cold, and the result says why.

use super::cold_start::{
    ColdStart, MAX_DROPPED_SHARE, MAX_NORMAL_ANGLE_DEG, MAX_OUTSIDE_SHARE, MAX_SHIFT_SHARE,
    MAX_SIZE_RATIO, NEW_GROUND_REACH_EDGES,
};
use super::types::{Dropped, ScanWarm};
use crate::remesh::planar::PlaneFrame;
use crate::TriMesh;
use glam::DVec3;
use rustc_hash::FxHashMap;

/// A warm grid may have at most this many times the controls the budget asks for: the old
/// spacing is kept for stability over small changes of the data, not at any cost.
pub(super) const WARM_BUDGET_SLACK: f64 = 1.25;

/// New points sampled for the coverage test at most.
const COVERAGE_SAMPLES: usize = 20_000;

/// `None` when `warm` may warm-start the fit of `part` (the piece kept of an input that
/// left `dropped` out; `edge_length`: its sample spacing), else why not.
pub(super) fn refuse_warm(
    part: &TriMesh,
    dropped: &Dropped,
    edge_length: f64,
    warm: &ScanWarm,
) -> Option<ColdStart> {
    if let Some(frame) = warm.frame {
        let angle = normal_angle_deg(part, &frame);
        if angle > MAX_NORMAL_ANGLE_DEG {
            return Some(ColdStart::Frame {
                normal_angle_deg: angle,
            });
        }
    }
    let feet = warm.feet.filter(|f| !f.points.is_empty())?;
    let previous = feet.points.len();
    let vertices = part.positions.len();
    let ratio = vertices.max(1) as f64 / previous as f64;
    if ratio < 1.0 / MAX_SIZE_RATIO || dropped.share > MAX_DROPPED_SHARE {
        return Some(ColdStart::Pieces {
            vertices,
            previous,
            dropped_share: dropped.share,
        });
    }
    let old: Vec<DVec3> = feet
        .points
        .iter()
        .map(|p| glam::Vec3::from_array(*p).as_dvec3())
        .collect();
    let (old_lo, old_hi) = bounds(&old);
    let (new_lo, new_hi) = bounds(&part.positions);
    let diagonal = (old_hi - old_lo).length();
    // How far the new box sticks out of the previous one: a moved version sticks out by its
    // move, a cut one (part of the same data) not at all.
    let shift = (new_hi - old_hi)
        .max(old_lo - new_lo)
        .max_element()
        .max(0.0);
    if diagonal > 0.0 && shift > MAX_SHIFT_SHARE * diagonal {
        return Some(ColdStart::Shift {
            diagonal_share: shift / diagonal,
        });
    }
    let outside_share = outside_share(&old, &part.positions, edge_length);
    (outside_share > MAX_OUTSIDE_SHARE).then_some(ColdStart::Coverage { outside_share })
}

/// Angle between the area-weighted mean normal of `mesh` and the normal of `frame`, sign
/// ignored (a cleaned version may be oriented the other way round).
fn normal_angle_deg(mesh: &TriMesh, frame: &PlaneFrame) -> f64 {
    let normal: DVec3 = mesh
        .triangles
        .iter()
        .map(|t| {
            let p = t.map(|v| mesh.positions[v as usize]);
            (p[1] - p[0]).cross(p[2] - p[0])
        })
        .sum();
    let (a, b) = (
        normal.normalize_or_zero(),
        frame.normal().normalize_or_zero(),
    );
    if a == DVec3::ZERO || b == DVec3::ZERO {
        return 0.0;
    }
    a.dot(b).abs().min(1.0).acos().to_degrees()
}

fn bounds(points: &[DVec3]) -> (DVec3, DVec3) {
    crate::numeric::bounds(points).unwrap_or((DVec3::splat(f64::MAX), DVec3::splat(f64::MIN)))
}

/// Share of `new` points (a spread sample) with no `old` point within
/// `NEW_GROUND_REACH_EDGES` sample spacings, found through a hash grid of that cell size.
fn outside_share(old: &[DVec3], new: &[DVec3], edge_length: f64) -> f64 {
    let reach = NEW_GROUND_REACH_EDGES * edge_length;
    if !(reach > 0.0 && reach.is_finite()) || old.is_empty() || new.is_empty() {
        return 0.0;
    }
    let cell = |p: DVec3| -> (i64, i64, i64) {
        let q = (p / reach).floor();
        (q.x as i64, q.y as i64, q.z as i64)
    };
    let mut buckets: FxHashMap<(i64, i64, i64), Vec<u32>> = FxHashMap::default();
    for (k, p) in old.iter().enumerate() {
        buckets.entry(cell(*p)).or_default().push(k as u32);
    }
    let stride = new.len().div_ceil(COVERAGE_SAMPLES).max(1);
    let reach2 = reach * reach;
    let mut sampled = 0usize;
    let mut outside = 0usize;
    for p in new.iter().step_by(stride) {
        sampled += 1;
        let (x, y, z) = cell(*p);
        let near = (-1..=1).any(|dx| {
            (-1..=1).any(|dy| {
                (-1..=1).any(|dz| {
                    buckets.get(&(x + dx, y + dy, z + dz)).is_some_and(|ks| {
                        ks.iter()
                            .any(|&k| (old[k as usize] - *p).length_squared() <= reach2)
                    })
                })
            })
        });
        if !near {
            outside += 1;
        }
    }
    outside as f64 / sampled.max(1) as f64
}
