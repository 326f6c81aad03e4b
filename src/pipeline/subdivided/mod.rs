//! Inputs with Loop subdivision connectivity: inverse subdivision gives the control net
//! and every fine vertex its exact parameter (coarse face, dyadic barycentric), so the fit
//! needs no parameterization and no foot-point correction.

pub mod lattice;

use super::collocation::collocation;
use super::geometric::geometric_errors;
use super::{FitOptions, NoSubdivision, PatchFit, PipelineError, SurfaceKind, SurfaceModel};
use crate::fit::{fit, FitProblem};
use crate::mesh::detect::Hierarchy;
use crate::mesh::inverse::{coarsen, composed_exact_inverse};
use crate::mesh::topology::Topology;
use crate::surface::bezier::{lattice_points, BezierTriangle};
use crate::surface::loop_limit::LoopLimitSurface;
use crate::surface::SurfaceParam;
use crate::TriMesh;
use glam::DVec3;
use std::time::Instant;

/// A face that no manifold mesh with Loop subdivision connectivity (one level or more) can
/// have: each of its faces has at least two vertices that subdivision put on an edge of the
/// coarser mesh, and those lie on 6 faces (inner edge) or 3 (boundary edge). Scans fail
/// this within their first irregular faces, before a topology of the whole mesh is built.
fn face_without_two_edge_vertices(mesh: &TriMesh) -> Option<usize> {
    let mut faces_at = vec![0u32; mesh.positions.len()];
    for t in &mesh.triangles {
        for &v in t {
            if let Some(count) = faces_at.get_mut(v as usize) {
                *count += 1;
            }
        }
    }
    let on_edge = |v: u32| matches!(faces_at.get(v as usize), Some(3 | 6));
    mesh.triangles
        .iter()
        .position(|t| t.iter().filter(|&&v| on_edge(v)).count() < 2)
}

/// Fits a mesh that has Loop subdivision connectivity at depth `levels`: the coarse net
/// from inverse subdivision is the control net, every fine vertex has its exact parameter
/// (coarse face, dyadic barycentric) from the hierarchy. `loop` fits the exact Loop limit
/// surface of that net (any valences, boundaries); `bezier` needs the net to be one
/// triangular lattice. `previous` is a previous fit's control net: used as the starting net
/// when its size matches.
pub fn fit_subdivided(
    mesh: &TriMesh,
    opts: &FitOptions,
    previous: Option<&[DVec3]>,
) -> Result<PatchFit, PipelineError> {
    let t0 = Instant::now();
    let (topo, hierarchy) = hierarchy_of(mesh, opts.levels)?;
    let coarse = coarsen(mesh, opts.levels, opts.inverse).map_err(NoSubdivision::Inverse)?;
    let r = composed_exact_inverse(&topo, &hierarchy).map_err(NoSubdivision::InverseOperator)?;
    let fine_params = hierarchy.fine_vertex_params(&topo);
    let OnNet {
        model,
        params,
        initial,
        to_control,
        degree,
    } = model_on_net(&coarse.mesh, fine_params, opts)?;
    let surface = model.as_surface();
    let basis = collocation(surface, &params);
    let pia = |res: &[DVec3]| {
        let coarse_order = r.apply(res);
        let mut out = vec![DVec3::ZERO; coarse_order.len()];
        for (v, d) in coarse_order.into_iter().enumerate() {
            out[to_control[v]] = d;
        }
        out
    };
    let prepare_ms = t0.elapsed().as_secs_f64() * 1e3;
    let warm = previous.filter(|p| p.len() == initial.len());
    let start = warm.map_or(initial, |p| p.to_vec());
    let problem = FitProblem {
        basis: &basis,
        data: &mesh.positions,
        smoothing: 0.0,
        fairness: None,
        pia_operator: Some(&pia),
        on_step: opts.on_step,
    };
    let t1 = Instant::now();
    let outcome = fit(&problem, start, opts.method, &opts.budget)?;
    let fit_ms = t1.elapsed().as_secs_f64() * 1e3;
    let geometric_errors = geometric_errors(surface, &outcome.controls, &mesh.positions, &params);
    Ok(PatchFit {
        surface: opts.surface,
        degree,
        controls: outcome.controls.clone(),
        model,
        data: mesh.positions.clone(),
        params,
        outcome,
        geometric_errors,
        warm_start: warm.is_some(),
        prepare_ms,
        fit_ms,
    })
}

/// The input's subdivision hierarchy `levels` deep, or why it has none. The cheap tests
/// (face count, one irregular face) run before a topology of the whole mesh is built.
pub(crate) fn hierarchy_of(
    mesh: &TriMesh,
    levels: usize,
) -> Result<(Topology, Hierarchy), PipelineError> {
    // L levels of Loop subdivision multiply the face count by 4^L: most scans fail this
    // count before a topology of all their faces is built.
    let faces = mesh.triangles.len();
    let per_coarse_face = u32::try_from(levels)
        .ok()
        .and_then(|l| 4usize.checked_pow(l));
    if per_coarse_face.is_none_or(|k| !faces.is_multiple_of(k)) {
        return Err(NoSubdivision::FaceCount { faces, levels }.into());
    }
    if levels > 0 {
        if let Some(face) = face_without_two_edge_vertices(mesh) {
            return Err(NoSubdivision::IrregularFace { face }.into());
        }
    }
    let topo = Topology::from_mesh(mesh).map_err(NoSubdivision::NotManifold)?;
    let (hierarchy, why) = Hierarchy::detect(&topo, levels);
    if hierarchy.depth() < levels {
        return Err(NoSubdivision::TooShallow {
            wanted: levels,
            found: hierarchy.depth(),
            cause: why,
        }
        .into());
    }
    Ok((topo, hierarchy))
}

