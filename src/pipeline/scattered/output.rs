//! What a B-patch or DMS fit adds to the outputs beside its `surface.json` kind (`kinds`):
//! the plane frame and trims, the report's keys, the warm state, and the
//! tessellation trimmed to the scanned region in domain coordinates.

use super::info::{planar_surface, ScatteredInfo};
use super::warm::ScatteredWarm;
use crate::pipeline::output::{tessellate, Tessellation};
use crate::pipeline::scan::WarmFeet;
use crate::pipeline::worker::WarmStart;
use crate::pipeline::{PatchFit, SurfaceModel};
use glam::DVec2;
use rayon::prelude::*;
use serde_json::{json, Value};

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
