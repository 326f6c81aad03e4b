//! `trispline export` of a Loop surface over a control mesh (a whole object): the
//! patchwork of `bspline::loop_patches`, split at irregular vertices until its deviation
//! meets the tolerance (or as asked), written as STEP (and IGES), with the patches as JSON and a
//! report beside.

use super::export_args::{beside, write_cad, ExportArgs};
use crate::bspline::loop_patches::{
    default_tolerance, loop_patchwork, loop_patchwork_within, Patchwork, Split, MAX_CORNER_LEVELS,
};
use crate::io::surface_json::{bspline_json, patchwork_json};
use crate::io::write_atomic;
use crate::surface::loop_limit::LoopLimitSurface;
use anyhow::{bail, Context};
use glam::DVec3;
use serde_json::json;
use std::path::Path;
use std::process::ExitCode;
use std::time::Instant;

/// Deepest uniform split `--depth` takes: 64 patches per control face (bun_zipper's fit:
/// 212k patches, a STEP file of some 200 MB).
const MAX_ASKED_DEPTH: u32 = 3;
/// The tolerance `--tolerance` leaves to the default (`loop_patches::default_tolerance`
/// over the fit's RMS error recorded in surface.json).
fn tolerance_of(path: &Path, controls: &[DVec3]) -> anyhow::Result<(f64, &'static str)> {
    let bytes = std::fs::read(path).with_context(|| format!("reading {}", path.display()))?;
    let v: serde_json::Value =
        serde_json::from_slice(&bytes).with_context(|| format!("{}: not JSON", path.display()))?;
    let fit_rms = v.pointer("/fit/rms_error").and_then(|x| x.as_f64());
    default_tolerance(fit_rms, controls)
        .with_context(|| format!("{}: the control points span no volume", path.display()))
}

/// The patchwork at the asked split, or, without `--corner-levels`, at the fewest corner
/// levels whose largest deviation is within `tolerance`.
fn patchwork(
    surface: &LoopLimitSurface,
    controls: &[DVec3],
    args: &ExportArgs,
    tolerance: f64,
) -> anyhow::Result<Patchwork> {
    let depth = args.depth.unwrap_or(0);
    Ok(match args.corner_levels {
        Some(corner_levels) => loop_patchwork(
            surface,
            controls,
            Split {
                depth,
                corner_levels,
            },
        )?,
        None => loop_patchwork_within(surface, controls, depth, tolerance)?,
    })
}

/// Refuses the patchwork flags out of their ranges, before anything is read or made.
pub(super) fn check_flags(args: &ExportArgs) -> anyhow::Result<()> {
    if let Some(d) = args.depth.filter(|&d| d > MAX_ASKED_DEPTH) {
        bail!("--depth {d}: must be in 0..={MAX_ASKED_DEPTH}");
    }
    if let Some(l) = args.corner_levels.filter(|&l| l > MAX_CORNER_LEVELS) {
        bail!("--corner-levels {l}: must be in 0..={MAX_CORNER_LEVELS}");
    }
    if let Some(t) = args.tolerance.filter(|t| !(t.is_finite() && *t > 0.0)) {
        bail!("--tolerance {t}: must be a positive distance");
    }
    Ok(())
}

/// Exports the Loop surface over `surface`'s control faces with these controls.
pub(super) fn run(
    args: &ExportArgs,
    surface: &LoopLimitSurface,
    controls: &[DVec3],
    t0: Instant,
) -> anyhow::Result<ExitCode> {
    let (tolerance, tolerance_source) = match args.tolerance {
        Some(t) => (t, "--tolerance"),
        None => tolerance_of(&args.surface, controls)?,
    };
    let work = patchwork(surface, controls, args, tolerance)?;
    let refs: Vec<_> = work.patches.iter().collect();
    write_cad(args, &refs)?;
    let patches_json = json!({
        "kind": "bspline_patches",
        "patches": work.patches.iter().map(bspline_json).collect::<Vec<_>>(),
    });
    write_atomic(
        &beside(&args.step, ".json"),
        &serde_json::to_vec(&patches_json)?,
    )?;
    let d = work.deviation;
    let met = d.max <= tolerance;
    let mut report = patchwork_json(&work, tolerance, tolerance_source);
    report["input"] = json!(args.surface.display().to_string());
    report["input_kind"] = json!("loop_mesh");
    report["step"] = json!(args.step.display().to_string());
    report["units"] = json!(args.units.name());
    report["control_faces"] = json!(surface.faces().len());
    report["corner_levels_chosen"] = json!(if args.corner_levels.is_some() {
        "--corner-levels"
    } else {
        "fewest meeting the tolerance"
    });
    report["wall_ms"] = json!(t0.elapsed().as_secs_f64() * 1e3);
    write_atomic(
        &beside(&args.step, ".report.json"),
        &serde_json::to_vec_pretty(&report)?,
    )?;
    println!(
        "exported {}: {} Bezier patches (depth {}, corner levels {}; {} of {} control faces exact) from the Loop mesh surface, deviation over {} samples max {:.3e} {u}, RMS {:.3e} {u}, normals within {:.2} deg at 99 %",
        args.step.display(),
        work.patches.len(),
        work.split.depth,
        work.split.corner_levels,
        work.exact_faces,
        surface.faces().len(),
        d.samples,
        d.max,
        d.rms,
        d.normal_p99_deg,
        u = args.units
    );
    if !met {
        let hint = if work.split.corner_levels < MAX_CORNER_LEVELS {
            format!(
                "; --corner-levels {} splits further",
                work.split.corner_levels + 1
            )
        } else {
            String::new()
        };
        eprintln!(
            "warning: the largest deviation {:.3e} exceeds the tolerance {tolerance:.3e} ({tolerance_source}){hint}",
            d.max
        );
    }
    Ok(ExitCode::SUCCESS)
}
