//! The `surface.json` kinds `bpatch` and `dms`: the records of `surface::bpatch` and
//! `surface::dms::record` with the text another program needs to evaluate them. Apart from
//! the rest of `scattered` so that `pipeline::output` can write them without depending on
//! the worker.

use crate::pipeline::SurfaceModel;
use crate::surface::bpatch::BPatchRecord;
use crate::surface::dms::record::DmsRecord;
use glam::DVec3;
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
