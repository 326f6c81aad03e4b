//! How far a fitted surface strays from its data: the one-sided distance from the surface
//! to the data mesh. The data-to-surface errors a fit minimises cannot see a surface that
//! bulges where no data is (over a hole, or a badly joined seam of an extension); this
//! measure does.

use super::model::ObjectFit;
use crate::mesh::distance::MeshDistance;
use crate::surface::loop_limit::LoopLimitSurface;
use crate::surface::{SurfaceParam, TriSurface};
use glam::DVec3;
use rayon::prelude::*;

/// The largest distance from the fitted surface, sampled on a lattice of `segments`
/// segments per control face edge, to the data mesh (infinite when the data mesh is
/// empty or a sample is not finite).
pub fn farthest_from_data(fit: &ObjectFit, segments: usize) -> f64 {
    let faces: Vec<u32> = (0..fit.surface.domain_face_count() as u32).collect();
    farthest_from(
        &fit.surface,
        &fit.controls,
        &MeshDistance::new(&fit.component),
        segments,
        &faces,
    )
}

/// [`farthest_from_data`] for any Loop limit surface and data mesh, over `faces` only
/// (indices past the surface's faces are skipped).
pub fn farthest_from(
    surface: &LoopLimitSurface,
    controls: &[DVec3],
    data: &MeshDistance,
    segments: usize,
    faces: &[u32],
) -> f64 {
    face_strays(surface, controls, data, segments, faces)
        .into_iter()
        .fold(0.0, f64::max)
}

/// Per face of `faces`, the largest distance from its lattice of `segments` segments per
/// edge to the data mesh (0 for indices past the surface's faces, infinite where a sample
/// is not finite or the data mesh is empty).
pub fn face_strays(
    surface: &LoopLimitSurface,
    controls: &[DVec3],
    data: &MeshDistance,
    segments: usize,
    faces: &[u32],
) -> Vec<f64> {
    let k = segments.max(1);
    let evaluate = surface.evaluator(controls);
    let count = surface.domain_face_count() as u32;
    faces
        .par_iter()
        .with_min_len(64)
        .map(|&f| {
            if f >= count {
                return 0.0;
            }
            let mut farthest = 0.0f64;
            for j in 0..=k {
                for i in 0..=k - j {
                    let p = SurfaceParam {
                        face: f,
                        u: i as f64 / k as f64,
                        v: j as f64 / k as f64,
                    };
                    let d = data.distance(evaluate(p).position).unwrap_or(f64::INFINITY);
                    farthest = farthest.max(d);
                }
            }
            farthest
        })
        .collect()
}
