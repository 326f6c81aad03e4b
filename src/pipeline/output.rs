//! What a fit turns into: the surface.json value, the tessellation (trimmed to the scanned
//! region) and its error colours. Bytes and values only; callers write them.

pub use super::coverage::Coverage;
use super::scan::ScanFit;
use super::welded_lattice::welded_lattices;
use super::{PatchFit, SurfaceKind, SurfaceModel};
use crate::io::glb::{glb_bytes_with_extras, GlbAttributes, ERROR_RAMP};
use crate::remesh::param::ring_cells;
use crate::surface::bezier::{lattice_points, lattice_triangles};
use crate::surface::{Derivatives, SurfaceParam};
use crate::TriMesh;
use glam::DVec3;
use rayon::prelude::*;
use serde_json::json;

/// surface.json of a fit: the model, its controls, and for scans the plane, domain and
/// trims; `report` gives the final errors and status.
pub fn surface_json(
    f: &PatchFit,
    scan: Option<&ScanFit>,
    report: &serde_json::Value,
) -> serde_json::Value {
    let controls = f
        .controls
        .iter()
        .map(|p| [p.x, p.y, p.z])
        .collect::<Vec<_>>();
    let mut v = match &f.model {
        SurfaceModel::Bezier(b) => json!({
            "kind": "bezier",
            "degree": b.degree,
            "domain": "reference triangle: barycentric (u, v, w = 1 - u - v)",
            "lattice_ordering": "control point P_{i,j,k} (i + j + k = degree) has weight degree!/(i! j! k!) u^i v^j w^k and sits at index j*(degree+1) - j*(j-1)/2 + i",
        }),
        SurfaceModel::Grid(g) if f.surface == SurfaceKind::Bezier => {
            let patches = g
                .cells()
                .iter()
                .map(|&cell| {
                    let (i, j, down) = cell;
                    // Corners where w, u and v are 1 (see `grid_spline::cell_at`).
                    let corners = if down {
                        [[i + 1, j + 1], [i, j + 1], [i + 1, j]]
                    } else {
                        [[i, j], [i + 1, j], [i, j + 1]]
                    };
                    let net = g.cell_bezier_net(&f.controls, cell);
                    json!({
                        "cell": [i, j, i64::from(down)],
                        "corners": corners,
                        "control_points": net.iter().map(|p| [p.x, p.y, p.z]).collect::<Vec<_>>(),
                    })
                })
                .collect::<Vec<_>>();
            json!({
                "kind": "bezier",
                "layout": "patches",
                "degree": 4,
                "domain": "grid coordinates (x, y) of the regular three-direction grid; a patch's point (u, v, w = 1 - u - v) sits at w corners[0] + u corners[1] + v corners[2]",
                "lattice_ordering": "in every patch, control point P_{i,j,k} (i + j + k = 4) has weight 4!/(i! j! k!) u^i v^j w^k and sits at index 5 j - j (j - 1) / 2 + i",
                "basis": "one quartic triangular Bezier patch per grid cell, C2 across cells: the Bezier form of the quartic box spline whose 12-point stencils over `control_points` at `control_coords` give the same surface (layout grid of kind loop)",
                "patches": patches,
                "cells": g.cells().iter().map(|&(i, j, d)| [i, j, i64::from(d)]).collect::<Vec<_>>(),
                "control_coords": g.control_coords().iter().map(|&(i, j)| [i, j]).collect::<Vec<_>>(),
            })
        }
        SurfaceModel::Grid(g) => json!({
            "kind": "loop",
            "layout": "grid",
            "domain": "grid coordinates (x, y) of the regular three-direction grid; grid vertex (i, j) is at x = i, y = j",
            "basis": "on every cell the quartic three-direction box spline of its 12 surrounding control points (the Loop limit surface of the regular control net); cell [i, j, 0] is the up triangle (i,j),(i+1,j),(i,j+1), [i, j, 1] the down triangle (i+1,j),(i+1,j+1),(i,j+1)",
            "cells": g.cells().iter().map(|&(i, j, d)| [i, j, i64::from(d)]).collect::<Vec<_>>(),
            "control_coords": g.control_coords().iter().map(|&(i, j)| [i, j]).collect::<Vec<_>>(),
        }),
        SurfaceModel::Mesh(m) => json!({
            "kind": "loop",
            "layout": "mesh",
            "domain": "every control face is a domain triangle; a parameter is (face, u, v) with u and v the barycentric weights of the face's corners 0 and 1 (w = 1 - u - v of corner 2)",
            "basis": "the Loop limit surface of the control mesh: Loop's original vertex weight beta(n) = (5/8 - (3/8 + cos(2 pi / n) / 4)^2) / n, boundary edges 1/2 1/2 and boundary vertices 3/4 1/8 1/8 (the boundary limit is the uniform cubic B-spline of the boundary polygon), boundary vertices with one face fixed; crease edges (Hoppe et al. 1994) are subdivided like boundary edges on both sides: a vertex with two sharp (crease or boundary) edges takes 3/4 1/8 1/8 along them, one with three or more (or a boundary vertex with a crease) is fixed, one with a single crease edge (a dart) keeps the smooth rule; faces whose corners are all regular on their side of every crease are quartic box-spline patches, the others are evaluated exactly by subdividing around them",
            "control_faces": m.faces(),
            "crease_edges": m.crease_edges(),
        }),
        SurfaceModel::BPatch(_) | SurfaceModel::Dms(_) => {
            super::scattered::kinds::model_json(&f.model, &f.controls).unwrap_or_else(|| json!({}))
        }
    };
    v["schema"] = json!("trispline.surface/1");
    v["control_points"] = json!(controls);
    if let Some(s) = scan {
        v["parameter_frame"] = json!({
            "about": "the plane the scan was mapped to: plane point (s, t) = ((p - origin) . e1, (p - origin) . e2); triangle domains give corners in (s, t), grid domains the spacing (grid vertex (i, j) at s = spacing (i + j / 2), t = spacing j sqrt(3) / 2)",
            "origin": s.mapping.frame.origin.to_array(),
            "e1": s.mapping.frame.e1.to_array(),
            "e2": s.mapping.frame.e2.to_array(),
            "domain": s.domain,
            "map": s.mapping.method,
        });
        if let Some(w) = &s.mapping.warp {
            v["parameter_frame"]["warp"] = json!({
                "about": "the projection (s, t) is warped before the domain applies: lattice vertex (i, j), 0 <= i < columns, 0 <= j < rows, sits at origin + spacing (i + j / 2, j sqrt(3) / 2) and moves to image[i + j columns]; between vertices the warp is linear on the triangles (i,j),(i+1,j),(i,j+1) and (i+1,j),(i+1,j+1),(i,j+1)",
                "lattice": w,
            });
        }
        v["trim"] = json!({
            "space": "the surface's own parameters (barycentric (u, v) for bezier, grid (x, y) for loop)",
            "outer": s.trims.outer.iter().map(|&(u, v)| [u, v]).collect::<Vec<_>>(),
            "holes": s.trims.holes.iter().map(|h| h.iter().map(|&(u, v)| [u, v]).collect::<Vec<_>>()).collect::<Vec<_>>(),
        });
    }
    v["fit"] = report["final"].clone();
    v["status"] = report["status"].clone();
    v
}

