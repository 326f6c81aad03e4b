//! The worker: a mesh with Loop subdivision connectivity in, a fitted surface out.
//! Pure: no file IO; the CLI writes what it returns.

pub mod components;
pub mod domain;
pub mod edge_band;
pub mod geometric;
pub mod grid_inverse;
pub mod holes;
pub mod lattice;
pub mod object;
pub mod output;
pub mod scan;
mod scan_solve;
pub mod scan_warm;
pub mod worker;

use crate::fit::{
    fit, Budget, Collocation, Csr, FitError, FitOutcome, FitProblem, Method, StepHook,
};
use crate::mesh::detect::Hierarchy;
use crate::mesh::inverse::{coarsen, composed_exact_inverse, InverseError, InverseMethod};
use crate::mesh::topology::Topology;
use crate::surface::bezier::{lattice_points, BezierTriangle};
use crate::surface::loop_limit::LoopLimitSurface;
use crate::surface::{SurfaceParam, TriSurface};
use crate::TriMesh;
use glam::DVec3;
use rayon::prelude::*;
use std::time::Instant;

#[derive(
    Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize, clap::ValueEnum,
)]
#[serde(rename_all = "lowercase")]
pub enum SurfaceKind {
    Bezier,
    Loop,
}

#[derive(Clone)]
pub struct FitOptions<'a> {
    pub surface: SurfaceKind,
    pub levels: usize,
    pub method: Method,
    pub inverse: InverseMethod,
    pub budget: Budget,
    /// Called after every fitting step (and every correction round of a scan): progress
    /// display; `None` costs nothing.
    pub on_step: Option<StepHook<'a>>,
}

