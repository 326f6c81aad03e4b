//! Stage 6 of a scan fit: what of the parameter domain is not part of the surface, in the
//! final parameters: the data's outer rim, the trimmed holes and the wide data triangles.

use super::holes::HolePlan;
use super::prepare::Prepared;
use super::types::{Domain, Trims};
use crate::surface::SurfaceParam;

pub(super) fn trims(
    prepared: &Prepared,
    domain: &Domain,
    params: &[SurfaceParam],
    plan: HolePlan,
) -> Trims {
    let plane = &prepared.map.plane;
    // Data vertices at their final parameters, virtual ones (hole centres) on the plain map.
    let loop_params = |rim: &[u32]| -> Vec<(f64, f64)> {
        rim.iter()
            .map(|&v| {
                params
                    .get(v as usize)
                    .map_or_else(|| domain.param(plane[v as usize]), |q| (q.u, q.v))
            })
            .collect()
    };
    let outer = loop_params(&prepared.patch.outer);
    let holes = prepared
        .patch
        .hole_loops
        .iter()
        .zip(&plan.bridged)
        .filter(|(_, bridged)| !**bridged)
        .map(|(rim, _)| loop_params(rim))
        .chain(
            plan.wide_triangles
                .iter()
                .map(|&k| loop_params(&prepared.map.mesh.triangles[k])),
        )
        .collect();
    Trims { outer, holes, plan }
}
