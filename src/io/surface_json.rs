//! The `surface.json` schema (`trispline.surface/1`): the B-spline kind written here, and
//! a reader for every kind (`bezier`, `loop` with layout lattice, `grid` or `mesh`,
//! `bspline`, `bpatch`, `dms`) for the tools that consume fitted surfaces (`trispline curvature`).

use super::{IoError, IoErrorKind};
use crate::bspline::BSplineSurface;
use crate::surface::bezier::lattice_len;
use crate::surface::bpatch::{BPatch, BPatchRecord};
use crate::surface::dms::record::DmsRecord;
use crate::surface::dms::DmsSpline;
use crate::surface::grid_spline::GridSpline;
use crate::surface::loop_limit::{LoopLimitError, LoopLimitSurface};
use glam::DVec3;
use serde::Deserialize;
use serde_json::{json, Value};

pub(crate) const SCHEMA: &str = "trispline.surface/1";

/// Largest `surface.json` read: the daemon's default input limit (a parsed JSON value
/// takes several times its text).
const MAX_SURFACE_JSON_BYTES: u64 = 512 << 20;

/// A surface as described by a `surface.json`.
#[derive(Clone, Debug)]
pub enum SurfaceDescription {
    /// Triangular Bezier patch of the given degree, controls in lattice order.
    Bezier {
        /// The degree.
        degree: usize,
        /// Control points.
        controls: Vec<DVec3>,
    },
    /// Loop limit surface (quartic box spline) of a regular lattice net.
    Loop {
        /// Domain lattice segments per side.
        domain_segments: usize,
        /// Control points.
        controls: Vec<DVec3>,
    },
    /// Loop limit surface over cells of the three-direction grid (remeshed scans).
    LoopGrid {
        /// The surface over the listed cells.
        surface: GridSpline,
        /// Control points.
        controls: Vec<DVec3>,
    },
    /// Quartic Bezier patches over the cells of a grid (`bezier`, `layout: patches`): the
    /// same surface as `LoopGrid`, read from the box-spline form the file carries beside
    /// the patches.
    BezierPatches {
        /// The box-spline form of the patches.
        surface: GridSpline,
        /// Control points.
        controls: Vec<DVec3>,
    },
    /// Loop limit surface of an arbitrary manifold control mesh (`layout: mesh`): the
    /// control faces are the domain faces. Shared, since the surface memoises its
    /// subdivision nodes and is not cheap to rebuild.
    LoopMesh {
        /// The surface of the control faces.
        surface: std::sync::Arc<LoopLimitSurface>,
        /// Control points.
        controls: Vec<DVec3>,
    },
    /// A tensor-product B-spline surface.
    BSpline(BSplineSurface),
    /// A B-patch (`kind: bpatch`): parameters barycentric in its domain triangle.
    BPatch {
        /// The checked patch (degree, domain triangle, knots).
        patch: BPatch,
        /// Control points in lattice order.
        controls: Vec<DVec3>,
    },
    /// A DMS triangular B-spline (`kind: dms`): parameters are domain points.
    Dms {
        /// The checked spline (domain, knot clouds), shared: its compiled basis is not cheap
        /// to rebuild.
        spline: std::sync::Arc<DmsSpline>,
        /// Control points, triangle by triangle.
        controls: Vec<DVec3>,
    },
}

/// `[[a, b, c], ...]` of integers as triples.
fn int_rows<const N: usize>(v: &Value, key: &str, name: &str) -> Result<Vec<[i64; N]>, IoError> {
    let bad = || {
        IoError::at(
            name,
            format!("key {key}"),
            IoErrorKind::schema(format!("not a list of {N} integers each")),
        )
    };
    field(v, key, name)?
        .as_array()
        .ok_or_else(bad)?
        .iter()
        .map(|row| {
            let a = row.as_array().filter(|a| a.len() == N).ok_or_else(bad)?;
            let mut out = [0i64; N];
            for (o, x) in out.iter_mut().zip(a) {
                *o = x.as_i64().filter(|x| x.abs() < 1 << 40).ok_or_else(bad)?;
            }
            Ok(out)
        })
        .collect()
}

