//! What a B-patch or DMS fit adds to the outputs: its `surface.json` kind (the records of
//! `surface::bpatch` and `surface::dms::record`, with the text another program needs to
//! evaluate them), the plane frame and trims, the report's keys, the warm state, and the
//! tessellation trimmed to the scanned region in domain coordinates.

use super::{planar_surface, ScatteredInfo, ScatteredWarm};
use crate::pipeline::output::{tessellate, Tessellation};
use crate::pipeline::scan::WarmFeet;
use crate::pipeline::worker::WarmStart;
use crate::pipeline::{PatchFit, SurfaceModel};
use crate::surface::bpatch::BPatchRecord;
use crate::surface::dms::record::DmsRecord;
use glam::{DVec2, DVec3};
use rayon::prelude::*;
use serde_json::{json, Value};

const LATTICE_ORDERING: &str = "control point b = (i, j, k), i + j + k = degree, sits at index j*(degree+1) - j*(j-1)/2 + i (the bezier kind's lattice order)";

/// The `surface.json` object of a B-patch or DMS model with `controls` (`None` for other
/// models).
pub fn model_json(model: &SurfaceModel, controls: &[DVec3]) -> Option<Value> {
    let mut v = match model {
        SurfaceModel::BPatch(b) => {
            let mut v = serde_json::to_value(BPatchRecord::new(b, controls)).ok()?;
            v["kind"] = json!("bpatch");
            v["domain"] = json!("domain points x in the plane of parameter_frame, inside domain_triangle [A, B, C] (counter-clockwise)");
            v["evaluation"] = json!("Seidel's B-patch: level 0 are the control points P_b; for l = 1..degree and every b with |b| = degree - l, P_b^l = l0 P_(b+(1,0,0))^(l-1) + l1 P_(b+(0,1,0))^(l-1) + l2 P_(b+(0,0,1))^(l-1), (l0, l1, l2) the barycentric coordinates of x in the knot triangle [r_b0, s_b1, t_b2]; the point is P_(0,0,0)^degree. r_0, s_0, t_0 are A, B, C; with every knot on its corner this is the Bezier patch over [A, B, C]");
            v
        }
        SurfaceModel::Dms(d) => {
            let mut v = serde_json::to_value(DmsRecord::new(d, controls)).ok()?;
            v["kind"] = json!("dms");
            v["domain"] = json!(
                "domain points x in the plane of parameter_frame, in the union of domain_triangles"
            );
            v["evaluation"] = json!("DMS triangular B-spline: S(x) = sum over domain triangles I = (a, b, c) and b = (i, j, k), i + j + k = degree, of P_(I,b) N_b^I(x) with N_b^I(x) = |det(t_(a,i), t_(b,j), t_(c,k))| M(x | t_(a,0..i), t_(b,0..j), t_(c,0..k)), t_(v,0..degree) the knot cloud of domain vertex v and M the bivariate simplex spline of those degree + 3 knots (degree 0: 1 / |det| inside the knot triangle, det twice its signed area; higher degrees by Micchelli's recurrence). Points on knot lines belong to the side towards the centroid of the domain triangle holding x");
            v
        }
        _ => return None,
    };
    v["lattice_ordering"] = json!(LATTICE_ORDERING);
    Some(v)
}

/// The tessellation of a planar fit (the B-patch's triangle as one lattice, DMS triangle by
/// triangle), keeping the triangles whose corners all lie on the scanned region.
pub fn tessellate_planar(f: &PatchFit, info: &ScatteredInfo, segments: usize) -> Tessellation {
    let mut tess = tessellate(f, segments, None);
    let Some(surface) = planar_surface(&f.model) else {
        return tess;
    };
    let covers = info.coverage.tester();
    let inside: Vec<bool> = tess
        .params
        .par_iter()
        .map(|p| {
            let x = surface.domain_point(*p);
            covers(x.x, x.y)
        })
        .collect();
    tess.triangles
        .retain(|t| t.iter().all(|&v| inside[v as usize]));
    tess
}

/// The plane, trims and report keys of a planar fit, and its warm state.
pub(crate) fn add_outputs(
    f: &PatchFit,
    info: &ScatteredInfo,
    report: &mut Value,
    surface: &mut Value,
    warm: &mut WarmStart,
) {
    surface["parameter_frame"] = json!({
        "about": "the plane the scan was mapped to: plane point (s, t) = ((p - origin) . e1, (p - origin) . e2); domain points x are (s, t) after the warp, if any",
        "origin": info.frame.origin.to_array(),
        "e1": info.frame.e1.to_array(),
        "e2": info.frame.e2.to_array(),
        "map": info.method,
    });
    if let Some(w) = &info.warp {
        surface["parameter_frame"]["warp"] = json!({
            "about": "the projection (s, t) is warped before the domain applies: lattice vertex (i, j), 0 <= i < columns, 0 <= j < rows, sits at origin + spacing (i + j / 2, j sqrt(3) / 2) and moves to image[i + j columns]; between vertices the warp is linear on the triangles (i,j),(i+1,j),(i,j+1) and (i+1,j),(i+1,j+1),(i,j+1)",
            "lattice": w,
        });
    }
    // In the surface's own parameters, as the other kinds' trims (`export` reads them so).
    let own = |x: &DVec2| -> [f64; 2] {
        match &f.model {
            SurfaceModel::BPatch(b) => {
                let p = b.param_of(*x);
                [p.u, p.v]
            }
            _ => [x.x, x.y],
        }
    };
    surface["trim"] = json!({
        "space": "the surface's own parameters: barycentric (u, v) of domain_triangle's A and B for bpatch, domain points x (the plane of parameter_frame) for dms",
        "outer": info.outer.iter().map(own).collect::<Vec<_>>(),
        "holes": info.holes.iter().map(|h| h.iter().map(own).collect::<Vec<_>>()).collect::<Vec<_>>(),
    });
    report["remeshed"] = json!(true);
    report["components"] = json!(info.preparation.components);
    report["kept_vertices"] = json!(info.preparation.kept_vertices);
    report["dropped"] = json!(info.preparation.dropped);
    report["cold_start"] = json!(info.cold_start);
    report["holes_filled"] = json!(info.preparation.holes);
    report["parameterization"] = json!({ "method": info.method });
    report["cells"] = json!(f.model.as_surface().domain_face_count());
    report["domain"] = match &f.model {
        SurfaceModel::Dms(d) => json!({
            "kind": "dms",
            "triangles": d.triangles().len(),
            "vertices": d.vertices().len(),
            "grid_spacing": info.spacing,
            "degree": d.degree(),
        }),
        SurfaceModel::BPatch(b) => json!({
            "kind": "bpatch",
            "triangle": b.domain().map(|p| p.to_array()),
            "degree": b.degree(),
        }),
        _ => Value::Null,
    };
    report["reused_controls"] = json!(info.reused_controls);
    report["parameter_correction_rms"] = json!(info.correction_rms);
    let rms = f.geometric_rms();
    let domain_points: Vec<[f32; 2]> = match planar_surface(&f.model) {
        Some(s) => f
            .params
            .iter()
            .map(|p| s.domain_point(*p).as_vec2().to_array())
            .collect(),
        None => Vec::new(),
    };
    warm.frame = Some(info.frame);
    warm.warp = info.warp.clone();
    warm.feet = Some(WarmFeet {
        points: f.data.iter().map(|p| p.as_vec3().to_array()).collect(),
        params: domain_points,
        rms,
    });
    warm.scattered = ScatteredWarm::of(&f.model, &f.controls, info.spacing);
}