/// A tessellation of the fitted surface: parameters, points, normals, triangles (trimmed
/// to the scanned region when a trim is given).
pub struct Tessellation {
    /// Each vertex's surface parameter.
    pub params: Vec<SurfaceParam>,
    /// Each vertex's surface point.
    pub positions: Vec<DVec3>,
    /// Each vertex's unit normal.
    pub normals: Vec<DVec3>,
    /// The triangles kept.
    pub triangles: Vec<[u32; 3]>,
}

impl Tessellation {
    /// Vertices from the surface's evaluations at `params` (normal: S_u x S_v, unit).
    fn from_evaluations(
        evals: &[Derivatives],
        params: Vec<SurfaceParam>,
        triangles: Vec<[u32; 3]>,
    ) -> Self {
        Tessellation {
            positions: evals.iter().map(|d| d.position).collect(),
            normals: evals
                .iter()
                .map(|d| d.du.cross(d.dv).normalize_or_zero())
                .collect(),
            params,
            triangles,
        }
    }
}

/// `segments`: per side of the Bezier triangle; for a grid, the total budget spread over
/// the cells, at least 4 per cell side (a quartic cell flattened into 4 x 4 keeps the
/// chordal error far below scan noise at scan-like curvatures). With a coverage, only
/// the triangles it shows are kept (see [`Coverage`]).
pub fn tessellate(f: &PatchFit, segments: usize, coverage: Option<&Coverage>) -> Tessellation {
    tessellate_in(f, segments, coverage, None)
}