/// The JSON object of a B-spline surface (without fit statistics, which callers add).
/// What a patchwork is (split, patches, exact faces) and how far from its surface, against
/// `tolerance` (from `source`): the part of report.json that `trispline export` and the
/// daemon's surface.stp share.
pub(crate) fn patchwork_json(
    work: &crate::bspline::loop_patches::Patchwork,
    tolerance: f64,
    source: &str,
) -> Value {
    let d = work.deviation;
    json!({
        "patches": work.patches.len(),
        "patch_degrees": [4, 4],
        "depth": work.split.depth,
        "corner_levels": work.split.corner_levels,
        "exact_faces": work.exact_faces,
        "tolerance": { "value": tolerance, "from": source, "met": d.max <= tolerance },
        "deviation": {
            "samples": d.samples,
            "max": d.max,
            "rms": d.rms,
            "normal_p99_deg": d.normal_p99_deg,
            "normal_max_deg": d.normal_max_deg,
            "measure": "distance from points of the limit surface (a lattice over every patch) to the patchwork (their own patch, or the one across the edge their foot reaches), and the angle between the two normals there, in the surface's unit and degrees; patches of regular control faces are the surface itself",
        },
    })
}

pub(crate) fn bspline_json(s: &BSplineSurface) -> Value {
    let (p, q) = s.degrees();
    let (nu, nv) = s.counts();
    json!({
        "schema": SCHEMA,
        "kind": "bspline",
        "degree_u": p,
        "degree_v": q,
        "knots_u": s.knots_u(),
        "knots_v": s.knots_v(),
        "control_grid": [nu, nv],
        "control_ordering": "row-major: control (i, j), i = 0..control_grid[0] along u, j along v, at index i * control_grid[1] + j",
        "domain": "u in [knots_u[degree_u], knots_u[control_grid[0]]], v likewise; S(u, v) = sum_ij N_i,degree_u(u) N_j,degree_v(v) P_ij (clamped, non-rational)",
        "control_points": s.controls().iter().map(|c| [c.x, c.y, c.z]).collect::<Vec<_>>(),
    })
}

fn field<'a>(v: &'a Value, key: &str, name: &str) -> Result<&'a Value, IoError> {
    v.get(key)
        .ok_or_else(|| IoError::at(name, format!("key {key}"), IoErrorKind::schema("missing")))
}

fn uint(v: &Value, key: &str, name: &str) -> Result<usize, IoError> {
    field(v, key, name)?
        .as_u64()
        .map(|x| x as usize)
        .ok_or_else(|| {
            IoError::at(
                name,
                format!("key {key}"),
                IoErrorKind::schema("not a non-negative integer"),
            )
        })
}

fn reals(v: &Value, key: &str, name: &str) -> Result<Vec<f64>, IoError> {
    let arr = field(v, key, name)?.as_array().ok_or_else(|| {
        IoError::at(
            name,
            format!("key {key}"),
            IoErrorKind::schema("not an array"),
        )
    })?;
    arr.iter()
        .enumerate()
        .map(|(k, x)| {
            x.as_f64().ok_or_else(|| {
                IoError::at(
                    name,
                    format!("{key}[{k}]"),
                    IoErrorKind::schema("not a number"),
                )
            })
        })
        .collect()
}

fn points(v: &Value, name: &str) -> Result<Vec<DVec3>, IoError> {
    let arr = field(v, "control_points", name)?
        .as_array()
        .ok_or_else(|| {
            IoError::at(
                name,
                "key control_points",
                IoErrorKind::schema("not an array"),
            )
        })?;
    arr.iter()
        .enumerate()
        .map(|(k, p)| {
            let c = p.as_array().filter(|c| c.len() == 3).ok_or_else(|| {
                IoError::at(
                    name,
                    format!("control_points[{k}]"),
                    IoErrorKind::schema("not [x, y, z]"),
                )
            })?;
            let mut x = [0.0; 3];
            for (d, e) in x.iter_mut().zip(c) {
                *d = e.as_f64().filter(|f| f.is_finite()).ok_or_else(|| {
                    IoError::at(
                        name,
                        format!("control_points[{k}]"),
                        IoErrorKind::non_finite("not a finite number"),
                    )
                })?;
            }
            Ok(DVec3::from_array(x))
        })
        .collect()
}

