//! The decimations a fitted surface is measured against: what a user who wants "fewer
//! numbers, same shape" would keep instead.

use super::{simplify, Simplified, SimplifyError, SimplifyOptions};
use crate::mesh::TriMesh;

/// Quadric decimations of `mesh` to `target_vertices`: with the default triangle-quality
/// guard, and without it (plain Garland-Heckbert). A comparison takes the better of the
/// two: the guard keeps a control mesh even but forbids the long thin triangles an exact
/// faceting needs (a finely tessellated octagonal prism: 4.9e-2 RMS guarded, exact plain),
/// while on organic models it barely matters (under 5 % either way on the shared models).
pub fn decimation_baselines(
    mesh: &TriMesh,
    target_vertices: usize,
) -> [Result<Simplified, SimplifyError>; 2] {
    [SimplifyOptions::default().min_quality, 0.0].map(|min_quality| {
        simplify(
            mesh,
            &SimplifyOptions {
                target_vertices,
                min_quality,
                ..Default::default()
            },
        )
    })
}