/// Where a coverage's coordinates are not the surface's own parameters (the planar kinds:
/// a coverage in domain points, a surface in (face, barycentric)): both ways between them.
pub(crate) struct CoverageFrame<'a> {
    /// A surface parameter's coverage coordinates (its `u`, `v`; the face is kept).
    pub to_coverage: &'a (dyn Fn(SurfaceParam) -> SurfaceParam + Sync),
    /// The surface parameter at coverage coordinates (the face given is a hint: the
    /// parameter's face before `to_coverage`, or the face of the triangle it was cut from).
    pub to_surface: &'a (dyn Fn(SurfaceParam) -> SurfaceParam + Sync),
}

/// `tessellate` with the coverage in its own coordinates (`frame`; `None`: the surface's).
pub(crate) fn tessellate_in(
    f: &PatchFit,
    segments: usize,
    coverage: Option<&Coverage>,
    frame: Option<&CoverageFrame>,
) -> Tessellation {
    // The coverage's point locator and the surface's samples need nothing of each other:
    // built side by side (each about a third of a 40k-point scan's tessellation).
    let (covers, (params, triangles, evals)) = rayon::join(
        || coverage.map(Coverage::tester),
        || sample_surface(f, segments),
    );
    let (mut params, mut evals) = (params, evals);
    let triangles = match (coverage, covers) {
        (Some(c), Some(mapped)) => {
            let evaluate = f.model.as_surface().evaluator(&f.controls);
            match frame {
                None => c.shown(
                    mapped,
                    &mut params,
                    &mut evals,
                    triangles,
                    evaluate.as_ref(),
                ),
                Some(frame) => {
                    let sampled = params.len();
                    let mut at: Vec<SurfaceParam> =
                        params.par_iter().map(|p| (frame.to_coverage)(*p)).collect();
                    let evaluate_at = |q: SurfaceParam| evaluate((frame.to_surface)(q));
                    let shown = c.shown(mapped, &mut at, &mut evals, triangles, &evaluate_at);
                    // The sampled vertices keep their parameters; the rim pieces' come back.
                    params.extend(at[sampled..].iter().map(|q| (frame.to_surface)(*q)));
                    shown
                }
            }
        }
        _ => triangles,
    };
    Tessellation::from_evaluations(&evals, params, triangles)
}

/// The tessellation's parameters, its untrimmed triangles and the surface there.
fn sample_surface(
    f: &PatchFit,
    segments: usize,
) -> (Vec<SurfaceParam>, Vec<[u32; 3]>, Vec<Derivatives>) {
    let (params, triangles) = match &f.model {
        SurfaceModel::Bezier(_) | SurfaceModel::BPatch(_) => {
            let n = segments.max(1);
            let params = lattice_points(n)
                .into_iter()
                .map(|(i, j)| SurfaceParam {
                    face: 0,
                    u: i as f64 / n as f64,
                    v: j as f64 / n as f64,
                })
                .collect();
            (params, lattice_triangles(n))
        }
        SurfaceModel::Grid(g) => {
            let per_cell = segments as f64 / (g.cells().len().max(1) as f64).sqrt();
            g.sample_lattice((per_cell.ceil() as usize).clamp(4, 32))
        }
        SurfaceModel::Mesh(_) | SurfaceModel::Dms(_) => {
            let faces = f.model.as_surface().domain_face_count();
            let per_face = segments as f64 / (faces.max(1) as f64).sqrt();
            let n = (per_face.ceil() as usize).clamp(4, 32);
            face_lattices(0..faces, n)
        }
    };
    let evaluate = f.model.as_surface().evaluator(&f.controls);
    let evals = params.par_iter().map(|p| evaluate(*p)).collect();
    (params, triangles, evals)
}

/// Each of `faces` its own lattice of `n` segments per side (vertices on shared edges
/// repeat: the surface is C1, so both copies carry the same point and normal).
fn face_lattices(
    faces: impl ExactSizeIterator<Item = usize>,
    n: usize,
) -> (Vec<SurfaceParam>, Vec<[u32; 3]>) {
    let n = n.max(1);
    let local = lattice_points(n);
    let local_tris = lattice_triangles(n);
    let mut params = Vec::with_capacity(faces.len() * local.len());
    let mut triangles = Vec::with_capacity(faces.len() * local_tris.len());
    for face in faces {
        let base = params.len() as u32;
        params.extend(local.iter().map(|&(i, j)| SurfaceParam {
            face: face as u32,
            u: i as f64 / n as f64,
            v: j as f64 / n as f64,
        }));
        triangles.extend(local_tris.iter().map(|t| t.map(|v| v + base)));
    }
    (params, triangles)
}