fn expect_len(name: &str, got: usize, want: usize, what: &str) -> Result<(), IoError> {
    if got != want {
        return Err(IoError::at(
            name,
            "key control_points",
            IoErrorKind::count_mismatch(format!("{got} control points, {what} needs {want}")),
        ));
    }
    Ok(())
}

/// Reads a `surface.json`; `name` is used in errors.
pub fn parse_surface_json(bytes: &[u8], name: &str) -> Result<SurfaceDescription, IoError> {
    let v: Value = serde_json::from_slice(bytes).map_err(|e| {
        IoError::at(
            name,
            format!("line {}, column {}", e.line(), e.column()),
            IoErrorKind::Json(e),
        )
    })?;
    match v.get("schema").and_then(Value::as_str) {
        Some(SCHEMA) => {}
        other => {
            return Err(IoError::at(
                name,
                "key schema",
                IoErrorKind::schema(format!("expected {SCHEMA:?}, found {other:?}")),
            ))
        }
    }
    let kind = field(&v, "kind", name)?.as_str().unwrap_or_default();
    let layout = v.get("layout").and_then(Value::as_str);
    match (kind, layout) {
        ("bezier", Some("patches")) | ("loop", Some("grid")) => grid_surface(&v, kind, name),
        ("bezier", _) => bezier_patch(&v, name),
        ("loop", Some("mesh")) => loop_mesh(&v, name),
        ("loop", _) => loop_lattice(&v, name),
        ("bspline", _) => bspline_surface(&v, name),
        ("bpatch", _) => bpatch_surface(&v, name),
        ("dms", _) => dms_surface(&v, name),
        (other, _) => Err(IoError::at(
            name,
            "key kind",
            IoErrorKind::schema(format!(
                "unknown surface kind {other:?} (bezier, loop, bspline, bpatch, dms)"
            )),
        )),
    }
}

/// `kind: bezier`: one triangular Bezier patch, controls in lattice order.
fn bezier_patch(v: &Value, name: &str) -> Result<SurfaceDescription, IoError> {
    let degree = uint(v, "degree", name)?;
    if degree == 0 || degree > 64 {
        return Err(IoError::at(
            name,
            "key degree",
            IoErrorKind::schema("degree outside 1..=64"),
        ));
    }
    let controls = points(v, name)?;
    expect_len(
        name,
        controls.len(),
        lattice_len(degree),
        "a triangular Bezier patch of this degree",
    )?;
    Ok(SurfaceDescription::Bezier { degree, controls })
}

/// `kind: loop, layout: grid` and `kind: bezier, layout: patches`: the box-spline form
/// over the listed grid cells (Bezier patches carry it beside the patches).
fn grid_surface(v: &Value, kind: &str, name: &str) -> Result<SurfaceDescription, IoError> {
    let cells = int_rows::<3>(v, "cells", name)?;
    check_cell_span(&cells, name)?;
    let coords = int_rows::<2>(v, "control_coords", name)?;
    let surface = GridSpline::new(cells.iter().map(|c| (c[0], c[1], c[2] != 0)));
    let same = surface.control_coords().len() == coords.len()
        && surface
            .control_coords()
            .iter()
            .zip(&coords)
            .all(|(a, b)| a.0 == b[0] && a.1 == b[1]);
    if !same {
        return Err(IoError::at(
            name,
            "key control_coords",
            IoErrorKind::schema("not the control points of the listed cells (in row order)"),
        ));
    }
    let controls = points(v, name)?;
    expect_len(
        name,
        controls.len(),
        coords.len(),
        "the grid's control list",
    )?;
    Ok(if kind == "bezier" {
        SurfaceDescription::BezierPatches { surface, controls }
    } else {
        SurfaceDescription::LoopGrid { surface, controls }
    })
}