#[derive(Debug, thiserror::Error)]
pub enum PipelineError {
    #[error("{0}")]
    NoSubdivision(String),
    #[error(transparent)]
    NotALattice(#[from] lattice::NotALattice),
    #[error("{0}")]
    Unsupported(String),
    #[error(transparent)]
    Fit(#[from] FitError),
}

#[derive(Clone, Debug)]
pub struct PatchFit {
    pub surface: SurfaceKind,
    /// Bezier degree (0 for a Loop grid).
    pub degree: usize,
    pub model: scan::SurfaceModel,
    /// Control points in the model's order (lattice order for Bezier).
    pub controls: Vec<DVec3>,
    pub data: Vec<DVec3>,
    pub params: Vec<SurfaceParam>,
    pub outcome: FitOutcome,
    pub geometric_errors: Vec<f64>,
    pub warm_start: bool,
    pub prepare_ms: f64,
    pub fit_ms: f64,
}

impl PatchFit {
    pub fn geometric_max(&self) -> f64 {
        self.geometric_errors.iter().cloned().fold(0.0, f64::max)
    }
    pub fn geometric_rms(&self) -> f64 {
        let n = self.geometric_errors.len().max(1) as f64;
        (self.geometric_errors.iter().map(|e| e * e).sum::<f64>() / n).sqrt()
    }
}

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
    // L levels of Loop subdivision multiply the face count by 4^L: most scans fail this
    // count before a topology of all their faces is built.
    let faces = mesh.triangles.len();
    let per_coarse_face = u32::try_from(opts.levels)
        .ok()
        .and_then(|l| 4usize.checked_pow(l));
    if per_coarse_face.is_none_or(|k| !faces.is_multiple_of(k)) {
        return Err(PipelineError::NoSubdivision(format!(
            "{faces} faces are not a multiple of 4^{} (what {} levels of Loop subdivision make)",
            opts.levels, opts.levels
        )));
    }
    if opts.levels > 0 {
        if let Some(face) = face_without_two_edge_vertices(mesh) {
            return Err(PipelineError::NoSubdivision(format!(
                "face {face} has fewer than two corners with 3 or 6 faces, as every face of a Loop-subdivided mesh has (the vertices subdivision adds on edges)"
            )));
        }
    }
    let topo = Topology::from_mesh(mesh)
        .map_err(|e| PipelineError::NoSubdivision(format!("not a manifold mesh: {e}")))?;
    let (hierarchy, why) = Hierarchy::detect(&topo, opts.levels);
    if hierarchy.depth() < opts.levels {
        return Err(PipelineError::NoSubdivision(format!(
            "no Loop subdivision connectivity at depth {} (found {}): {}",
            opts.levels,
            hierarchy.depth(),
            why.map_or_else(String::new, |e| e.to_string())
        )));
    }
    let coarse = coarsen(mesh, opts.levels, opts.inverse).map_err(|e| match e {
        InverseError::NotSubdivided { .. } | InverseError::Topology(_) => {
            PipelineError::NoSubdivision(e.to_string())
        }
    })?;
    let r = composed_exact_inverse(&topo, &hierarchy)
        .map_err(|e| PipelineError::NoSubdivision(e.to_string()))?;
    let fine_params = hierarchy.fine_vertex_params(&topo);
    // The PIA update R^L(eps) comes out in coarse vertex order; `to_control[v]` is coarse
    // vertex v's control index.
    let (model, params, initial, to_control, degree) = match opts.surface {
        SurfaceKind::Loop => {
            let surface =
                LoopLimitSurface::new(coarse.mesh.positions.len(), &coarse.mesh.triangles)
                    .map_err(|e| {
                        PipelineError::Unsupported(format!(
                            "the coarse net after {} levels has no Loop limit surface: {e}",
                            opts.levels
                        ))
                    })?;
            let params: Vec<SurfaceParam> = fine_params
                .into_iter()
                .map(|(face, u, v)| SurfaceParam { face, u, v })
                .collect();
            let identity: Vec<usize> = (0..coarse.mesh.positions.len()).collect();
            (
                scan::SurfaceModel::Mesh(std::sync::Arc::new(surface)),
                params,
                coarse.mesh.positions.clone(),
                identity,
                0,
            )
        }
        SurfaceKind::Bezier => {
            let (n, index) =
                lattice::lattice_coordinates(coarse.mesh.positions.len(), &coarse.mesh.triangles)?;
            let coords = lattice_points(n);
            let mut initial = vec![DVec3::ZERO; coords.len()];
            for (v, &idx) in index.iter().enumerate() {
                initial[idx] = coarse.mesh.positions[v];
            }
            // Each fine vertex: (coarse face, barycentric) -> global lattice (u, v).
            let coarse_faces = &coarse.mesh.triangles;
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
            (
                scan::SurfaceModel::Bezier(BezierTriangle::new(n)),
                params,
                initial,
                index,
                n,
            )
        }
    };
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

/// The collocation operator of `params` on `surface`: matrix-free for a Bezier patch
/// sampled on lattice rows, otherwise the sparse matrix (rows built in parallel).
pub fn collocation(surface: &dyn TriSurface, params: &[SurfaceParam]) -> Collocation {
    let matrix = || collocation_rows(surface, params);
    match surface.as_bezier() {
        Some(b) => Collocation::bezier(b.degree, params, matrix),
        None => Collocation::new(matrix()),
    }
}

/// The collocation rows at `params` as a stored matrix (no transpose), built in parallel
/// chunks with one row buffer per chunk.
pub fn collocation_rows(surface: &dyn TriSurface, params: &[SurfaceParam]) -> Csr {
    const CHUNK: usize = 4096;
    let parts: Vec<(Vec<usize>, Vec<u32>, Vec<f64>)> = params
        .par_chunks(CHUNK)
        .map(|chunk| {
            let mut row = Vec::new();
            let (mut lens, mut cols, mut vals) =
                (Vec::with_capacity(chunk.len()), Vec::new(), Vec::new());
            for p in chunk {
                surface.basis_row(*p, &mut row);
                let before = cols.len();
                for &(c, w) in &row {
                    if w != 0.0 {
                        cols.push(c);
                        vals.push(w);
                    }
                }
                lens.push(cols.len() - before);
            }
            (lens, cols, vals)
        })
        .collect();
    let nnz = parts.iter().map(|p| p.1.len()).sum();
    let mut m = Csr {
        nrows: params.len(),
        ncols: surface.control_count(),
        row_ptr: Vec::with_capacity(params.len() + 1),
        col_idx: Vec::with_capacity(nnz),
        values: Vec::with_capacity(nnz),
    };
    m.row_ptr.push(0);
    for (lens, cols, vals) in parts {
        for len in lens {
            let last = *m.row_ptr.last().unwrap_or(&0);
            m.row_ptr.push(last + len);
        }
        m.col_idx.extend(cols);
        m.values.extend(vals);
    }
    m
}

/// Distance of every data point to its foot point, Newton started at its parameter.
pub fn geometric_errors(
    surface: &dyn TriSurface,
    controls: &[DVec3],
    data: &[DVec3],
    params: &[SurfaceParam],
) -> Vec<f64> {
    let evaluate = surface.evaluator(controls);
    data.par_iter()
        .zip(params.par_iter())
        .map(|(p, u)| {
            (geometric::foot_point(surface, &*evaluate, *p, *u)
                .1
                .position
                - *p)
                .length()
        })
        .collect()
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