/// A control-mesh surface tessellated with `per_face` segments per control-face side,
/// untrimmed (a whole object's boundary loops are the control mesh's own), its vertices
/// shared between faces except across creases (`welded_lattice`): one connected mesh, as
/// the surface is. Other models get `tessellate` with that many segments in all.
pub fn tessellate_mesh_faces(f: &PatchFit, per_face: usize) -> Tessellation {
    let SurfaceModel::Mesh(m) = &f.model else {
        return tessellate(f, per_face, None);
    };
    let (params, triangles) = welded_lattices(m.topology(), m.crease_edges(), per_face);
    let evaluate = f.model.as_surface().evaluator(&f.controls);
    let evals: Vec<Derivatives> = params.par_iter().map(|p| evaluate(*p)).collect();
    Tessellation::from_evaluations(&evals, params, triangles)
}

/// The flat triangles' own error: for every triangle of a `per_face` tessellation of (at
/// most `max_faces`, spread evenly) control faces, the distance from the surface at the
/// triangle's parameter centroid to the triangle's centroid. Zero-length for models
/// without control faces.
pub fn chord_errors(f: &PatchFit, per_face: usize, max_faces: usize) -> Vec<f64> {
    let SurfaceModel::Mesh(m) = &f.model else {
        return Vec::new();
    };
    let faces = m.faces().len();
    let stride = faces.div_ceil(max_faces.max(1)).max(1);
    let (params, triangles) = face_lattices((0..faces).step_by(stride), per_face);
    let evaluate = f.model.as_surface().evaluator(&f.controls);
    let corners: Vec<DVec3> = params.par_iter().map(|p| evaluate(*p).position).collect();
    triangles
        .par_iter()
        .map(|t| {
            let [a, b, c] = t.map(|v| params[v as usize]);
            let centre = SurfaceParam {
                face: a.face,
                u: (a.u + b.u + c.u) / 3.0,
                v: (a.v + b.v + c.v) / 3.0,
            };
            let flat = t.iter().map(|&v| corners[v as usize]).sum::<DVec3>() / 3.0;
            (evaluate(centre).position - flat).length()
        })
        .collect()
}

/// The GLB of a tessellation, each vertex coloured by the geometric error of the data point
/// whose parameter is nearest (`ERROR_RAMP`: blue exact .. red twice the tolerance), the
/// ramp and its scale in the mesh's `extras`.
pub fn tessellated_glb(f: &PatchFit, tess: &Tessellation, tolerance: f64) -> Vec<u8> {
    // Parameters are (u, v) within a face: the nearest data point is searched among those
    // of the same face (one face for Bezier and grid surfaces).
    let mut by_face: rustc_hash::FxHashMap<u32, (Vec<SurfaceParam>, Vec<usize>)> =
        Default::default();
    if f.params.iter().all(|p| p.face == 0) {
        // Bezier and grid surfaces: one face, no grouping.
        by_face.insert(0, (f.params.clone(), (0..f.params.len()).collect()));
    } else {
        for (k, p) in f.params.iter().enumerate() {
            let entry = by_face.entry(p.face).or_default();
            entry.0.push(*p);
            entry.1.push(k);
        }
    }
    let nearest: rustc_hash::FxHashMap<u32, (NearestParam, &[usize])> = by_face
        .iter()
        .map(|(&face, (params, ids))| (face, (NearestParam::new(params), ids.as_slice())))
        .collect();
    // Only the vertices the trimmed triangles use go into the file (and need a colour).
    let mut remap = vec![u32::MAX; tess.positions.len()];
    let mut used: Vec<u32> = Vec::new();
    let triangles: Vec<[u32; 3]> = tess
        .triangles
        .iter()
        .map(|t| {
            t.map(|v| {
                let v = v as usize;
                if remap[v] == u32::MAX {
                    remap[v] = used.len() as u32;
                    used.push(v as u32);
                }
                remap[v]
            })
        })
        .collect();
    let positions: Vec<DVec3> = used.iter().map(|&v| tess.positions[v as usize]).collect();
    let normals: Vec<DVec3> = used.iter().map(|&v| tess.normals[v as usize]).collect();
    // Each vertex's nearest-parameter search on its own: in parallel, in order.
    let cols: Vec<[f32; 4]> = used
        .par_iter()
        .map(|&v| {
            let p = tess.params[v as usize];
            let e = nearest
                .get(&p.face)
                .and_then(|(n, ids)| n.nearest(p.u, p.v).map(|k| ids[k]))
                .map_or(0.0, |k| f.geometric_errors[k]);
            ERROR_RAMP.colour(e, tolerance)
        })
        .collect();
    let mesh = TriMesh::new(positions, triangles);
    glb_bytes_with_extras(
        &mesh,
        &GlbAttributes {
            normals: Some(&normals),
            colors: Some(&cols),
            polylines: &[],
        },
        Some(error_ramp(tolerance)),
    )
}