/// Grid surfaces index their controls and cells through dense tables over the bounding
/// box of the cells (about 20 bytes per grid point): two cells far apart would make a
/// few-byte file take gigabytes. The box may hold at most `SPAN_PER_CELL` grid points per
/// listed cell (fitted grids cover a compact region: about two per cell) and never more
/// than `MAX_SPAN` (~350 MB of tables).
fn check_cell_span(cells: &[[i64; 3]], name: &str) -> Result<(), IoError> {
    const SPAN_PER_CELL: u64 = 32;
    const MAX_SPAN: u64 = 1 << 24;
    // The stencil of a cell reaches two grid points beyond it on every side.
    const MARGIN: i64 = 4;
    let (Some(lo_i), Some(hi_i), Some(lo_j), Some(hi_j)) = (
        cells.iter().map(|c| c[0]).min(),
        cells.iter().map(|c| c[0]).max(),
        cells.iter().map(|c| c[1]).min(),
        cells.iter().map(|c| c[1]).max(),
    ) else {
        return Ok(());
    };
    // Coordinates are below 2^40 (int_rows): these cannot overflow.
    let width = (hi_i - lo_i + 1 + 2 * MARGIN) as u64;
    let height = (hi_j - lo_j + 1 + 2 * MARGIN) as u64;
    let span = width.saturating_mul(height);
    let budget = (cells.len() as u64 * SPAN_PER_CELL + 4096).min(MAX_SPAN);
    if span > budget {
        return Err(IoError::at(
            name,
            "key cells",
            IoErrorKind::too_large(format!(
                "{} cells span a {width} x {height} grid; at most {budget} grid points are allowed",
                cells.len()
            )),
        ));
    }
    Ok(())
}

/// `kind: loop, layout: mesh`: the Loop limit surface of an arbitrary manifold control mesh.
fn loop_mesh(v: &Value, name: &str) -> Result<SurfaceDescription, IoError> {
    let controls = points(v, name)?;
    let faces = int_rows::<3>(v, "control_faces", name)?
        .into_iter()
        .enumerate()
        .map(|(f, t)| {
            // Range-check here so the error names the row; LoopLimitSurface::new
            // checks again against the control count.
            let mut out = [0u32; 3];
            for (o, &i) in out.iter_mut().zip(&t) {
                *o = u32::try_from(i)
                    .ok()
                    .filter(|&i| (i as usize) < controls.len())
                    .ok_or_else(|| {
                        IoError::at(
                            name,
                            format!("control_faces[{f}]"),
                            IoErrorKind::index_out_of_range(format!(
                                "index {i} is not one of the {} control points",
                                controls.len()
                            )),
                        )
                    })?;
            }
            Ok(out)
        })
        .collect::<Result<Vec<_>, IoError>>()?;
    // Optional: files written before creases existed have none.
    let creases = if v.get("crease_edges").is_some() {
        int_rows::<2>(v, "crease_edges", name)?
            .into_iter()
            .map(|[a, b]| [a, b].map(|i| u32::try_from(i).unwrap_or(u32::MAX)))
            .collect()
    } else {
        Vec::new()
    };
    let surface =
        LoopLimitSurface::with_creases(controls.len(), &faces, &creases).map_err(|e| {
            let key = match &e {
                LoopLimitError::UnknownCreaseEdge { .. } => "key crease_edges",
                _ => "key control_faces",
            };
            IoError::at(name, key, IoErrorKind::LoopSurface(e))
        })?;
    Ok(SurfaceDescription::LoopMesh {
        surface: std::sync::Arc::new(surface),
        controls,
    })
}

/// `kind: loop` without a layout: the regular lattice net of `domain_segments`.
fn loop_lattice(v: &Value, name: &str) -> Result<SurfaceDescription, IoError> {
    let n = uint(v, "domain_segments", name)?;
    if n == 0 || n > 4096 {
        return Err(IoError::at(
            name,
            "key domain_segments",
            IoErrorKind::schema("outside 1..=4096"),
        ));
    }
    let controls = points(v, name)?;
    expect_len(
        name,
        controls.len(),
        lattice_len(n + 3),
        "a regular lattice net of n + 3 segments",
    )?;
    Ok(SurfaceDescription::Loop {
        domain_segments: n,
        controls,
    })
}

