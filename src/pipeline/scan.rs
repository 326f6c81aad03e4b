//! Scans without subdivision connectivity: clean, keep the largest component, parameterize
//! onto the domain triangle, resample on a lattice of `lattice * 2^levels` segments,
//! inverse-subdivide it for the initial net, then fit the ORIGINAL scan points.

use super::SurfaceKind;
use super::{collocation, geometric_errors, FitOptions, PatchFit, PipelineError};
use crate::fit::engine::umbrella_laplacian;
use crate::fit::{fit, Collocation, FitProblem};
use crate::mesh::clean::{clean, CleanOptions};
use crate::mesh::inverse::coarsen;
use crate::mesh::stats::UnionFind;
use crate::remesh::param::{prepare, DomainShape, PreparedPatch};
use crate::surface::bezier::{lattice_index, lattice_points, lattice_triangles, BezierTriangle};
use crate::surface::box_spline::LatticeSpline;
use crate::surface::{SurfaceParam, TriSurface};
use crate::TriMesh;
use glam::DVec3;
use std::collections::HashMap;
use std::time::Instant;

#[derive(Clone, Debug)]
pub struct ScanOptions {
    /// Control-net segments per side (the Bezier degree).
    pub lattice: usize,
    /// Fairness weight relative to the data: s = smoothing * data points / control points.
    pub smoothing: f64,
}

#[derive(Clone, Debug)]
pub struct ScanFit {
    pub fit: PatchFit,
    pub prepared: PreparedPatch,
    pub components: usize,
    pub kept_vertices: usize,
}

/// The largest edge-connected component of a cleaned mesh, compacted.
pub fn largest_component(mesh: &TriMesh) -> (TriMesh, usize) {
    let mut uf = UnionFind::new(mesh.triangles.len());
    let mut edge_face: HashMap<(u32, u32), usize> = HashMap::new();
    for (f, t) in mesh.triangles.iter().enumerate() {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            if let Some(&g) = edge_face.get(&(a.min(b), a.max(b))) {
                uf.union(f, g);
            } else {
                edge_face.insert((a.min(b), a.max(b)), f);
            }
        }
    }
    let mut size: HashMap<usize, usize> = HashMap::new();
    for f in 0..mesh.triangles.len() {
        *size.entry(uf.find(f)).or_insert(0) += 1;
    }
    let components = size.len();
    let Some((&root, _)) = size.iter().max_by_key(|(r, s)| (**s, usize::MAX - **r)) else {
        return (TriMesh::default(), 0);
    };
    let mut map = vec![u32::MAX; mesh.positions.len()];
    let mut out = TriMesh::default();
    for (f, t) in mesh.triangles.iter().enumerate() {
        if uf.find(f) != root {
            continue;
        }
        let mut nt = [0u32; 3];
        for (k, &v) in t.iter().enumerate() {
            if map[v as usize] == u32::MAX {
                map[v as usize] = out.positions.len() as u32;
                out.positions.push(mesh.positions[v as usize]);
            }
            nt[k] = map[v as usize];
        }
        out.triangles.push(nt);
    }
    (out, components)
}