/// What the heatmap's colours mean, for the GLB's `extras` and report.json: the ramp's
/// stops at this tolerance, in the input's length unit (the unit of every error the
/// reports give).
pub fn error_ramp(tolerance: f64) -> serde_json::Value {
    ERROR_RAMP.extras(tolerance, ERROR_UNIT, ERROR_QUANTITY)
}

/// The heatmap's legend as an SVG image (written as legend.svg beside the GLB).
pub fn error_legend(tolerance: f64) -> String {
    ERROR_RAMP.legend_svg(
        tolerance,
        ERROR_UNIT,
        "surface.glb colours: distance from each data point to the fitted surface",
    )
}

/// The errors' unit: the input's own (no unit is declared by the formats read).
const ERROR_UNIT: &str = "input length unit";

const ERROR_QUANTITY: &str =
    "geometric error: distance from the data point whose parameter is nearest to the vertex";

/// Nearest data parameter through a uniform bucket grid over the parameters' bounding box.
struct NearestParam<'a> {
    params: &'a [SurfaceParam],
    lo: (f64, f64),
    cell: f64,
    dim: usize,
    /// Parameters of bucket b, in order: `bucketed[start[b]..start[b + 1]]`.
    start: Vec<u32>,
    bucketed: Vec<u32>,
}

impl<'a> NearestParam<'a> {
    fn new(params: &'a [SurfaceParam]) -> Self {
        let (mut lo, mut hi) = ((f64::MAX, f64::MAX), (f64::MIN, f64::MIN));
        for p in params {
            lo = (lo.0.min(p.u), lo.1.min(p.v));
            hi = (hi.0.max(p.u), hi.1.max(p.v));
        }
        let dim = ((params.len() as f64).sqrt() as usize / 2).clamp(1, 1024);
        let cell = ((hi.0 - lo.0).max(hi.1 - lo.1) / dim as f64).max(1e-300);
        let mut s = Self {
            params,
            lo,
            cell,
            dim,
            start: vec![0; dim * dim + 1],
            bucketed: vec![0; params.len()],
        };
        let slots: Vec<usize> = params
            .iter()
            .map(|p| {
                let (x, y) = s.cell_of(p.u, p.v);
                y * dim + x
            })
            .collect();
        for &b in &slots {
            s.start[b + 1] += 1;
        }
        for b in 0..dim * dim {
            s.start[b + 1] += s.start[b];
        }
        let mut fill = s.start.clone();
        for (k, &b) in slots.iter().enumerate() {
            s.bucketed[fill[b] as usize] = k as u32;
            fill[b] += 1;
        }
        s
    }

    fn cell_of(&self, u: f64, v: f64) -> (usize, usize) {
        let x = ((u - self.lo.0) / self.cell).max(0.0) as usize;
        let y = ((v - self.lo.1) / self.cell).max(0.0) as usize;
        (x.min(self.dim - 1), y.min(self.dim - 1))
    }

    fn nearest(&self, u: f64, v: f64) -> Option<usize> {
        let (cx, cy) = self.cell_of(u, v);
        let mut best: Option<(f64, usize)> = None;
        for r in 0..self.dim {
            ring_cells(cx, cy, r, self.dim, |x, y| {
                let b = y * self.dim + x;
                for &k in &self.bucketed[self.start[b] as usize..self.start[b + 1] as usize] {
                    let p = self.params[k as usize];
                    let d = (p.u - u).powi(2) + (p.v - v).powi(2);
                    if best.is_none_or(|b| d < b.0) {
                        best = Some((d, k as usize));
                    }
                }
            });
            // One more ring after the first hit: a nearer point can sit in the next ring.
            if let Some((d, _)) = best {
                if (r as f64 * self.cell).powi(2) >= d {
                    break;
                }
            }
        }
        best.map(|b| b.1)
    }
}
