//! surface.stp beside the daemon's surfaces over a control mesh (`[output] step`): the
//! patchwork `trispline export` writes by default, made from the surface.json about to be
//! written (so the two describe one surface), on the worker thread.

use super::outcome::Outcome;
use crate::bspline::loop_patches::{default_tolerance, loop_patchwork_within};
use crate::io::iges::IgesUnits;
use crate::io::step::{step_bytes, StepOptions};
use crate::io::surface_json::{parse_surface_json, patchwork_json, SurfaceDescription};
use crate::pipeline::worker::PatchOutputs;
use serde_json::json;
use std::time::Instant;

/// Adds surface.stp to every fitted surface of `outcome` that has a CAD form, and says in
/// each report.json what was written or why not.
pub(crate) fn add_step_files(outcome: &mut Outcome, units: IgesUnits) {
    if let Outcome::Fitted { outputs, .. } = outcome {
        for part in &mut outputs.parts {
            add_step(&mut part.outputs, units);
        }
    }
}

fn add_step(outputs: &mut PatchOutputs, units: IgesUnits) {
    let start = Instant::now();
    let bytes = serde_json::to_vec(&outputs.surface).unwrap_or_default();
    let (surface, controls) = match parse_surface_json(&bytes, "surface.json") {
        Ok(SurfaceDescription::LoopMesh { surface, controls }) => (surface, controls),
        Ok(_) => {
            outputs.report["cad"] = json!({
                "written": false,
                "reason": "surface.stp is written for surfaces over a control mesh (whole objects, subdivision connectivity); `trispline export` converts the others",
            });
            return;
        }
        Err(e) => return refuse(outputs, e.to_string()),
    };
    let fit_rms = outputs
        .surface
        .pointer("/fit/rms_error")
        .and_then(|x| x.as_f64());
    let Some((tolerance, source)) = default_tolerance(fit_rms, &controls) else {
        return refuse(outputs, "the control points span no volume".into());
    };
    let work = match loop_patchwork_within(&surface, &controls, 0, tolerance) {
        Ok(work) => work,
        Err(e) => return refuse(outputs, e.to_string()),
    };
    let refs: Vec<_> = work.patches.iter().collect();
    let options = StepOptions {
        units,
        file_name: "surface.stp".into(),
        time: Some(std::time::SystemTime::now()),
    };
    outputs.step = Some(step_bytes(&refs, &options));
    let mut cad = patchwork_json(&work, tolerance, source);
    cad["written"] = json!(true);
    cad["file"] = json!("surface.stp");
    cad["units"] = json!(units.name());
    cad["ms"] = json!(start.elapsed().as_secs_f64() * 1e3);
    outputs.report["cad"] = cad;
}

/// A surface whose STEP could not be made: said in report.json and the log, the fit kept.
fn refuse(outputs: &mut PatchOutputs, reason: String) {
    tracing::warn!(reason = %reason, "no surface.stp");
    outputs.report["cad"] = json!({"written": false, "reason": reason});
}