/// `kind: bspline`: a clamped tensor-product B-spline surface.
fn bspline_surface(v: &Value, name: &str) -> Result<SurfaceDescription, IoError> {
    let (p, q) = (uint(v, "degree_u", name)?, uint(v, "degree_v", name)?);
    let grid = reals(v, "control_grid", name)?;
    let (nu, nv) = match grid[..] {
        [a, b]
            if (1.0..=1e7).contains(&a)
                && (1.0..=1e7).contains(&b)
                && a.fract() == 0.0
                && b.fract() == 0.0 =>
        {
            (a as usize, b as usize)
        }
        _ => {
            return Err(IoError::at(
                name,
                "key control_grid",
                IoErrorKind::schema("not [count_u, count_v] with counts in 1..=10^7"),
            ))
        }
    };
    let ku = reals(v, "knots_u", name)?;
    let kv = reals(v, "knots_v", name)?;
    let controls = points(v, name)?;
    BSplineSurface::new((p, q), ku, kv, (nu, nv), controls)
        .map(SurfaceDescription::BSpline)
        .map_err(|e| IoError::new(name, None, IoErrorKind::BSpline(e)))
}

/// `kind: bpatch`: the record of `surface::bpatch`, checked (degree, corners, knot
/// triangles, control count).
fn bpatch_surface(v: &Value, name: &str) -> Result<SurfaceDescription, IoError> {
    // The control points first: their errors name the point, as for every other kind.
    points(v, name)?;
    let record = BPatchRecord::deserialize(v)
        .map_err(|e| IoError::at(name, "kind bpatch", IoErrorKind::schema(e.to_string())))?;
    let (patch, controls) = record
        .surface()
        .map_err(|e| IoError::at(name, "kind bpatch", IoErrorKind::schema(e.to_string())))?;
    Ok(SurfaceDescription::BPatch { patch, controls })
}

/// Most DMS domain triangles read: each compiles a simplex-spline family (a few kB), so a
/// small file must not ask for gigabytes.
const MAX_DMS_TRIANGLES: usize = 1 << 20;

/// `kind: dms`: the record of `surface::dms::record`, checked (domain, the DMS and boundary
/// conditions of the knot clouds, control count).
fn dms_surface(v: &Value, name: &str) -> Result<SurfaceDescription, IoError> {
    points(v, name)?;
    let triangles = v
        .get("domain_triangles")
        .and_then(Value::as_array)
        .map_or(0, Vec::len);
    if triangles > MAX_DMS_TRIANGLES {
        return Err(IoError::at(
            name,
            "key domain_triangles",
            IoErrorKind::too_large(format!(
                "{triangles} triangles, at most {MAX_DMS_TRIANGLES}"
            )),
        ));
    }
    let record = DmsRecord::deserialize(v)
        .map_err(|e| IoError::at(name, "kind dms", IoErrorKind::schema(e.to_string())))?;
    let (spline, controls) = record
        .surface()
        .map_err(|e| IoError::at(name, "kind dms", IoErrorKind::schema(e.to_string())))?;
    Ok(SurfaceDescription::Dms {
        spline: std::sync::Arc::new(spline),
        controls,
    })
}

