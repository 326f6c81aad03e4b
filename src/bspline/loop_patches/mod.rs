//! A Loop limit surface over any control mesh as CAD patches: one Bezier patch of degree
//! (4, 4) per control face, or per sub-triangle when faces are split (`split`: uniformly,
//! and at irregular vertices), each the tensor-product form of a quartic triangle
//! (degenerate along one side, as a CAD sphere is at its poles). STEP and IGES carry them
//! as B-spline surfaces.
//!
//! Why quartic triangles: a regular face's limit patch is a quartic box spline, i.e. a
//! quartic triangle, so its patch is the surface itself (to rounding); only faces at an
//! extraordinary, boundary or crease vertex, where the limit is no polynomial, are
//! approximated, and splitting shrinks that approximation where it is needed.
//!
//! Watertight by construction: each patch edge is one quartic curve, fitted once to the
//! exact limit curve (ends interpolated) and shared by the two patches that meet there.
//! The three interior ordinates of each patch are then fitted to the limit surface by
//! least squares. The deviation is measured on a lattice other than the fit's, from each
//! limit point to its foot on the patch, and in normal direction.

mod measure;
mod quartic;
mod split;

use super::{BSplineError, BSplineSurface};
use crate::surface::loop_limit::LoopLimitSurface;
use crate::surface::{Derivatives, SurfaceParam, TriSurface};
use glam::DVec3;
use quartic::{ordinate, tensor_form, Fits};
use rayon::prelude::*;
use split::{node, param, sub_triangles, Lattice, Node};
use std::collections::HashMap;

/// Deepest uniform split taken: each control face becomes 4^depth patches.
pub const MAX_DEPTH: u32 = 4;
/// Most levels of splitting at irregular vertices.
pub const MAX_CORNER_LEVELS: u32 = 8;

/// Most corner levels [`loop_patchwork_within`] goes to in search of its tolerance. Each
/// level adds two patches per face corner at an irregular vertex and halves (or better)
/// the largest deviation, which sits at those vertices (bun_zipper's fit: 3311 patches at
/// level 0, 9392 at 1, 16940 at 2; 33, 15 and 2.6 um).
pub const MAX_AUTO_CORNER_LEVELS: u32 = 6;

/// Default tolerance without a fit's RMS, as a share of the controls' bounding-box
/// diagonal (the fits' own default tolerance is 1e-3 of it).
const DIAGONAL_SHARE: f64 = 1e-4;

/// How each control face is cut into patches (see `split`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Split {
    /// Uniform splits of every face (4^depth triangles), at most [`MAX_DEPTH`].
    pub depth: u32,
    /// Then halvings of the edges at irregular vertices, at most [`MAX_CORNER_LEVELS`].
    pub corner_levels: u32,
}

/// How far a patchwork is from its limit surface.
#[derive(Clone, Copy, Debug, Default)]
pub struct PatchDeviation {
    /// Limit-surface points compared with their patch.
    pub samples: usize,
    /// Largest distance from such a point to its patch.
    pub max: f64,
    /// Root mean square distance.
    pub rms: f64,
    /// Largest angle between a patch's normal and the surface's, in degrees (at sliver
    /// faces, where the limit surface's own normal turns fast, it can be large).
    pub normal_max_deg: f64,
    /// The 99th percentile of that angle, in degrees.
    pub normal_p99_deg: f64,
}

/// A limit surface as patches.
#[derive(Debug)]
pub struct Patchwork {
    /// Degree (4, 4) Bezier patches, in control-face order.
    pub patches: Vec<BSplineSurface>,
    /// How the faces were cut.
    pub split: Split,
    /// Control faces whose patches are exact (regular box-spline faces).
    pub exact_faces: usize,
    /// Measured deviation from the limit surface.
    pub deviation: PatchDeviation,
}

/// One patch as fitted: its quartic triangle's ordinates, the control face it lies in,
/// its corners in that face's parameters and their lattice nodes.
struct Piece {
    b: [DVec3; 15],
    face: usize,
    corners: Corners,
    nodes: [Node; 3],
}