pub fn fit_scan(
    mesh: &TriMesh,
    opts: &FitOptions,
    scan: &ScanOptions,
    previous: Option<&[DVec3]>,
) -> Result<ScanFit, PipelineError> {
    let t0 = Instant::now();
    let cleaned = clean(mesh, &CleanOptions::default());
    let (part, components) = largest_component(&cleaned.mesh);
    if part.triangles.is_empty() {
        return Err(PipelineError::Unsupported(
            "no faces left after cleaning".into(),
        ));
    }
    let n0 = scan.lattice.max(1);
    let segments = n0 << opts.levels;
    let shape = match opts.surface {
        SurfaceKind::Bezier => DomainShape::Triangle,
        SurfaceKind::Loop => DomainShape::Disk,
    };
    let prepared =
        prepare(&part, segments, shape).map_err(|e| PipelineError::Unsupported(e.to_string()))?;
    let lattice_mesh = TriMesh::new(prepared.lattice.clone(), lattice_triangles(segments));
    // The lattice has subdivision connectivity by construction; its even vertices come in
    // lattice order, so the coarse net is already in Bezier lattice order.
    let coarse = coarsen(&lattice_mesh, opts.levels, opts.inverse)
        .map_err(|e| PipelineError::NoSubdivision(e.to_string()))?
        .mesh
        .positions;
    let (surface, initial, net_triangles) = surface_and_net(opts.surface, n0, coarse);
    let surface = surface.as_ref();
    let params: Vec<SurfaceParam> = prepared
        .uv
        .iter()
        .map(|&(u, v)| SurfaceParam { face: 0, u, v })
        .collect();
    let basis = collocation(surface, &params);
    let fairness = Collocation::new(umbrella_laplacian(surface.control_count(), &net_triangles));
    let prepare_ms = t0.elapsed().as_secs_f64() * 1e3;
    let smoothing = scan.smoothing * part.positions.len() as f64 / surface.control_count() as f64;
    let problem = FitProblem {
        basis: &basis,
        data: &part.positions,
        smoothing,
        fairness: Some(&fairness),
        pia_operator: None,
    };
    let warm = previous.filter(|p| p.len() == initial.len());
    let start = warm.map_or(initial, |p| p.to_vec());
    let t1 = Instant::now();
    let outcome = fit(&problem, start, opts.method, &opts.budget)?;
    let fit_ms = t1.elapsed().as_secs_f64() * 1e3;
    let geometric_errors = geometric_errors(surface, &outcome.controls, &part.positions, &params);
    Ok(ScanFit {
        fit: PatchFit {
            surface: opts.surface,
            degree: n0,
            controls: outcome.controls.clone(),
            data: part.positions.clone(),
            params,
            outcome,
            geometric_errors,
            warm_start: warm.is_some(),
            prepare_ms,
            fit_ms,
        },
        kept_vertices: part.positions.len(),
        prepared,
        components,
    })
}

/// The surface over the domain lattice of `n0` segments and its initial control net from
/// the inverse-subdivided resampled lattice (`coarse`, lattice order). The Loop surface
/// (box spline over the lattice) has one more ring of control points outside the domain;
/// they start at their nearest domain lattice point and the fairness term shapes them.
/// The surface of a kind over a domain lattice of `n0` segments.
pub fn surface_for(kind: SurfaceKind, n0: usize) -> Box<dyn TriSurface> {
    match kind {
        SurfaceKind::Bezier => Box::new(BezierTriangle::new(n0)),
        SurfaceKind::Loop => Box::new(LatticeSpline::new(n0)),
    }
}

pub fn surface_and_net(
    kind: SurfaceKind,
    n0: usize,
    coarse: Vec<DVec3>,
) -> (Box<dyn TriSurface>, Vec<DVec3>, Vec<[u32; 3]>) {
    match kind {
        SurfaceKind::Bezier => (
            Box::new(BezierTriangle::new(n0)),
            coarse,
            lattice_triangles(n0),
        ),
        SurfaceKind::Loop => {
            let s = LatticeSpline::new(n0);
            let m = s.control_segments();
            let n = n0 as i64;
            let net = lattice_points(m)
                .into_iter()
                .map(|(a, b)| {
                    let (mut i, mut j) = (a as i64 - 1, b as i64 - 1);
                    i = i.clamp(0, n);
                    j = j.clamp(0, n);
                    if i + j > n {
                        let over = i + j - n;
                        let take_i = over.min(i);
                        i -= take_i;
                        j -= over - take_i;
                    }
                    coarse
                        .get(lattice_index(n0, i as usize, j as usize))
                        .copied()
                        .unwrap_or_default()
                })
                .collect();
            (Box::new(s), net, lattice_triangles(m))
        }
    }
}
