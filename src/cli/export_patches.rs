//! `trispline export` of a Loop surface over a control mesh (a whole object): the
//! patchwork of `bspline::loop_patches`, split at irregular vertices until its deviation
//! meets the tolerance (or as asked), written as STEP (and IGES), with the patches as JSON and a
//! report beside.

use super::export_args::{beside, write_cad, ExportArgs};
use crate::bspline::loop_patches::{loop_patchwork, Patchwork, Split, MAX_CORNER_LEVELS};
use crate::io::surface_json::bspline_json;
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
/// Most levels of splitting at irregular vertices that the default goes to in search of
/// the tolerance. Each level adds two patches per face corner at an irregular vertex and
/// about halves the largest deviation, which sits at those vertices (bun_zipper's fit:
/// 3311 patches at level 0, 9392 at 1, 24488 at 3; 62, 34 and 11 um).
const MAX_AUTO_LEVELS: u32 = 6;
/// Default tolerance without a fit's RMS, as a share of the controls' bounding-box
/// diagonal (the fits' own default tolerance is 1e-3 of it).
const DIAGONAL_SHARE: f64 = 1e-4;

/// The tolerance `--tolerance` leaves to the default: the fit's RMS error recorded in
/// surface.json, else a share of the controls' diagonal.
fn default_tolerance(path: &Path, controls: &[DVec3]) -> anyhow::Result<(f64, &'static str)> {
    let bytes = std::fs::read(path).with_context(|| format!("reading {}", path.display()))?;
    let v: serde_json::Value =
        serde_json::from_slice(&bytes).with_context(|| format!("{}: not JSON", path.display()))?;
    let fit_rms = v
        .pointer("/fit/rms_error")
        .and_then(|x| x.as_f64())
        .filter(|x| x.is_finite() && *x > 0.0);
    if let Some(rms) = fit_rms {
        return Ok((rms, "the fit's RMS error (surface.json fit.rms_error)"));
    }
    let (lo, hi) = controls.iter().fold(
        (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)),
        |(lo, hi), p| (lo.min(*p), hi.max(*p)),
    );
    let diagonal = (hi - lo).length();
    if !(diagonal.is_finite() && diagonal > 0.0) {
        bail!("{}: the control points span no volume", path.display());
    }
    Ok((
        diagonal * DIAGONAL_SHARE,
        "1e-4 of the controls' bounding-box diagonal",
    ))
}

/// The patchwork at the asked depth and corner levels, or, without `--corner-levels`, at
/// the fewest corner levels (up to `MAX_AUTO_LEVELS`) whose largest deviation is within
/// `tolerance`.
fn patchwork(
    surface: &LoopLimitSurface,
    controls: &[DVec3],
    args: &ExportArgs,
    tolerance: f64,
) -> anyhow::Result<Patchwork> {
    let mut split = Split {
        depth: args.depth.unwrap_or(0),
        corner_levels: args.corner_levels.unwrap_or(0),
    };
    let mut work = loop_patchwork(surface, controls, split)?;
    while args.corner_levels.is_none()
        && work.deviation.max > tolerance
        && split.corner_levels < MAX_AUTO_LEVELS
    {
        split.corner_levels += 1;
        work = loop_patchwork(surface, controls, split)?;
    }
    Ok(work)
}

/// Exports the Loop surface over `surface`'s control faces with these controls.
pub(super) fn run(
    args: &ExportArgs,
    surface: &LoopLimitSurface,
    controls: &[DVec3],
    t0: Instant,
) -> anyhow::Result<ExitCode> {
    if let Some(d) = args.depth.filter(|&d| d > MAX_ASKED_DEPTH) {
        bail!("--depth {d}: must be in 0..={MAX_ASKED_DEPTH}");
    }
    if let Some(l) = args.corner_levels.filter(|&l| l > MAX_CORNER_LEVELS) {
        bail!("--corner-levels {l}: must be in 0..={MAX_CORNER_LEVELS}");
    }
    let (tolerance, tolerance_source) = match args.tolerance {
        Some(t) if t.is_finite() && t > 0.0 => (t, "--tolerance"),
        Some(t) => bail!("--tolerance {t}: must be a positive distance"),
        None => default_tolerance(&args.surface, controls)?,
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
    let report = json!({
        "input": args.surface.display().to_string(),
        "input_kind": "loop_mesh",
        "step": args.step.display().to_string(),
        "units": args.units.name(),
        "patches": work.patches.len(),
        "patch_degrees": [4, 4],
        "depth": work.split.depth,
        "corner_levels": work.split.corner_levels,
        "corner_levels_chosen": if args.corner_levels.is_some() { "--corner-levels" } else { "fewest meeting the tolerance" },
        "control_faces": surface.faces().len(),
        "exact_faces": work.exact_faces,
        "tolerance": { "value": tolerance, "from": tolerance_source, "met": met },
        "deviation": {
            "samples": d.samples,
            "max": d.max,
            "rms": d.rms,
            "normal_p99_deg": d.normal_p99_deg,
            "normal_max_deg": d.normal_max_deg,
            "measure": "distance from points of the limit surface (a lattice over every patch) to the patch, and the angle between the two normals there, in the surface's unit and degrees; patches of regular control faces are the surface itself",
        },
        "wall_ms": t0.elapsed().as_secs_f64() * 1e3,
    });
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