/// The surface on a coarse net and where the fine vertices sit on it.
struct OnNet {
    model: SurfaceModel,
    /// Each fine vertex's parameter.
    params: Vec<SurfaceParam>,
    /// The coarse net in the model's control order.
    initial: Vec<DVec3>,
    /// Coarse vertex v's control index (the PIA update comes out in coarse vertex order).
    to_control: Vec<usize>,
    /// Bezier degree (0 for the Loop limit surface).
    degree: usize,
}

/// `loop`: the exact Loop limit surface of the coarse net; `bezier`: one patch, when the net
/// is one triangular lattice. `fine_params`: (coarse face, u, v) of every fine vertex.
fn model_on_net(
    coarse: &TriMesh,
    fine_params: Vec<(u32, f64, f64)>,
    opts: &FitOptions,
) -> Result<OnNet, PipelineError> {
    let on_net = match opts.surface {
        SurfaceKind::Loop => {
            let surface = LoopLimitSurface::new(coarse.positions.len(), &coarse.triangles)
                .map_err(|source| PipelineError::NoLimitSurface {
                    levels: opts.levels,
                    source,
                })?;
            let params: Vec<SurfaceParam> = fine_params
                .into_iter()
                .map(|(face, u, v)| SurfaceParam { face, u, v })
                .collect();
            let identity: Vec<usize> = (0..coarse.positions.len()).collect();
            OnNet {
                model: SurfaceModel::Mesh(std::sync::Arc::new(surface)),
                params,
                initial: coarse.positions.clone(),
                to_control: identity,
                degree: 0,
            }
        }
        // The worker fits these in `pipeline::scattered` (over the coarse net, or over the
        // planar map without subdivision connectivity) before it comes here.
        kind @ (SurfaceKind::Bpatch | SurfaceKind::Dms) => {
            return Err(
                crate::pipeline::scattered::ScatteredError::NotPlanarKind(kind.name()).into(),
            )
        }
        SurfaceKind::Bezier => {
            let (n, index) =
                lattice::lattice_coordinates(coarse.positions.len(), &coarse.triangles)?;
            let coords = lattice_points(n);
            let mut initial = vec![DVec3::ZERO; coords.len()];
            for (v, &idx) in index.iter().enumerate() {
                initial[idx] = coarse.positions[v];
            }
            // Each fine vertex: (coarse face, barycentric) -> global lattice (u, v).
            let coarse_faces = &coarse.triangles;
            let params: Vec<SurfaceParam> = fine_params
                .into_iter()
                .map(|(f, u, v)| {
                    let t = coarse_faces.get(f as usize).copied().unwrap_or([0, 0, 0]);
                    let w = 1.0 - u - v;
                    let c = |k: usize| coords[index[t[k] as usize]];
                    let gu = (u * c(0).0 as f64 + v * c(1).0 as f64 + w * c(2).0 as f64) / n as f64;
                    let gv = (u * c(0).1 as f64 + v * c(1).1 as f64 + w * c(2).1 as f64) / n as f64;
                    SurfaceParam {
                        face: 0,
                        u: gu,
                        v: gv,
                    }
                })
                .collect();
            OnNet {
                model: SurfaceModel::Bezier(BezierTriangle::new(n)),
                params,
                initial,
                to_control: index,
                degree: n,
            }
        }
    };
    Ok(on_net)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::loop_subdiv::subdivide;

    /// A fan of `n` triangles around a centre, closed (n >= 3) into a disk with an
    /// irregular centre when n != 6.
    fn fan(n: usize) -> TriMesh {
        let mut positions = vec![DVec3::ZERO];
        let mut triangles = Vec::new();
        for k in 0..n {
            let a = k as f64 / n as f64 * std::f64::consts::TAU;
            positions.push(DVec3::new(a.cos(), a.sin(), 0.0));
            triangles.push([0, 1 + k as u32, 1 + ((k + 1) % n) as u32]);
        }
        TriMesh::new(positions, triangles)
    }

    #[test]
    fn subdivided_meshes_pass_the_quick_face_test_and_irregular_ones_fail_it() {
        for n in [3, 5, 7] {
            let coarse = fan(n);
            for levels in 1..=3 {
                let fine = subdivide(&coarse, levels).expect("manifold");
                assert_eq!(
                    face_without_two_edge_vertices(&fine),
                    None,
                    "fan {n}, {levels} levels"
                );
            }
            // The coarse fan itself: its faces have one corner (the centre) not on 3 or 6
            // faces and rim corners on 2 faces.
            assert!(face_without_two_edge_vertices(&coarse).is_some());
        }
    }
}