/// Reads a `surface.json` file.
pub fn read_surface_json(path: &std::path::Path) -> Result<SurfaceDescription, IoError> {
    let name = path.display().to_string();
    let bytes = super::read_limited(path, MAX_SURFACE_JSON_BYTES, "the surface file")
        .map_err(|kind| IoError::new(&name, None, kind))?;
    parse_surface_json(&bytes, &name)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bspline_round_trips() {
        let s = BSplineSurface::new(
            (2, 1),
            vec![0.0, 0.0, 0.0, 0.5, 1.0, 1.0, 1.0],
            vec![0.0, 0.0, 1.0, 1.0],
            (4, 2),
            (0..8)
                .map(|k| DVec3::new(k as f64, (k * k) as f64 * 0.1, -0.3))
                .collect(),
        )
        .expect("valid");
        let bytes = serde_json::to_vec(&bspline_json(&s)).expect("json");
        match parse_surface_json(&bytes, "t").expect("parse") {
            SurfaceDescription::BSpline(r) => assert_eq!(r, s),
            other => panic!("wrong kind {other:?}"),
        }
    }

    #[test]
    fn loop_mesh_round_trips() {
        let controls = vec![
            DVec3::new(0.0, 0.0, 0.1),
            DVec3::new(1.0, 0.0, 0.0),
            DVec3::new(0.0, 1.0, 0.2),
            DVec3::new(-1.0, 0.0, 0.0),
        ];
        let faces = vec![[0u32, 1, 2], [0, 2, 3]];
        let text = json!({
            "schema": SCHEMA,
            "kind": "loop",
            "layout": "mesh",
            "control_faces": faces,
            "crease_edges": [[2, 0]],
            "control_points": controls.iter().map(|c| [c.x, c.y, c.z]).collect::<Vec<_>>(),
        });
        let bytes = serde_json::to_vec(&text).expect("json");
        match parse_surface_json(&bytes, "t").expect("parse") {
            SurfaceDescription::LoopMesh {
                surface,
                controls: c,
            } => {
                assert_eq!(c, controls);
                assert_eq!(surface.faces(), &faces[..]);
                assert_eq!(surface.crease_edges(), &[[0, 2]]);
            }
            other => panic!("wrong kind {other:?}"),
        }
    }

    #[test]
    fn malformed_files_name_the_problem() {
        let cases = [
            (r#"{"schema":"x","kind":"bezier"}"#, "schema"),
            (
                r#"{"schema":"trispline.surface/1","kind":"bspline","degree_u":2,"degree_v":2,"control_grid":[1e300,3],"knots_u":[],"knots_v":[],"control_points":[]}"#,
                "control_grid",
            ),
            (
                r#"{"schema":"trispline.surface/1","kind":"bspline","degree_u":18446744073709551615,"degree_v":2,"control_grid":[3,3],"knots_u":[0,0,0,1,1,1],"knots_v":[0,0,0,1,1,1],"control_points":[]}"#,
                "degree",
            ),
            (r#"{"schema":"trispline.surface/1","kind":"torus"}"#, "kind"),
            (
                r#"{"schema":"trispline.surface/1","kind":"bezier","degree":2,"control_points":[[0,0,0]]}"#,
                "control_points",
            ),
            (
                r#"{"schema":"trispline.surface/1","kind":"bspline","degree_u":2,"degree_v":2,"control_grid":[3,3],"knots_u":[0,0,0,1,1],"knots_v":[0,0,0,1,1,1],"control_points":[]}"#,
                "knot",
            ),
            ("{", "line"),
            (
                r#"{"schema":"trispline.surface/1","kind":"loop","layout":"mesh","control_points":[[0,0,0],[1,0,0],[0,1,0]],"control_faces":[[0,1]]}"#,
                "control_faces",
            ),
            (
                r#"{"schema":"trispline.surface/1","kind":"loop","layout":"mesh","control_points":[[0,0,0],[1,0,0],[0,1,0]],"control_faces":[[0,1,3]]}"#,
                "control_faces[0]",
            ),
            (
                r#"{"schema":"trispline.surface/1","kind":"loop","layout":"mesh","control_points":[[0,0,0],[1,0,0],[0,1,0]]}"#,
                "key control_faces",
            ),
            (
                r#"{"schema":"trispline.surface/1","kind":"loop","layout":"mesh","control_points":[[0,0,0],[1,0,0],[0,1,0],[1,1,0]],"control_faces":[[0,1,2],[1,3,2]],"crease_edges":[[0,3]]}"#,
                "crease_edges",
            ),
            (
                r#"{"schema":"trispline.surface/1","kind":"loop","layout":"mesh","control_points":[[0,0,0],[1,0,0],[0,1,0],[1,1,0]],"control_faces":[[0,1,2],[1,3,2]],"crease_edges":[[1]]}"#,
                "crease_edges",
            ),
            // Four faces on one edge: the LoopLimitError names the non-manifold net.
            (
                r#"{"schema":"trispline.surface/1","kind":"loop","layout":"mesh","control_points":[[0,0,0],[1,0,0],[0,1,0],[0,-1,0],[0,0,1],[0,0,-1]],"control_faces":[[0,1,2],[1,0,3],[0,1,4],[1,0,5]]}"#,
                "not a manifold",
            ),
        ];
        for (text, needle) in cases {
            let e = parse_surface_json(text.as_bytes(), "s.json").expect_err(text);
            assert!(e.to_string().contains(needle), "{e} lacks {needle}");
            assert!(e.to_string().contains("s.json"), "{e} lacks the file name");
        }
    }
}