/// A patch edge's ends in its face's parameters (u, v).
type Span = ((f64, f64), (f64, f64));

/// A sub-triangle's corners in its face's parameters (u, v).
type Corners = [(f64, f64); 3];

fn at(c: &Corners, x: f64, y: f64) -> (f64, f64) {
    let z = 1.0 - x - y;
    (
        c[0].0 * x + c[1].0 * y + c[2].0 * z,
        c[0].1 * x + c[1].1 * y + c[2].1 * z,
    )
}

/// Per control vertex: whether faces around it are not box-spline patches there (an
/// interior vertex of valence other than 6, a boundary vertex with other than 3 faces, any
/// vertex on a crease).
fn irregular_vertices(surface: &LoopLimitSurface) -> Vec<bool> {
    let topology = surface.topology();
    let mut irregular: Vec<bool> = topology
        .face_valence
        .iter()
        .zip(&topology.boundary)
        .map(|(&faces, &boundary)| faces != if boundary { 3 } else { 6 })
        .collect();
    for e in surface.crease_edges() {
        for &v in e {
            irregular[v as usize] = true;
        }
    }
    irregular
}

/// The limit surface of `surface` over `controls` as patches, each control face cut as
/// `split` says (clamped to [`MAX_DEPTH`] and [`MAX_CORNER_LEVELS`]).
pub fn loop_patchwork(
    surface: &LoopLimitSurface,
    controls: &[DVec3],
    split: Split,
) -> Result<Patchwork, BSplineError> {
    if controls.len() != surface.control_count() {
        return Err(BSplineError::ControlCount {
            got: controls.len(),
            expected: surface.control_count(),
        });
    }
    let split = Split {
        depth: split.depth.min(MAX_DEPTH),
        corner_levels: split.corner_levels.min(MAX_CORNER_LEVELS),
    };
    let eval = surface.evaluator(controls);
    let point = |face: usize, (u, v): (f64, f64)| -> Derivatives {
        eval(SurfaceParam {
            face: face as u32,
            u,
            v,
        })
    };
    let fits = Fits::new();
    let faces = surface.faces();
    let irregular = irregular_vertices(surface);
    let cuts: Vec<Vec<[Lattice; 3]>> = faces
        .iter()
        .map(|t| {
            sub_triangles(
                split.depth,
                split.corner_levels,
                t.map(|v| irregular[v as usize]),
            )
        })
        .collect();
    let curves = edge_curves(faces, &cuts, &fits, &|f, p| point(f, p).position);

    let pieces: Vec<Piece> = faces
        .par_iter()
        .zip(&cuts)
        .enumerate()
        .flat_map_iter(|(f, (&corners, tris))| {
            let (curves, fits, point) = (&curves, &fits, &point);
            tris.iter().map(move |tri| {
                let nodes = tri.map(|l| node(f, corners, l));
                let c: Corners = tri.map(param);
                let mut b = boundary_ordinates(&nodes, curves);
                fits.interior(&mut b, |x, y| point(f, at(&c, x, y)).position);
                Piece {
                    b,
                    face: f,
                    corners: c,
                    nodes,
                }
            })
        })
        .collect();
    let deviation = measure::deviation(&pieces, &|f, p| point(f, p));
    let patches = pieces
        .iter()
        .map(|piece| tensor_form(&piece.b))
        .collect::<Result<Vec<_>, _>>()?;
    Ok(Patchwork {
        patches,
        split,
        exact_faces: (0..faces.len())
            .filter(|&f| surface.is_regular_face(f))
            .count(),
        deviation,
    })
}

/// The patchwork cut uniformly `depth` times and then at the fewest corner levels (up to
/// [`MAX_AUTO_CORNER_LEVELS`]) whose largest deviation is within `tolerance`.
pub fn loop_patchwork_within(
    surface: &LoopLimitSurface,
    controls: &[DVec3],
    depth: u32,
    tolerance: f64,
) -> Result<Patchwork, BSplineError> {
    let mut split = Split {
        depth,
        corner_levels: 0,
    };
    let mut work = loop_patchwork(surface, controls, split)?;
    while work.deviation.max > tolerance && split.corner_levels < MAX_AUTO_CORNER_LEVELS {
        split.corner_levels += 1;
        work = loop_patchwork(surface, controls, split)?;
    }
    Ok(work)
}

/// The default tolerance of a patchwork and where it comes from: the fit's RMS error when
/// known (the conversion then adds at its worst point no more than the fit's typical
/// error), else 1e-4 of the controls' bounding-box diagonal; `None` when the controls span
/// nothing.
pub fn default_tolerance(fit_rms: Option<f64>, controls: &[DVec3]) -> Option<(f64, &'static str)> {
    if let Some(rms) = fit_rms.filter(|x| x.is_finite() && *x > 0.0) {
        return Some((rms, "the fit's RMS error (surface.json fit.rms_error)"));
    }
    let (lo, hi) = controls.iter().fold(
        (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)),
        |(lo, hi), p| (lo.min(*p), hi.max(*p)),
    );
    let diagonal = (hi - lo).length();
    (diagonal.is_finite() && diagonal > 0.0).then_some((
        diagonal * DIAGONAL_SHARE,
        "1e-4 of the controls' bounding-box diagonal",
    ))
}

/// Every patch edge of the cuts, once, in the direction from its lower node to its
/// higher. Each lattice node's limit point is evaluated once, from one of its faces, so
/// the patches meeting at a node share its position to the bit.
fn edge_curves(
    faces: &[[u32; 3]],
    cuts: &[Vec<[Lattice; 3]>],
    fits: &Fits,
    limit: &(dyn Fn(usize, (f64, f64)) -> DVec3 + Sync),
) -> HashMap<(Node, Node), [DVec3; 5]> {
    let mut nodes: HashMap<Node, (usize, (f64, f64))> = HashMap::new();
    let mut edges: HashMap<(Node, Node), (usize, Span)> = HashMap::new();
    for (f, (&corners, tris)) in faces.iter().zip(cuts).enumerate() {
        for tri in tris {
            for k in 0..3 {
                let (a, b) = (tri[k], tri[(k + 1) % 3]);
                let (na, nb) = (node(f, corners, a), node(f, corners, b));
                nodes.entry(na).or_insert((f, param(a)));
                let (key, pa, pb) = if na < nb {
                    ((na, nb), a, b)
                } else {
                    ((nb, na), b, a)
                };
                edges.entry(key).or_insert((f, (param(pa), param(pb))));
            }
        }
    }
    let positions: HashMap<Node, DVec3> = nodes
        .into_par_iter()
        .map(|(key, (f, p))| (key, limit(f, p)))
        .collect();
    edges
        .into_par_iter()
        .map(|(key, (f, (pa, pb)))| {
            let along = |t: f64| limit(f, (pa.0 + (pb.0 - pa.0) * t, pa.1 + (pb.1 - pa.1) * t));
            let ends = [key.0, key.1].map(|k| positions.get(&k).copied().unwrap_or(DVec3::ZERO));
            (key, fits.edge(ends, along))
        })
        .collect()
}

/// The 12 boundary ordinates of the sub-triangle with these corner nodes, from the shared
/// edge curves (the interior three are left zero).
fn boundary_ordinates(
    nodes: &[Node; 3],
    curves: &HashMap<(Node, Node), [DVec3; 5]>,
) -> [DVec3; 15] {
    // From corner `from` to corner `to`: the stored curve, reversed when stored the
    // other way.
    let curve = |from: usize, to: usize| -> [DVec3; 5] {
        let (a, b) = (nodes[from], nodes[to]);
        match curves.get(&(a.min(b), a.max(b))) {
            Some(c) if a < b => *c,
            Some(c) => [c[4], c[3], c[2], c[1], c[0]],
            None => [DVec3::ZERO; 5],
        }
    };
    let mut b = [DVec3::ZERO; 15];
    let (ab, bc, ca) = (curve(0, 1), curve(1, 2), curve(2, 0));
    for m in 0..=4 {
        b[ordinate(4 - m, m)] = ab[m];
        b[ordinate(0, 4 - m)] = bc[m];
        b[ordinate(m, 0)] = ca[m];
    }
    b
}
